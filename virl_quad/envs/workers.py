"""Where a vector env's slices of envs run: in this process or in worker processes on this host.

A *slice* is a group of envs stepped together (:class:`Slice`). A backend holds one slice per
worker and answers ``call(cmd, per_worker_args)`` with the list of the slices' results, in
worker order:

- :class:`InProcess`: one slice in this process (debugging, tests);
- :class:`Processes`: one slice per ``multiprocessing`` worker (the default: two cores run two
  slices at once);
- :class:`virl_quad.envs.ray_workers.RayActors`: one slice per Ray actor, on any machine of a
  Ray cluster (``pip install -e ".[cluster]"``).

Every backend builds the same envs with the same seeds (env ``i`` is seeded ``seed + i``), so
the results do not depend on where the slices run.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import sys
import traceback

import numpy as np

from virl_quad.envs import make
from virl_quad.robots.spec import RobotSpec

IMAGE_KEYS = ("agent_image", "expert_image")


class EnvWorkerLost(RuntimeError):
    """A worker that hosted envs is gone (its process was killed, its Ray actor died)."""


class Slice:
    """A group of envs stepped together (runs inside a worker or in-process)."""

    def __init__(self, robot: str | RobotSpec, env_ids: list[int], seed: int, overrides: dict) -> None:
        self.envs = [make(robot, time_limit=False, **overrides) for _ in env_ids]
        self.seeds = [seed + i for i in env_ids]

    def reset_all(self) -> dict:
        """Reset every env with its own seed; stacked observations."""
        obs = [env.reset(seed=s)[0] for env, s in zip(self.envs, self.seeds)]
        return stack(obs)

    def step(self, actions: np.ndarray, time_outs: np.ndarray) -> tuple:
        """Step every env, resetting those that ended: (obs, final frames, terminated, rewards)."""
        obs, final, terminated = [], [], np.zeros(len(self.envs), bool)
        rewards = np.zeros(len(self.envs))
        for i, env in enumerate(self.envs):
            o, rewards[i], term, _, _ = env.step(actions[i])
            terminated[i] = term
            final.append({k: o[k] for k in IMAGE_KEYS if k in o})
            if term or time_outs[i]:
                o, _ = env.reset()
            obs.append(o)
        return stack(obs), stack(final), terminated, rewards

    def close(self) -> None:
        """Release every env."""
        for env in self.envs:
            env.close()


def stack(dicts: list[dict]) -> dict:
    """Per-key ``np.stack`` of a list of same-keyed dicts ({} for none)."""
    return {k: np.stack([d[k] for d in dicts]) for k in dicts[0]} if dicts and dicts[0] else {}


class InProcess:
    """Every env in one slice in this process."""

    def __init__(self, robot: str | RobotSpec, ids: list[list[int]], seed: int, overrides: dict) -> None:
        self.slice = Slice(robot, [i for chunk in ids for i in chunk], seed, overrides)

    def call(self, cmd: str, per_worker_args: list[tuple]) -> list:
        """The slice's result of ``cmd`` (one-element list)."""
        return [getattr(self.slice, cmd)(*per_worker_args[0])]

    def close(self) -> None:
        """Release the envs."""
        if self.slice is not None:
            self.slice.close()
            self.slice = None


def _worker(conn, robot: str | RobotSpec, env_ids: list[int], seed: int, overrides: dict) -> None:
    """Worker process loop: build a slice, then serve commands until 'close'. Ctrl-C is the
    parent's to handle (it checkpoints and closes the workers): a worker ignores SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        sl = Slice(robot, env_ids, seed, overrides)
        if "torch" in sys.modules:      # not loaded by the envs (2 s a worker); where it is, one thread
            sys.modules["torch"].set_num_threads(1)
        conn.send(("ok", None))
    except Exception as exc:  # report construction errors to the parent, one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    while True:
        cmd, payload = conn.recv()
        try:
            if cmd == "close":
                sl.close()
                conn.send(("ok", None))
                return
            conn.send(("ok", getattr(sl, cmd)(*payload)))
        except Exception as exc:
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"))


class Processes:
    """One slice per ``multiprocessing`` worker process (spawned: no inherited PyBullet state)."""

    def __init__(self, robot: str | RobotSpec, ids: list[list[int]], seed: int, overrides: dict) -> None:
        ctx = mp.get_context("spawn")
        self._procs, self._conns = [], []
        # a new process inherits an ignored SIGINT, so a Ctrl-C while it starts up is not its to report
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            for chunk in ids:
                parent, child = ctx.Pipe()
                p = ctx.Process(target=_worker, args=(child, robot, chunk, seed, overrides), daemon=True)
                p.start()
                self._procs.append(p)
                self._conns.append(parent)
        finally:
            signal.signal(signal.SIGINT, previous)
        self._gather()  # construction acknowledgements

    def _gather(self) -> list:
        out = []
        for w, conn in enumerate(self._conns):
            try:
                status, payload = conn.recv()
            except (EOFError, OSError):
                code = self._procs[w].exitcode
                self.close()
                raise EnvWorkerLost(f"env worker {w} (process) was lost (exit code {code})") from None
            if status == "error":
                self.close()
                raise RuntimeError(f"env worker failed: {payload}")
            out.append(payload)
        return out

    def call(self, cmd: str, per_worker_args: list[tuple]) -> list:
        """Every worker's result of ``cmd``, in worker order."""
        for conn, args in zip(self._conns, per_worker_args):
            try:
                conn.send((cmd, args))
            except (BrokenPipeError, OSError):
                pass   # reported by _gather with the worker's exit code
        return self._gather()

    def close(self) -> None:
        """Stop the workers (each closes its envs)."""
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
