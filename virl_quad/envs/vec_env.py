"""rsl-rl VecEnv over N PyBullet environments spread across workers.

Each worker hosts a slice of the envs and steps them in a loop; the main
process sends one message per step (actions and which envs time out) and gets
stacked arrays back, so two cores really run two slices at once. Workers are
processes on this host (``workers_kind="local"``, the default; ``num_workers=0``
keeps everything in this process: debugging, tests) or Ray actors on a cluster
(``"ray"``, see :mod:`virl_quad.envs.ray_workers`); a lost worker raises
:class:`EnvWorkerLost`.

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
from virl_quad.envs.quadruped import checked
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
        ids = [chunk.tolist() for chunk in np.array_split(np.arange(num_envs), max(workers, 1))]
        self._bounds = np.cumsum([0] + [len(i) for i in ids])
        if workers_kind == "ray":
            from virl_quad.envs.ray_workers import RayActors   # Ray is an extra: imported only when asked for

            self._workers = RayActors(robot, ids, seed, overrides, address=ray_address, prefix=actor_prefix)
        elif workers == 0:
            self._workers = InProcess(robot, ids, seed, overrides)
            self._bounds = np.array([0, num_envs])
        else:
            self._workers = Processes(robot, ids, seed, overrides)
        self._obs = self._to_tensordict(self._call("reset_all"))

    # -- worker plumbing -------------------------------------------------------------------------
    def _call(self, cmd: str, *per_worker_args) -> Any:
        args = [tuple(a[w] for a in per_worker_args) for w in range(len(self._bounds) - 1)]
        parts = self._workers.call(cmd, args)
        if isinstance(parts[0], dict):
            return _concat(parts)
        return tuple(_concat([p[i] for p in parts]) for i in range(len(parts[0])))

    def _split(self, x: np.ndarray) -> list[np.ndarray]:
        return [x[a:b] for a, b in zip(self._bounds[:-1], self._bounds[1:])]

    def _to_tensordict(self, obs: dict) -> TensorDict:
        data = {k: torch.from_numpy(np.ascontiguousarray(v)).to(self.device) for k, v in obs.items()}
        return TensorDict(data, batch_size=[self.num_envs], device=self.device)

    # -- VecEnv API ------------------------------------------------------------------------------
    def get_observations(self) -> TensorDict:
        """Current observations of all envs."""
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step all envs. The reward is the env's (0, or the oracle's); the VIRL reward comes from the trainer."""
        a = actions.detach().to("cpu", torch.float64).numpy()
        if a.shape != (self.num_envs, self.num_actions):
            raise ValueError(f"actions must be ({self.num_envs}, {self.num_actions}), got {tuple(a.shape)}")
        self.episode_length_buf += 1
        time_outs = (self.episode_length_buf >= self.max_episode_length).cpu().numpy()
        obs, final, terminated, env_rewards = self._call("step", self._split(a), self._split(time_outs))
        time_outs &= ~terminated
        dones = terminated | time_outs
        self.episode_length_buf[torch.from_numpy(dones).to(self.device)] = 0
        self._obs = self._to_tensordict(obs)
        extras = {
            "time_outs": torch.from_numpy(time_outs).to(self.device),
            "terminated": torch.from_numpy(terminated).to(self.device),
            "log": {},
        }
        for k, v in final.items():
            extras[f"final_{k}"] = torch.from_numpy(v).to(self.device)
        rewards = torch.from_numpy(env_rewards).float().to(self.device)
        return self._obs, rewards, torch.from_numpy(dones).to(self.device), extras

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
