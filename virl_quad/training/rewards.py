"""Reward sources for :class:`~virl_quad.training.algorithm.VirlPPO`.

A source sees every step of a rollout (``observe``) and, once it is complete,
returns the rollout's rewards [T, N] (``finish``):

- :class:`LearnedReward`: the VIRL distance or one of its baselines/ablations
  (``virl``, ``frame``, ``sequence``, ``no_ae``, ``gaifo``): stores the rollout's
  agent/expert frames in the distance model's dataset, runs M updates, then
  recomputes every reward of the rollout with the updated model; the video speed term
  scales it by how near the agent travels to the demonstration's speed (up to
  ``video_speed_weight`` of it taken away), the ground's slide measured in both videos
  (:mod:`virl_quad.reward.egomotion`, :func:`~virl_quad.reward.egomotion.gated`);
- :class:`EnvReward`: the reward the env computed (``oracle``: the ground-truth
  pose-imitation reward, the upper bound of the comparison);
- :class:`SurvivalReward`: 1 per step the robot is up (``prior``: no imitation reward at all,
  the baseline a learned reward must beat to add anything to the gait prior and warm start).
"""

from __future__ import annotations

import time

import numpy as np
import torch
from tensordict import TensorDict

from virl_quad.reward import RewardConfig, build_reward
from virl_quad.reward.egomotion import VideoSpeedTerm, gated
from virl_quad.reward.frames import textured_ground


