"""A thin rsl-rl runner: the stock construction, our own iteration loop around the same PPO calls.

Per iteration: rollout (``alg.act`` -> ``env.step`` -> ``alg.process_env_step``, pipelined over
the env's groups: :mod:`virl_quad.training.rollout`),
``alg.compute_returns`` (where VirlPPO updates the distance model and recomputes
rewards), ``alg.update``; then one progress line, TensorBoard scalars, a
checkpoint every ``save_every`` iterations and a ground-truth evaluation every
``eval_every``. Ctrl-C, and a lost env worker, write a checkpoint before leaving.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import check_nan
from tensordict import TensorDict

from virl_quad.envs.workers import EnvWorkerLost
from virl_quad.training import checkpoint
from virl_quad.training.rollout import rollout

#: below this spread of its encodings over the demonstration (units of e, in (0, 1)) the distance
#: model's frame encoder counts as collapsed (trained healthy models: 0.04-0.3; collapsed ~1e-5)
COLLAPSED_SPREAD = 0.005
#: a spread this large once counts as having learned the frames (a later fall below
#: COLLAPSED_SPREAD is then a collapse, not a model that never spread)
SPREAD_LEARNED = 0.02


def actor_policy(actor: torch.nn.Module) -> Callable[[dict], np.ndarray]:
    """Wrap an rsl-rl actor as ``obs dict -> action`` (deterministic mean, numpy); the observation
    goes to the actor's device (a GPU with ``--device cuda``) and the action comes back."""
    device = next(actor.parameters()).device

    def act(obs: dict) -> np.ndarray:
        x = torch.as_tensor(obs["policy"], dtype=torch.float32, device=device).reshape(1, -1)
        with torch.inference_mode():
            out = actor(TensorDict({"policy": x}, batch_size=[1]))
        return out[0].cpu().numpy().astype(np.float64)
    return act


def eval_summary(result: dict, standing: dict) -> str:
    """The last ground-truth evaluation for a person: the score as a multiple of holding the
    default pose (below 1x the policy is worse than standing still), the forward-speed ratio
    to the demonstration and the falls, with the iteration it was taken at ("-" before one);
    with a learned reward, its rank correlation with the score on the alignment probe."""
    if "total" not in result:
        return "-"
    base = standing.get("total")
    score = f"{result['total'] / base:.2f}x standing" if base else f"score {result['total']:.3f}"
    episodes = int(result.get("episodes_run", 0))
    falls = f"falls {int(result.get('falls', 0))}" + (f"/{episodes}" if episodes else "")
    align = f", reward-score rank corr {result['reward_alignment']:+.2f}" if "reward_alignment" in result else ""
    return (f"{score}, speed {result.get('speed_ratio', float('nan')):.2f}, {falls}{align} "
            f"@{result.get('iteration', '?')}")


