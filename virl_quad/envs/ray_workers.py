"""Env slices as Ray actors: a vector env whose envs run on the machines of a Ray cluster.

Needs Ray (``pip install -e ".[cluster]"``). Each actor reserves one CPU and hosts one
:class:`~virl_quad.envs.workers.Slice` with its own PyBullet clients; the trainer stays where it
was started and sends each step's actions to every actor at once. Actors are named
``<prefix>env-<k>`` in the ``virl_quad`` namespace, so an operator (or a test) can find them.
"""

from __future__ import annotations

import logging
import socket

from virl_quad.cli import UserError
from virl_quad.envs.workers import EnvWorkerLost, Slice
from virl_quad.robots.spec import RobotSpec

NAMESPACE = "virl_quad"
START_S = 300.0   # s an actor may take to start (Ray schedules it once the cluster has a free CPU)
ANSWER_S = 120.0  # s an actor may take to answer one call before it counts as lost (a step takes ms)


def _ray():
    """The ray module, or a one-line UserError naming the extra that installs it."""
    try:
        import ray
    except ImportError:
        raise UserError('Ray workers need Ray: pip install -e ".[cluster]"') from None
    return ray


def connect(address: str | None = None) -> None:
    """Join the Ray cluster at ``address`` (``auto``: the one started on this machine by ``ray
    start``), or start a local one when ``address`` is None or empty; nothing if already joined."""
    ray = _ray()
    if ray.is_initialized():
        return
    check_address(address)
    try:
        ray.init(address=address or None, namespace=NAMESPACE, include_dashboard=False,
                 log_to_driver=False, logging_level=logging.WARNING, configure_logging=True)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise UserError(f"cannot join the Ray cluster at {address!r}: {str(exc).splitlines()[0]}") from None


REACH_S = 5.0     # s, how long a cluster address may take to accept a TCP connection


def check_address(address: str | None) -> None:
    """UserError at once when a ``host:port`` address has nothing listening (Ray itself would
    retry for minutes); ``auto``, ``ray://`` and empty addresses are left to Ray."""
    if not address or address == "auto" or "://" in address:
        return
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        raise UserError(f"--ray-address must be auto or HOST:PORT, got {address!r}")
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=REACH_S).close()
    except OSError as exc:
        raise UserError(f"cannot reach a Ray cluster at {address} ({exc.strerror or exc}): start one with "
                        f"`ray start --head`, or leave --ray-address empty for a local one") from None


class _SliceActor:
    """One slice inside a Ray actor process (one torch thread: the actor owns one CPU)."""

    def __init__(self, robot: str | RobotSpec, env_ids: list[int], seed: int, overrides: dict) -> None:
        import torch

        torch.set_num_threads(1)
        self.slice = Slice(robot, env_ids, seed, overrides)

    def ready(self) -> bool:
        """True once the slice is built."""
        return True

    def call(self, cmd: str, args: tuple):
        """The slice's result of ``cmd``."""
        return getattr(self.slice, cmd)(*args)


class RayActors:
    """One slice per Ray actor (``address``: see :func:`connect`; ``prefix``: actor names); one
    group of envs (``groups[0][w]``: actor ``w``'s env ids)."""

    def __init__(self, robot: str | RobotSpec, groups: list[list[list[int]]], seed: int, overrides: dict,
                 address: str | None = None, prefix: str = "") -> None:
        if len(groups) != 1:
            raise ValueError(f"Ray actors hold one group of envs, got {len(groups)}")
        ids = groups[0]
        self._refs: list | None = None
        ray = _ray()
        connect(address)
        actor = ray.remote(num_cpus=1, max_restarts=0)(_SliceActor)
        self.names = [f"{prefix}env-{k}" for k in range(len(ids))]
        self.actors = [actor.options(name=name, namespace=NAMESPACE).remote(robot, chunk, seed, overrides)
                       for name, chunk in zip(self.names, ids)]
        try:
            # construction errors surface here; a cluster without free CPUs keeps actors pending
            self._get([a.ready.remote() for a in self.actors], timeout=START_S,
                      hint=f" of starting (it needs one free CPU of the cluster, {len(ids)} in all)")
        except Exception:
            self.close()
            raise

    def _get(self, refs: list, timeout: float = ANSWER_S, hint: str = "") -> list:
        """Each actor's result in order: a lost actor, or one silent for ``timeout`` s, raises
        EnvWorkerLost; an error in the slice a one-line RuntimeError."""
        ray = _ray()
        try:
            return ray.get(refs, timeout=timeout)   # one wait for all: the common case, the cheapest
        except ray.exceptions.GetTimeoutError:
            ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
            k = next(i for i, ref in enumerate(refs) if ref not in ready)
            raise EnvWorkerLost(f"env worker {k} (Ray actor {self.names[k]}) did not answer within "
                                f"{timeout:g} s{hint}") from None
        except ray.exceptions.RayError:
            pass
        for k, ref in enumerate(refs):      # something failed: say which actor, and how
            try:
                ray.get(ref)
            except ray.exceptions.RayActorError as exc:
                why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                raise EnvWorkerLost(f"env worker {k} (Ray actor {self.names[k]}) was lost: {why}") from None
            except ray.exceptions.RayTaskError as exc:
                cause = exc.cause if getattr(exc, "cause", None) is not None else exc
                raise RuntimeError(f"env worker failed: {type(cause).__name__}: {cause}") from None
        raise RuntimeError("env worker failed: Ray reported an error no actor holds")

    def send(self, cmd: str, group: int, per_worker_args: list[tuple]) -> None:
        """Ask every actor to run ``cmd`` (the actors run at once; returns at once)."""
        self._refs = [a.call.remote(cmd, args) for a, args in zip(self.actors, per_worker_args)]

    def gather(self, group: int) -> list:
        """Every actor's result of the last :meth:`send`, in worker order."""
        refs, self._refs = self._refs, None
        return self._get(refs)

    def close(self) -> None:
        """Release the envs and end the actors (the cluster stays up)."""
        if not self.actors:
            return
        ray = _ray()
        refs = [a.call.remote("close", ()) for a in self.actors]
        try:
            ray.wait(refs, num_returns=len(refs), timeout=10)
        except Exception:
            pass
        for a in self.actors:
            try:
                ray.kill(a)
            except Exception:
                pass
        self.actors = []
