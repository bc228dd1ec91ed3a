"""Does the learned reward rank behaviours as the ground-truth score does? The alignment probe.

A fixed, graded set of rollouts of the simulated robot (recorded once): the privileged tracker
of :mod:`virl_quad.evaluation.tracker`, its actions scaled towards the default pose, with action
noise, half a cycle late, tracking other built-in gaits, standing still and random actions.
Each rollout keeps its agent and demonstration frames and its ground-truth score (which the
reward never sees). :func:`alignment` scores every rollout with a distance model, the reward
a policy would get (``exp(w_d d^2)``, from frame :data:`SKIP` on), and returns Spearman's rank
correlation of reward and score: near 1, climbing the reward climbs the score; near 0 or
below, the reward gives a policy nothing (or the wrong thing) to climb.

Training runs the probe at every ground-truth evaluation (``VirlRunner``) and logs it beside
the score; ``bench/reward_alignment.py`` runs it on a saved run or a fresh model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
from scipy.stats import spearmanr

from virl_quad.reward.egomotion import VideoSpeedTerm, gated

SKIP = 10  # first frames of an episode left out (the sequence encoder warms up)

Controller = Callable[[object, np.random.Generator, dict], np.ndarray]   # (env, rng, obs) -> action


@dataclass
class GradedRollout:
    """One rollout of the probe: its frames (T, 48, 48) uint8 and ground-truth score."""

    controller: str
    seed: int
    agent: np.ndarray
    expert: np.ndarray
    score: float


def controllers(robot: str, cycle: float, gait: str = "trot") -> dict[str, Controller]:
    """name -> controller, from best to worst in intent (``cycle``: the demonstration's, s; the
    other built-in gaits than ``gait`` are tracked as wrong motions)."""
    from virl_quad import demo as demo_lib
    from virl_quad.evaluation.tracker import tracker_action

    others = {g: demo_lib.load(g, robot).motion for g in ("trot", "pace", "bound") if g != gait}
    out: dict[str, Controller] = {"standing still": lambda env, rng, obs: np.zeros(12),
                                  "random actions": lambda env, rng, obs: rng.uniform(-1.0, 1.0, 12)}
    for alpha in (0.25, 0.5, 0.75, 1.0):
        out[f"tracker, alpha {alpha:g}"] = lambda env, rng, obs, a=alpha: a * tracker_action(env)
    for sigma in (0.3, 0.6):
        out[f"tracker + noise {sigma:g}"] = lambda env, rng, obs, s=sigma: tracker_action(env) + rng.normal(0.0, s, 12)
    out["tracker, half a cycle late"] = lambda env, rng, obs: tracker_action(env, delay=0.5 * cycle)
    for g, m in others.items():
        out[f"tracking the {g}"] = lambda env, rng, obs, m=m: tracker_action(env, motion=m)
    return out


def rollout(robot: str, demo, act: Controller, seed: int, seconds: float, randomize: bool,
            ground: str, **overrides) -> tuple[np.ndarray, np.ndarray, float]:
    """(agent frames, expert frames, ground-truth total) of one episode of ``act`` (``overrides``:
    further env options, e.g. a policy's action contract)."""
    from virl_quad import envs
    from virl_quad.evaluation.rollout import record_episode
    from virl_quad.evaluation.score import score_trajectory

    env = envs.make(robot, demo=demo, randomize=randomize, episode_seconds=seconds, ground=ground, **overrides)
    rng = np.random.default_rng(seed)
    agent, expert = [], []

    def policy(obs: dict) -> np.ndarray:
        """The controller's action; keeps the frames the reward would see at this step."""
        agent.append(obs["agent_image"])
        expert.append(obs["expert_image"])
        return act(env, rng, obs)

    try:
        obs, _ = env.reset(seed=seed)
        traj, times, _ = record_episode(env, policy, obs)
    finally:
        env.close()
    score = score_trajectory(traj, demo.motion, times, robot)["total"]
    return np.array(agent), np.array(expert), float(score)


def record(robot: str, demo, gait: str = "trot", seeds: tuple[int, ...] = (0, 1), seconds: float = 4.0,
           randomize: bool = True, ground: str = "checker") -> list[GradedRollout]:
    """The probe's rollouts: every controller once per seed (needs ``demo.motion``)."""
    if demo.motion is None:
        raise ValueError("the alignment probe needs a demonstration with a reference motion (the score needs one)")
    out = []
    for name, act in controllers(robot, float(demo.motion.duration), gait).items():
        for seed in seeds:
            agent, expert, score = rollout(robot, demo, act, seed, seconds, randomize, ground)
            out.append(GradedRollout(name, seed, agent, expert, score))
    return out


def rollout_rewards(model, rollouts: list[GradedRollout]) -> list[float]:
    """Mean reward ``exp(w_d d^2)`` (d^2 in the model's calibrated unit) of each rollout under a
    distance model (frames SKIP.., or every frame of a rollout that ended, by a fall, before that)."""
    rewards = []
    with torch.no_grad():
        for r in rollouts:
            d = model.distance(torch.from_numpy(r.expert[:, None]), torch.from_numpy(r.agent[:, None]))[:, 0]
            d = d[SKIP:] if len(d) > SKIP else d
            rewards.append(float(model.reward_of(d).mean()))
    return rewards


def alignment(model, rollouts: list[GradedRollout]) -> tuple[float, list[float]]:
    """(Spearman rank correlation of reward and score over the rollouts, each rollout's reward).
    0 when every reward is the same (a reward that ranks nothing)."""
    rewards = rollout_rewards(model, rollouts)
    return _rank(rewards, rollouts), rewards


def speed_rewards(term, rollouts: list[GradedRollout]) -> list[float]:
    """Mean reward of the video speed term (a :class:`~virl_quad.reward.egomotion.VideoSpeedTerm`,
    whose target, levels and rate are used) over each rollout's frames from :data:`SKIP` on (NaN
    where it never applies)."""
    out = []
    for r in rollouts:
        fresh = VideoSpeedTerm(term.target, term.fps, term.levels, 1, term.k, term.agent_levels, term.reach)
        reward, valid, _ = fresh.rollout(torch.from_numpy(r.agent[:, None]), torch.zeros(len(r.agent), 1, dtype=torch.bool))
        reward, valid = reward[SKIP:, 0], valid[SKIP:, 0]
        out.append(float(reward[valid].mean()) if bool(valid.any()) else float("nan"))
    return out


def _rank(rewards: list[float], rollouts: list[GradedRollout]) -> float:
    if np.ptp(rewards) == 0.0 or not np.isfinite(rewards).all():
        return 0.0
    return float(spearmanr(rewards, [r.score for r in rollouts]).statistic)


class AlignmentProbe:
    """The probe as training uses it: rollouts recorded at construction, ``probe(model)`` after.

    ``speed``: (weight, :class:`~virl_quad.reward.egomotion.VideoSpeedTerm`) when the training
    reward mixes in the video speed term; the probe then ranks that mixed reward (what the policy
    is trained on) and reports the distance model's own ranking beside it."""

    def __init__(self, robot: str, demo, gait: str = "trot", seeds: tuple[int, ...] = (0, 1),
                 seconds: float = 4.0, randomize: bool = True, ground: str = "checker",
                 speed: tuple[float, object] | None = None) -> None:
        self.rollouts = record(robot, demo, gait, seeds, seconds, randomize, ground)
        self.speed_weight, self.speed = (0.0, None) if speed is None else (float(speed[0]), speed[1])
        self._speed_rewards = None if self.speed is None else np.nan_to_num(speed_rewards(self.speed, self.rollouts))

    def probe(self, model) -> dict[str, float]:
        """``{"reward_alignment": rho, "reward_best": mean reward of the best-scored controller,
        "reward_standing": of standing still}`` under ``model`` (with the speed term: of the mixed
        reward, and ``distance_alignment``, the model's own rho)."""
        rho, rewards = alignment(model, self.rollouts)
        out = {}
        if self._speed_rewards is not None:
            out["distance_alignment"] = rho
            rewards = list(gated(np.asarray(rewards), self._speed_rewards, self.speed_weight))
            rho = _rank(rewards, self.rollouts)
        by = _by_controller(self.rollouts, rewards)
        best = max(by, key=lambda name: by[name][1])
        return {"reward_alignment": rho, "reward_best": by[best][0],
                "reward_standing": by.get("standing still", (float("nan"), 0.0))[0], **out}


def _by_controller(rollouts: list[GradedRollout], rewards: list[float]) -> dict[str, tuple[float, float]]:
    """controller -> (mean reward, mean score)."""
    out: dict[str, list[list[float]]] = {}
    for r, w in zip(rollouts, rewards):
        out.setdefault(r.controller, [[], []])
        out[r.controller][0].append(w)
        out[r.controller][1].append(r.score)
    return {k: (float(np.mean(v[0])), float(np.mean(v[1]))) for k, v in out.items()}


def table(rollouts: list[GradedRollout], rewards: list[float]) -> list[tuple[str, float, float]]:
    """(controller, mean reward, mean score) rows, best score first."""
    by = _by_controller(rollouts, rewards)
    return sorted(((k, v[0], v[1]) for k, v in by.items()), key=lambda row: -row[2])