class VirlRunner(OnPolicyRunner):
    """OnPolicyRunner with progress lines, atomic checkpoints and ground-truth evaluation."""

    def __init__(self, env, train_cfg: dict, reward_source, run_dir: Path, config: dict,
                 evaluate: Callable[[Callable], dict] | None = None, device: str = "cpu") -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints the model structure
            super().__init__(env, train_cfg, log_dir=None, device=device)
        self.alg.attach_reward(reward_source)
        self.reward_source = reward_source
        self.run_dir = Path(run_dir)
        self.config = config
        self.evaluate_fn = evaluate
        self.alignment_probe = None   # an AlignmentProbe: the learned reward's rank agreement with the score
        self.env_steps = 0
        self.wall_time = 0.0
        self.last_eval: dict = {}
        self.standing: dict = {}      # the same evaluation of holding the default pose (the bar)
        self.writer = None
        self._episode_len = torch.zeros(env.num_envs)
        self._finished_lengths: list[float] = []
        self._collapse_warned = False
        self._peak_spread = 0.0       # the largest encoding spread seen in this run

    # -- checkpoints --------------------------------------------------------------------------
    def checkpoint_payload(self) -> dict:
        """Everything needed to continue: networks, optimisers, normalisers, reward model, RNG."""
        return {**self.alg.save(), "reward": self.reward_source.state_dict(), "config": self.config,
                "iteration": self.current_learning_iteration, "env_steps": self.env_steps,
                "wall_time": self.wall_time, "rng": checkpoint.rng_state(), "last_eval": self.last_eval,
                "standing": self.standing, "frozen_updates": self.alg.frozen_updates,
                "actor_normalizer_fixed": not self.alg.actor.obs_normalization,
                "anchor": {"pull": self.alg.prior_pull, "weights": self.alg.anchor},
                "peak_spread": self._peak_spread, "speed_term": checkpoint.SPEED_TERM_FORM,
                "contract": checkpoint.contract_payload(self.env.contract, self.env.spec)}

    def save_checkpoint(self) -> Path:
        """Write ``checkpoint.pt`` atomically in the run folder."""
        return checkpoint.save(self.run_dir / checkpoint.LATEST, self.checkpoint_payload())

    def restore(self, data: dict) -> None:
        """Continue from a loaded checkpoint (see :func:`virl_quad.training.checkpoint.load`)."""
        self.alg.load(data, None, strict=True)
        self.reward_source.load_state_dict(data["reward"])
        self.current_learning_iteration = int(data["iteration"])
        self.env_steps = int(data["env_steps"])
        self.wall_time = float(data["wall_time"])
        self.last_eval = dict(data.get("last_eval") or {})
        self.standing = dict(data.get("standing") or {})
        self.alg.freeze_actor(int(data.get("frozen_updates", 0)))
        if data.get("actor_normalizer_fixed"):
            self.alg.fix_actor_normalizer()
        anchor = data.get("anchor") or {}
        if anchor.get("weights") is not None:
            self.alg.anchor_actor(float(anchor["pull"]), anchor["weights"])
        self._peak_spread = float(data.get("peak_spread", 0.0))
        checkpoint.set_rng_state(data["rng"])

    # -- the loop -----------------------------------------------------------------------------
    def train(self, iterations: int, minutes: float = 0.0, save_every: int = 10, eval_every: int = 0,
              log: Callable[[str], None] = print) -> None:
        """Run until ``iterations`` in total are done or ``minutes`` of wall time have passed."""
        self._open_writer()
        start_wall, start_it = time.time(), self.current_learning_iteration
        obs = self.env.get_observations().to(self.device)
        self.alg.train_mode()
        try:
            while self.current_learning_iteration < iterations:
                t0 = time.time()
                obs = self._rollout(obs)
                t1 = time.time()
                with torch.inference_mode():
                    self.alg.compute_returns(obs)
                t2 = time.time()
                losses = self.alg.update()
                t3 = time.time()
                self.current_learning_iteration += 1
                self.wall_time += t3 - t0
                it = self.current_learning_iteration
                if eval_every and it % eval_every == 0:
                    self.run_evaluation()
                self._report(it, iterations, losses, (t1 - t0, t2 - t1, t3 - t2), start_wall, start_it, log,
                             minutes)
                if it % save_every == 0:
                    self.save_checkpoint()
                if minutes and time.time() - start_wall >= 60 * minutes:
                    log(f"time budget of {minutes:g} min reached after iteration {it}")
                    break
        except KeyboardInterrupt:
            self.save_checkpoint()
            log(f"interrupted: checkpoint written at iteration {self.current_learning_iteration}")
            raise
        except EnvWorkerLost:
            self.save_checkpoint()    # the rollout in flight is lost; the learning so far is not
            raise
        finally:
            self.writer.close()
            self.writer = None
        self.save_checkpoint()

    def pretrain_reward(self, updates: int) -> dict[str, float]:
        """One rollout of the present deterministic policy (``num_steps_per_env`` steps of every
        env, counted in the env steps, stored nowhere for PPO), its frames given to the learned
        reward, which then trains its model ``updates`` times: before the first PPO update its
        reward has seen the demonstration, the other clips and what the agent looks like."""
        policy = self.alg.get_policy()
        obs = self.env.get_observations().to(self.device)
        self.alg.eval_mode()
        try:
            with torch.inference_mode():
                for _ in range(self.cfg["num_steps_per_env"]):
                    obs, rewards, dones, extras = self.env.step(policy(obs).to(self.env.device))
                    if self.cfg.get("check_for_nan", True):
                        check_nan(obs, rewards, dones)
                    obs = obs.to(self.device)
                    self.reward_source.observe(obs, rewards, dones, extras)
                    self._count_episodes(dones)
        finally:
            self.alg.train_mode()
        self.env_steps += self.cfg["num_steps_per_env"] * self.env.num_envs
        with self.alg.learning_threads(), torch.inference_mode(False), torch.enable_grad():
            return self.reward_source.pretrain(updates)

    def _rollout(self, obs: TensorDict) -> TensorDict:
        obs = rollout(self.alg, self.env, obs, self.cfg["num_steps_per_env"], self._count_episodes,
                      check_nans=self.cfg.get("check_for_nan", True))
        self.env_steps += self.cfg["num_steps_per_env"] * self.env.num_envs
        return obs

    def _count_episodes(self, dones: torch.Tensor) -> None:
        self._episode_len += 1
        ended = dones.cpu().bool()
        self._finished_lengths += self._episode_len[ended].tolist()
        self._episode_len[ended] = 0

    def _open_writer(self):
        """The run's TensorBoard writer (opened on first use)."""
        if self.writer is None:
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(str(self.run_dir / "tensorboard"))
        return self.writer

    def run_evaluation(self) -> dict:
        """Ground-truth imitation score of the current deterministic policy (if an evaluator is set)."""
        if self.evaluate_fn is None:
            return {}
        self.alg.eval_mode()
        try:
            result = self.evaluate_fn(actor_policy(self.alg.get_policy()))
        finally:
            self.alg.train_mode()
        self.last_eval = {"iteration": self.current_learning_iteration,
                          "episodes_run": len(result.get("episodes", [])),
                          **{k: float(v) for k, v in result.items() if isinstance(v, (int, float))}}
        if self.standing.get("total"):
            self.last_eval["score_vs_standing"] = self.last_eval.get("total", float("nan")) / self.standing["total"]
        model = getattr(self.reward_source, "model", None)
        if self.alignment_probe is not None and model is not None:
            self.last_eval.update(self.alignment_probe.probe(model))
        with open(self.run_dir / "evaluations.jsonl", "a") as f:   # the learning curve, one line per evaluation
            f.write(json.dumps({**self.last_eval, "env_steps": self.env_steps, "wall_time_s": self.wall_time}) + "\n")
        writer = self._open_writer()
        for k, v in self.last_eval.items():
            writer.add_scalar(f"eval/{k}", v, self.current_learning_iteration)
        return self.last_eval

    def _warn_collapse(self, it: int, spread: float | None, log: Callable[[str], None]) -> None:
        """One line, once, when after its first 100 iterations the distance model's frame encoder
        maps the demonstration's frames alike: it collapsed (its spread was healthy once) or it never
        spread them out (told apart by the peak spread, which this keeps). Either way its reward
        tells behaviours apart poorly."""
        if spread is None:
            return
        self._peak_spread = max(self._peak_spread, spread)
        if it < 100 or spread >= COLLAPSED_SPREAD or self._collapse_warned:
            return
        self._collapse_warned = True
        what = (f"has collapsed (encoding spread over the demonstration {spread:.1e}, down from "
                f"{self._peak_spread:.2f}; healthy 0.04-0.3): its reward no longer tells behaviours apart"
                if self._peak_spread >= SPREAD_LEARNED else
                f"still encodes the demonstration's frames alike after {it} iterations (spread {spread:.1e}, "
                f"healthy 0.04-0.3): its reward tells behaviours apart poorly until they spread")
        log(f"warning: the distance model's frame encoder {what}")

    def _report(self, it: int, total: int, losses: dict, phases: tuple, start_wall: float, start_it: int,
                log: Callable[[str], None], minutes: float = 0.0) -> None:
        info = self.alg.last_reward_info
        rollout, returns, update = phases
        n = self.cfg["num_steps_per_env"] * self.env.num_envs
        sps = n / max(sum(phases), 1e-9)
        dt = self.env.spec.control_dt
        ep_len = float(np.mean(self._finished_lengths)) * dt if self._finished_lengths else float("nan")
        self._finished_lengths = self._finished_lengths[-200:]
        per_it = (time.time() - start_wall) / max(it - start_it, 1)
        eta = per_it * (total - it)
        if minutes:
            eta = min(eta, max(60 * minutes - (time.time() - start_wall), 0.0))
        dist = info.get("distance/total", float("nan"))
        dist_text = f" | dist-loss {dist:.4f}" if math.isfinite(dist) else ""          # no distance model: none
        seen = f" | video speed {info['video_speed/ratio']:+.2f}" if "video_speed/ratio" in info else ""
        ep_text = f"{ep_len:5.2f}s" if math.isfinite(ep_len) else "    - "              # no episode ended yet
        log(f"it {it:5d}/{total} | steps {self.env_steps:9,d} | {sps:6.0f} st/s | reward {info['reward_mean']:.3f}"
            f"{dist_text}{seen} | ep-len {ep_text} | eval {eval_summary(self.last_eval, self.standing)}"
            f" | ETA {eta / 60:5.1f} min")
        self._warn_collapse(it, info.get("distance/e_spread"), log)
        w = self.writer
        w.add_scalar("train/reward_mean", info["reward_mean"], it)
        w.add_scalar("train/episode_seconds", ep_len, it)
        w.add_scalar("train/steps_per_second", sps, it)
        w.add_scalar("train/env_steps", self.env_steps, it)
        w.add_scalar("time/rollout_s", rollout, it)
        w.add_scalar("time/reward_and_returns_s", returns, it)
        w.add_scalar("time/ppo_update_s", update, it)
        w.add_scalar("policy/action_std", float(self.alg.get_policy().output_std.detach().mean()), it)
        w.add_scalar("policy/learning_rate", float(self.alg.learning_rate), it)   # the actor's, KL-adaptive
        for k, v in {**losses, **info}.items():
            w.add_scalar(f"loss/{k}", float(v), it)
