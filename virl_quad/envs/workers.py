"""Where a vector env's slices of envs run: in this process or in worker processes on this host.

A *slice* is a group of envs stepped together (:class:`Slice`). The envs fall into *groups*
that step independently (``groups[g][w]``: the ids of group ``g``'s envs on worker ``w``); a
worker holds one slice per group. A backend's ``send(cmd, group, per_worker_args)`` starts a
command on that group's slices and ``gather(group)`` returns their results in worker order, so
that one group steps while the caller works on the other's results (a worker runs its commands
in the order sent):

- :class:`InProcess`: the slices in this process (debugging, tests; ``send`` runs at once);
- :class:`Processes`: each ``multiprocessing`` worker holds one slice per group (the default:
  two cores run two workers at once);
- :class:`virl_quad.envs.ray_workers.RayActors`: one slice per Ray actor, on any machine of a
  Ray cluster (``pip install -e ".[cluster]"``; one group).

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
    """Every group's envs in one slice in this process."""

    def __init__(self, robot: str | RobotSpec, groups: list[list[list[int]]], seed: int, overrides: dict) -> None:
        self.slices = [Slice(robot, [i for chunk in g for i in chunk], seed, overrides) for g in groups]
        self._results: dict[int, list] = {}

    def send(self, cmd: str, group: int, per_worker_args: list[tuple]) -> None:
        """Run ``cmd`` on the group's slice now; :meth:`gather` returns its result."""
        self._results[group] = [getattr(self.slices[group], cmd)(*per_worker_args[0])]

    def gather(self, group: int) -> list:
        """The result of the group's last :meth:`send` (one-element list)."""
        return self._results.pop(group)

    def close(self) -> None:
        """Release the envs."""
        for sl in self.slices:
            sl.close()
        self.slices = []


def _worker(conn, robot: str | RobotSpec, groups: list[list[int]], seed: int, overrides: dict) -> None:
    """Worker process loop: build one slice per group (``groups[g]``: its env ids), then serve
    ``(cmd, group, args)`` commands in order until 'close'. Ctrl-C is the parent's to handle (it
    checkpoints and closes the workers): a worker ignores SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        slices = [Slice(robot, ids, seed, overrides) for ids in groups]
        if "torch" in sys.modules:      # not loaded by the envs (2 s a worker); where it is, one thread
            sys.modules["torch"].set_num_threads(1)
        conn.send(("ok", None))
    except Exception as exc:  # report construction errors to the parent, one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    while True:
        cmd, group, payload = conn.recv()
        try:
            if cmd == "close":
                for sl in slices:
                    sl.close()
                conn.send(("ok", None))
                return
            conn.send(("ok", getattr(slices[group], cmd)(*payload)))
        except Exception as exc:
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"))


class Processes:
    """``multiprocessing`` worker processes (spawned: no inherited PyBullet state), each holding
    one slice per group."""

    def __init__(self, robot: str | RobotSpec, groups: list[list[list[int]]], seed: int, overrides: dict) -> None:
        ctx = mp.get_context("spawn")
        self._procs, self._conns = [], []
        self._pending: list[int] = []   # groups sent and not yet gathered, in order
        ids = [[g[w] for g in groups] for w in range(len(groups[0]))]
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

    def send(self, cmd: str, group: int, per_worker_args: list[tuple]) -> None:
        """Ask every worker to run ``cmd`` on its slice of ``group`` (returns at once)."""
        for conn, args in zip(self._conns, per_worker_args):
            try:
                conn.send((cmd, group, args))
            except (BrokenPipeError, OSError):
                pass   # reported by _gather with the worker's exit code
        self._pending.append(group)

    def gather(self, group: int) -> list:
        """Every worker's result of the oldest :meth:`send` not yet gathered, which must be
        ``group``'s, in worker order."""
        if not self._pending or self._pending[0] != group:
            raise RuntimeError(f"gather({group}) out of order: groups sent and not gathered: {self._pending}")
        self._pending.pop(0)
        return self._gather()

    def close(self) -> None:
        """Stop the workers (each closes its envs)."""
        for conn in self._conns:
            try:
                for _ in self._pending:     # answers still owed: read them first
                    conn.recv()
                conn.send(("close", 0, ()))
                conn.recv()
            except (OSError, EOFError, BrokenPipeError):
                pass
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
        self._procs, self._conns, self._pending = [], [], []
