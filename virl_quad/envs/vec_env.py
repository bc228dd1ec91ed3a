"""rsl-rl VecEnv over N PyBullet environments spread across worker processes.

Each worker process hosts a slice of the envs and steps them in a loop; the
main process sends one message per step (actions and which envs time out)
and gets stacked arrays back, so two cores really run two slices at once.
``num_workers=0`` keeps everything in this process (debugging, tests).

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

import multiprocessing as mp
import signal
import traceback
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from virl_quad.envs import make

_IMAGE_KEYS = ("agent_image", "expert_image")


class _Slice:
    """A group of envs stepped together (runs inside a worker or in-process)."""

    def __init__(self, robot: str, env_ids: list[int], seed: int, overrides: dict) -> None:
        self.envs = [make(robot, time_limit=False, **overrides) for _ in env_ids]
        self.seeds = [seed + i for i in env_ids]

    def reset_all(self) -> dict:
        """Reset every env with its own seed; stacked observations."""
        obs = [env.reset(seed=s)[0] for env, s in zip(self.envs, self.seeds)]
        return _stack(obs)

    def step(self, actions: np.ndarray, time_outs: np.ndarray) -> tuple:
        """Step every env, resetting those that ended: (obs, final frames, terminated, rewards)."""
        obs, final, terminated = [], [], np.zeros(len(self.envs), bool)
        rewards = np.zeros(len(self.envs))
        for i, env in enumerate(self.envs):
            o, rewards[i], term, _, _ = env.step(actions[i])
            terminated[i] = term
            final.append({k: o[k] for k in _IMAGE_KEYS if k in o})
            if term or time_outs[i]:
                o, _ = env.reset()
            obs.append(o)
        return _stack(obs), _stack(final), terminated, rewards

    def close(self) -> None:
        """Release every env."""
        for env in self.envs:
            env.close()


def _stack(dicts: list[dict]) -> dict:
    return {k: np.stack([d[k] for d in dicts]) for k in dicts[0]} if dicts and dicts[0] else {}


def _worker(conn, robot: str, env_ids: list[int], seed: int, overrides: dict) -> None:
    """Worker process loop: build a slice, then serve commands until 'close'. Ctrl-C is the
    parent's to handle (it checkpoints and closes the workers): a worker ignores SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    torch.set_num_threads(1)
    try:
        sl = _Slice(robot, env_ids, seed, overrides)
        conn.send(("ok", None))
    except Exception as exc:  # report construction errors to the parent, one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    while True:
        cmd, payload = conn.recv()
        try:
            if cmd == "reset_all":
                conn.send(("ok", sl.reset_all()))
            elif cmd == "step":
                conn.send(("ok", sl.step(*payload)))
            elif cmd == "close":
                sl.close()
                conn.send(("ok", None))
                return
        except Exception as exc:
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"))


class QuadrupedVecEnv(VecEnv):
    """``num_envs`` quadruped envs for rsl-rl, over ``num_workers`` processes."""

    def __init__(self, robot: str, num_envs: int, *, num_workers: int | None = None, seed: int = 0,
                 device: str = "cpu", episode_seconds: float | None = None, **overrides: Any) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        probe = make(robot, **overrides)  # validates the robot and overrides here, with a clear error
        spec = probe.unwrapped.robot
        #: the policy contract of these envs (action size, scale, clip, rate limit, TG, clock)
        self.contract = probe.unwrapped.contract
        probe.close()
        seconds = episode_seconds if episode_seconds is not None else spec.episode_seconds
        self.num_envs = num_envs
        self.num_actions = self.contract.action_size   # 12, or 14 with a trajectory generator
        self.max_episode_length = int(round(seconds / spec.control_dt))
        self.device = torch.device(device)
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long, device=self.device)
        self.cfg = {"robot": robot, "num_envs": num_envs, "seed": seed, "episode_seconds": seconds,
                    **{k: v for k, v in overrides.items() if k not in ("demo", "tg")},
                    "tg": None if self.contract.tg is None else self.contract.tg.to_dict()}
        self.spec = spec
        workers = min(num_envs, mp.cpu_count()) if num_workers is None else num_workers
        ids = np.array_split(np.arange(num_envs), max(workers, 1))
        self._bounds = np.cumsum([0] + [len(i) for i in ids])
        self._local: _Slice | None = None
        self._procs, self._conns = [], []
        if workers == 0:
            self._local = _Slice(robot, list(range(num_envs)), seed, overrides)
        else:
            ctx = mp.get_context("spawn")
            # a new process inherits an ignored SIGINT, so a Ctrl-C while it starts up is not its to report
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
            try:
                for chunk in ids:
                    parent, child = ctx.Pipe()
                    p = ctx.Process(target=_worker, args=(child, robot, chunk.tolist(), seed, overrides),
                                    daemon=True)
                    p.start()
                    self._procs.append(p)
                    self._conns.append(parent)
            finally:
                signal.signal(signal.SIGINT, previous)
            self._gather()  # construction acknowledgements
        self._obs = self._to_tensordict(self._call("reset_all"))

    # -- worker plumbing -------------------------------------------------------------------------
    def _gather(self) -> list:
        out = []
        for conn in self._conns:
            status, payload = conn.recv()
            if status == "error":
                self.close()
                raise RuntimeError(f"env worker failed: {payload}")
            out.append(payload)
        return out

    def _call(self, cmd: str, *per_worker_args) -> Any:
        if self._local is not None:
            return getattr(self._local, cmd)(*[a[0] for a in per_worker_args])
        for w, conn in enumerate(self._conns):
            conn.send((cmd, tuple(a[w] for a in per_worker_args)))
        parts = self._gather()
        if isinstance(parts[0], dict):
            return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        return tuple(_concat([p[i] for p in parts]) for i in range(len(parts[0])))

    def _split(self, x: np.ndarray) -> list[np.ndarray]:
        if self._local is not None:
            return [x]
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
        if self._local is not None:
            self._local.close()
            self._local = None
        for conn in self._conns:
            try:
                conn.send(("close", ()))
                conn.recv()
            except (OSError, EOFError, BrokenPipeError):
                pass
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
        self._procs, self._conns = [], []

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass


def _concat(parts: list) -> Any:
    if isinstance(parts[0], dict):
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts[0] else {}
    return np.concatenate(parts)