def step_frames(obs: TensorDict, dones: torch.Tensor, extras: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """The agent and expert frames each env produced this step, [N, 48, 48] uint8.

    For an env whose episode just ended, ``obs`` already holds the next episode's
    first frame, so its last frame comes from ``extras["final_*"]``.
    """
    d = dones.bool().view(-1, 1, 1)
    agent = torch.where(d, extras["final_agent_image"], obs["agent_image"])
    expert = torch.where(d, extras["final_expert_image"], obs["expert_image"])
    return agent, expert


class LearnedReward:
    """Algorithm 1's reward: a distance model trained online beside the policy."""

    def __init__(self, variant: str, demo_frames: np.ndarray, num_envs: int, updates: int, seed: int,
                 device: str = "cpu", other_clips: list[np.ndarray] | None = None, lr: float = 1e-3,
                 cyclic: bool = False, w_d: float = -5.0, adversarial_weight: float = 1.0,
                 fps: float = 50.0, video_speed_weight: float = 0.0) -> None:
        weights = {} if adversarial_weight == 1.0 else {"expert_vs_agent": float(adversarial_weight)}
        cfg = RewardConfig.make(variant=variant, lr=lr, clips_cyclic=cyclic, w_d=w_d, pair_weights=weights)
        self.model = build_reward(cfg, demo_frames, other_clips, seed, device)
        self.speed, self.speed_weight, self.speed_note = None, float(video_speed_weight), ""
        self._find_agent_ground = textured_ground(demo_frames) is not None   # the env's ground looks otherwise
        if self.speed_weight > 0:
            self.speed, self.speed_note = _speed_term(demo_frames, fps, num_envs, self.speed_weight)
        self.updates = updates
        self.num_envs = num_envs
        self.state = self.model.stream_state(num_envs)
        self._agent: list[torch.Tensor] = []
        self._expert: list[torch.Tensor] = []
        self._dones: list[torch.Tensor] = []

    def observe(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Keep this step's frames and episode ends."""
        agent, expert = step_frames(obs, dones, extras)
        self._agent.append(agent.cpu())
        self._expert.append(expert.cpu())
        self._dones.append(dones.bool().cpu())

    def pretrain(self, updates: int) -> dict[str, float]:
        """Dataset <- the steps observed so far (a rollout no policy learns from); ``updates``
        model updates; no rewards. A new run's distance model so starts from the demonstration,
        the other clips and the agent's own frames rather than from random weights."""
        agent, expert, dones = self._take()
        self.model.add_rollout(agent, expert, dones)
        info = {f"distance/{k}": float(v) for k, v in self.model.update(updates).items()}
        self._stream(agent, expert, dones)
        return info

    def finish(self) -> tuple[torch.Tensor, dict[str, float]]:
        """Dataset <- rollout; M model updates; rewards [T, N] recomputed with the updated model."""
        agent, expert, dones = self._take()
        t0 = time.perf_counter()
        self.model.add_rollout(agent, expert, dones)
        info = {f"distance/{k}": float(v) for k, v in self.model.update(self.updates).items()}
        t1 = time.perf_counter()
        rewards = self._stream(agent, expert, dones)
        if self.speed is not None:
            if self._find_agent_ground:                  # once, from the first rollout's first env
                self.speed.find_agent_ground(agent[:, 0])
                self._find_agent_ground = False
            r_speed, valid, shift = self.speed.rollout(agent, dones)
            w = self.speed_weight
            rewards = torch.where(valid.to(rewards.device), gated(rewards, r_speed.to(rewards.device), w), rewards)
            if bool(valid.any()):
                info["video_speed/ratio"] = float(shift[valid].mean()) / self.speed.target
                info["video_speed/reward"] = float(r_speed[valid].mean())
        info["time/distance_update_s"] = t1 - t0
        info["time/reward_recompute_s"] = time.perf_counter() - t1
        return rewards, info

    def _take(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The observed agent and expert frames [T, N, 48, 48] and episode ends [T, N]; cleared."""
        out = torch.stack(self._agent), torch.stack(self._expert), torch.stack(self._dones)
        self._agent, self._expert, self._dones = [], [], []
        return out

    def _stream(self, agent: torch.Tensor, expert: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        """The rollout's rewards [T, N] under the present model. The rollout starts from the state
        the last one ended in (computed with the previous weights); envs whose episode ended on
        the last step start the next one fresh."""
        rewards, end_state = self.model.recompute(agent, expert, dones, self.state, return_state=True)
        self.state = end_state.with_reset(dones[-1].to(end_state.fresh.device))
        return rewards

    def state_dict(self) -> dict:
        """Distance model and optimiser (weights-only loadable)."""
        return self.model.state_dict()

    def load_state_dict(self, d: dict) -> None:
        """Restore the distance model and optimiser (an older version's rollout count is ignored)."""
        self.model.load_state_dict(d)


def _speed_term(demo_frames: np.ndarray, fps: float, num_envs: int, weight: float) -> tuple[VideoSpeedTerm | None, str]:
    """The video speed term for a demonstration, or None, with a line saying which and why."""
    term = VideoSpeedTerm.for_demo(demo_frames, fps, num_envs)
    if term is None:
        return None, ("video speed term off: the demonstration shows no patterned ground to measure its "
                      "travel by (render it on the checker ground)")
    return term, (f"video speed term: up to {weight:g} of the reward for the ground's slide, {term.target:+.2f} px per "
                  f"{term.k} frames in the demonstration (negative: forwards), shifts searched to +-{term.reach} px")


class EnvReward:
    """Rewards computed by the env itself (the oracle pose reward)."""

    def __init__(self) -> None:
        self._rewards: list[torch.Tensor] = []

    def observe(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Keep the env's reward of this step."""
        self._rewards.append(rewards.detach().float().cpu().clone())

    def finish(self) -> tuple[torch.Tensor, dict[str, float]]:
        """The rollout's env rewards [T, N]."""
        r = torch.stack(self._rewards)
        self._rewards = []
        return r, {}

    def state_dict(self) -> dict:
        """Nothing to save."""
        return {}

    def load_state_dict(self, d: dict) -> None:
        """Nothing to restore."""


class SurvivalReward(EnvReward):
    """1 per step: a fall ends the episode, so the return counts the steps the robot stays up."""

    def observe(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Keep a reward of 1 for this step."""
        self._rewards.append(torch.ones_like(rewards, dtype=torch.float32).cpu())
