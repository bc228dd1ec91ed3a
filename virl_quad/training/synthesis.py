"""Kinematic renders of trajectory generators (no physics), for the video fit.

:class:`Synthesizer` plays a TG on one robot and renders it with the env's own camera, the
base moving forward at the TG's stance speed. :class:`RenderPool` renders many
candidates at once on several processes, each with its own PyBullet client: a render depends
only on its TG and frame count, so the pool's renders are the same, pixel for pixel, as one
process's. This module imports no torch (a spawned worker starts in about a second).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from virl_quad.policy.tg import TGParams, TrajectoryGenerator
from virl_quad.robots.spec import RobotSpec


class Synthesizer:
    """Kinematic renders of a TG on one robot with the env's camera and ground (no physics), at
    ``fps`` frames per second (None: the robot's control rate)."""

    def __init__(self, spec: RobotSpec, fps: float | None = None) -> None:
        from virl_quad.sim.camera import CameraParams
        from virl_quad.sim.world import World

        self.spec = spec
        self.fps = float(fps or spec.control_hz)                              # Hz
        self.cam = CameraParams.from_spec(spec)
        self.world = World(spec, ground="plain")        # painted out by silhouettes() anyway

    def render(self, params: TGParams, num_frames: int) -> np.ndarray | None:
        """Gray frames (num_frames, 48, 48) uint8 of the TG played from phase 0 at the
        synthesizer's frame rate, or None when its feet are out of the robot's reach."""
        try:
            tg = TrajectoryGenerator(self.spec, params)
        except ValueError:
            return None
        t = np.arange(num_frames) / self.fps                                  # s
        q = self.spec.clip_to_limits(tg.joint_targets((t * params.frequency)[:, None]))
        speed = params.step_length * params.frequency / params.duty           # m/s, stance feet at rest
        base_z = self.spec.foot_radius - float(np.mean(tg.stance_z))          # m, stance feet on the ground
        out = np.empty((num_frames, 48, 48), np.uint8)
        for i in range(num_frames):
            self.world.set_pose(np.array([speed * t[i], 0.0, base_z]), np.array([0.0, 0.0, 0.0, 1.0]), q[i])
            out[i] = self.world.render(cam=self.cam)
        return out

    def close(self) -> None:
        """Release the physics client."""
        self.world.close()


_WORKER: Synthesizer | None = None          # a pool process's own synthesizer


def _start_worker(spec: RobotSpec, fps: float | None) -> None:
    global _WORKER
    _WORKER = Synthesizer(spec, fps)


def _render_in_worker(job: tuple[TGParams, int]) -> np.ndarray | None:
    assert _WORKER is not None
    return _WORKER.render(*job)


def default_workers() -> int:
    """Processes for the renders: one per CPU core this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                                                  # not on Linux
        return os.cpu_count() or 1


class RenderPool:
    """Renders of many candidate TGs on ``workers`` spawned processes (1: in this process), at
    ``fps`` frames per second (None: the robot's control rate)."""

    def __init__(self, spec: RobotSpec, workers: int | None = None, fps: float | None = None) -> None:
        self.workers = max(1, default_workers() if workers is None else int(workers))
        self._local = Synthesizer(spec, fps) if self.workers == 1 else None
        self._pool = None if self.workers == 1 else ProcessPoolExecutor(
            self.workers, mp_context=mp.get_context("spawn"), initializer=_start_worker, initargs=(spec, fps))

    def render_many(self, candidates: list[TGParams], num_frames: int) -> list[np.ndarray | None]:
        """:meth:`Synthesizer.render` of each candidate, in order."""
        if self._local is not None:
            return [self._local.render(p, num_frames) for p in candidates]
        return list(self._pool.map(_render_in_worker, [(p, num_frames) for p in candidates]))

    def close(self) -> None:
        """Stop the processes (or release this process's physics client)."""
        if self._local is not None:
            self._local.close()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "RenderPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
