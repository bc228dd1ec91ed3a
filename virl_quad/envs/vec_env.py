"""rsl-rl VecEnv over N PyBullet environments spread across workers.

Each worker hosts a slice of the envs and steps them in a loop; the main
process sends one message per step (actions and which envs time out) and gets
stacked arrays back, so two cores really run two slices at once. Workers are
processes on this host (``workers_kind="local"``, the default; ``num_workers=0``
keeps everything in this process: debugging, tests) or Ray actors on a cluster
(``"ray"``, see :mod:`virl_quad.envs.ray_workers`); a lost worker raises
:class:`EnvWorkerLost`.

With worker processes the envs are split in two *groups*, each spread over
every worker: :meth:`QuadrupedVecEnv.step_async` / :meth:`~QuadrupedVecEnv.step_wait` step one
group while the caller acts on the other's observations, so the workers do not wait for the
policy (the runner's rollout does this; :meth:`~QuadrupedVecEnv.step` steps both, the same envs
and results as one group).

Semantics rsl-rl relies on:
- ``step`` auto-resets every env that terminated or timed out, and returns
  the observation of the NEW episode for it;
- ``extras["time_outs"]`` marks time-limit ends (bootstrapped by PPO), which
  follow ``episode_length_buf >= max_episode_length`` — so a runner that
  randomises ``episode_length_buf`` is honoured;
- the last frames of a finished episode (needed by the VIRL reward) come in
  ``extras["final_agent_image"]`` / ``extras["final_expert_image"]``.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from virl_quad import robots
from virl_quad.envs import options_of
from virl_quad.envs.config import checked
from virl_quad.envs.workers import EnvWorkerLost, InProcess, Processes
from virl_quad.robots.spec import RobotSpec

__all__ = ["QuadrupedVecEnv", "EnvWorkerLost", "WORKER_KINDS"]


#: where a slice of envs runs: "local" (processes on this host, or this process with
#: num_workers=0) or "ray" (actors on a Ray cluster)
WORKER_KINDS = ("local", "ray")


class QuadrupedVecEnv(VecEnv):
    """``num_envs`` quadruped envs for rsl-rl, over ``num_workers`` workers of ``workers_kind``
    (local processes, or Ray actors on the cluster at ``ray_address``, named with ``actor_prefix``)."""

    def __init__(self, robot: str | RobotSpec, num_envs: int, *, num_workers: int | None = None, seed: int = 0,
                 device: str = "cpu", episode_seconds: float | None = None, workers_kind: str = "local",
                 ray_address: str | None = None, actor_prefix: str = "", **overrides: Any) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        robot = robots.get(robot)
        #: the policy contract of these envs (action size, scale, clip, rate limit, TG, clock);
        #: every option is checked here, in this process, with a clear error
        spec, actions = checked(robot, options_of(overrides))
        self.contract = actions.contract
        seconds = episode_seconds if episode_seconds is not None else spec.episode_seconds
        self.num_envs = num_envs
        self.num_actions = self.contract.action_size   # 12, or 14 with a trajectory generator
        self.max_episode_length = int(round(seconds / spec.control_dt))
        self.device = torch.device(device)
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long, device=self.device)
        self.cfg = {"robot": spec.name, "num_envs": num_envs, "seed": seed, "episode_seconds": seconds,
                    **{k: v for k, v in overrides.items() if k not in ("demo", "tg")},
                    "tg": None if self.contract.tg is None else self.contract.tg.to_dict()}
        self.spec = spec
        workers = min(num_envs, os.cpu_count() or 1) if num_workers is None else num_workers
        if workers_kind not in WORKER_KINDS:
            raise ValueError(f"unknown workers {workers_kind!r}; choose one of: {', '.join(WORKER_KINDS)}")
        # two groups where worker processes can step one while the policy acts on the other
        n_groups = 2 if workers_kind == "local" and workers > 0 and num_envs >= 2 * workers else 1
        slices = 1 if workers_kind == "local" and workers == 0 else max(workers, 1)
        group_ids = np.array_split(np.arange(num_envs), n_groups)
        #: env range (first, end) of each group, in env order
        self.groups = [(int(g[0]), int(g[-1]) + 1) for g in group_ids]
        layout = [[chunk.tolist() for chunk in np.array_split(g, slices)] for g in group_ids]
        self._bounds = [np.cumsum([0] + [len(c) for c in g]) for g in layout]   # per group, worker slices
        if workers_kind == "ray":
            from virl_quad.envs.ray_workers import RayActors   # Ray is an extra: imported only when asked for

            self._workers = RayActors(robot, layout, seed, overrides, address=ray_address, prefix=actor_prefix)
        elif workers == 0:
            self._workers = InProcess(robot, layout, seed, overrides)
        else:
            self._workers = Processes(robot, layout, seed, overrides)
        self._time_outs: dict[int, np.ndarray] = {}
        self._group_obs = [self._to_tensordict(self._gather(g, "reset_all")) for g in range(n_groups)]
        self._obs: TensorDict | None = None

    # -- worker plumbing -------------------------------------------------------------------------
    def _send(self, group: int, cmd: str, *group_args: np.ndarray) -> None:
        b = self._bounds[group]
        self._workers.send(cmd, group, [tuple(a[lo:hi] for a in group_args) for lo, hi in zip(b[:-1], b[1:])])

    def _gather(self, group: int, cmd: str | None = None) -> Any:
        if cmd is not None:
            self._send(group, cmd)
        parts = self._workers.gather(group)
        if isinstance(parts[0], dict):
            return _concat(parts)
        return tuple(_concat([p[i] for p in parts]) for i in range(len(parts[0])))

    def _to_tensordict(self, obs: dict) -> TensorDict:
        data = {k: torch.from_numpy(np.ascontiguousarray(v)).to(self.device) for k, v in obs.items()}
        return TensorDict(data, batch_size=[len(next(iter(data.values())))], device=self.device)

    # -- VecEnv API ------------------------------------------------------------------------------
    def get_observations(self) -> TensorDict:
        """Current observations of all envs."""
        if self._obs is None:
            self._obs = self._group_obs[0] if len(self.groups) == 1 else torch.cat(self._group_obs)
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step all envs. The reward is the env's (0, or the oracle's); the VIRL reward comes from the trainer."""
        if tuple(actions.shape) != (self.num_envs, self.num_actions):
            raise ValueError(f"actions must be ({self.num_envs}, {self.num_actions}), got {tuple(actions.shape)}")
        for g, (lo, hi) in enumerate(self.groups):
            self.step_async(actions[lo:hi], g)
        parts = [self.step_wait(g) for g in range(len(self.groups))]
        if len(parts) == 1:
            return parts[0]
        extras = {k: torch.cat([p[3][k] for p in parts]) for k in parts[0][3] if k != "log"}
        return (self.get_observations(), torch.cat([p[1] for p in parts]), torch.cat([p[2] for p in parts]),
                {**extras, "log": {}})

    def step_async(self, actions: torch.Tensor, group: int = 0) -> None:
        """Start stepping the envs of ``group`` (``self.groups[group]``) with ``actions`` (one row
        per env of the group); :meth:`step_wait` returns the result. Groups are waited for in the
        order started."""
        lo, hi = self.groups[group]
        a = actions.detach().to("cpu", torch.float64).numpy()
        if a.shape != (hi - lo, self.num_actions):
            raise ValueError(f"actions must be ({hi - lo}, {self.num_actions}), got {tuple(a.shape)}")
        self.episode_length_buf[lo:hi] += 1
        time_outs = (self.episode_length_buf[lo:hi] >= self.max_episode_length).cpu().numpy()
        self._time_outs[group] = time_outs
        self._send(group, "step", a, time_outs)

    def step_wait(self, group: int = 0) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """The result of :meth:`step_async` for ``group``: its envs' (observations, rewards,
        dones, extras), as :meth:`step` gives them for all envs."""
        lo, hi = self.groups[group]
        obs, final, terminated, env_rewards = self._gather(group)
        time_outs = self._time_outs.pop(group) & ~terminated
        dones = terminated | time_outs
        self.episode_length_buf[lo:hi][torch.from_numpy(dones).to(self.device)] = 0
        self._group_obs[group] = self._to_tensordict(obs)
        self._obs = None
        extras = {
            "time_outs": torch.from_numpy(time_outs).to(self.device),
            "terminated": torch.from_numpy(terminated).to(self.device),
            "log": {},
        }
        for k, v in final.items():
            extras[f"final_{k}"] = torch.from_numpy(v).to(self.device)
        rewards = torch.from_numpy(env_rewards).float().to(self.device)
        return self._group_obs[group], rewards, torch.from_numpy(dones).to(self.device), extras

    def close(self) -> None:
        """Stop the workers and release the physics clients."""
        workers, self._workers = getattr(self, "_workers", None), None
        if workers is not None:
            workers.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass


def _concat(parts: list) -> Any:
    if isinstance(parts[0], dict):
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts[0] else {}
    return np.concatenate(parts)
