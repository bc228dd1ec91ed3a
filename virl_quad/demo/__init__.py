"""Demonstrations: the video a robot learns from, rendered from a motion or imported from a file.

``load(source, robot) -> Demonstration`` is the one entry point the trainer needs:

>>> from virl_quad import demo
>>> d = demo.load("trot", "pupper")          # built-in gait (rendered once, then cached)
>>> d = demo.load("dog_pace.txt", "pupper")  # motion_imitation clip, retargeted Laikago -> Pupper
>>> d = demo.load("clip.mp4", "laikago")     # any video, imported to 48x48 at the control rate
>>> d = demo.load("demo.npz", "pupper")      # a saved demonstration

Modules: ``demonstration`` (the ``Demonstration`` the env consumes), ``render`` (demo videos of a
motion, ``.npz``), ``video_import`` (any video), ``sheet`` (contact sheet PNG), ``checks`` (video
round trip). The motions themselves live in :mod:`virl_quad.motion`, the ground-truth score in
:mod:`virl_quad.evaluation`. CLI: ``python -m virl_quad.demo``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from virl_quad import robots
from virl_quad.demo.demonstration import Demonstration
from virl_quad.motion.state import MotionLike, MotionState
from virl_quad.sim.params import DEFAULT_GROUND

if TYPE_CHECKING:
    from virl_quad.motion.motion import Motion

# The heavier modules (scipy, OpenCV, PyBullet, Pinocchio) load on first use: the environment
# imports this package for the Demonstration class alone.
_LAZY = {
    "Motion": "virl_quad.motion.motion", "GAIT_NAMES": "virl_quad.motion.gaits",
    "DEFAULT_GAIT": "virl_quad.motion.gaits", "load_npz": "virl_quad.demo.render",
    "save_npz": "virl_quad.demo.render",
}

#: Bump when gait parameters or rendering change, so cached renders are rebuilt.
CACHE_VERSION = "gaits-v2"   # v2: the ground is recorded in the demonstration
MOTION_SUFFIXES = (".txt", ".json")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")


def __getattr__(name: str):
    """Lazy access to the names of :data:`_LAZY`."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def cache_dir() -> Path:
    """Folder of cached built-in gait renders: ``$VIRL_QUAD_CACHE``, else ``$XDG_CACHE_HOME/virl_quad``
    (default ``~/.cache/virl_quad``). Entries are keyed by robot, gait, :data:`CACHE_VERSION` and a
    hash of the gait parameters, the robot spec and its URDF, so a changed camera or gait re-renders."""
    if os.environ.get("VIRL_QUAD_CACHE"):
        return Path(os.environ["VIRL_QUAD_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "virl_quad"


def _bad_source(source: str) -> ValueError:
    from virl_quad.motion.gaits import GAIT_NAMES

    return ValueError(f"cannot use {source!r} as a demonstration: give a built-in gait "
                      f"({', '.join(GAIT_NAMES)}), a .npz demonstration, a motion file (.txt/.json) "
                      f"or a video ({'/'.join(VIDEO_SUFFIXES)})")


def _cache_key(robot: str, gait: str) -> str:
    """Short hash of everything a gait render depends on: gait parameters, robot spec, URDF text."""
    import dataclasses
    import hashlib

    from virl_quad.motion.gaits import gait_params

    spec = robots.get(robot)
    h = hashlib.sha1(repr((CACHE_VERSION, gait_params(robot, gait), dataclasses.astuple(spec))).encode())
    try:
        h.update(Path(spec.urdf_path).read_bytes())
    except OSError:
        pass
    return h.hexdigest()[:10]


def gait_demonstration(gait: str, robot: str, use_cache: bool = True, ground: str = DEFAULT_GROUND) -> Demonstration:
    """The rendered demonstration of built-in ``gait`` on ``robot`` and ``ground``, cached under :func:`cache_dir`."""
    from virl_quad.motion.gaits import gait_motion
    from virl_quad.demo.render import load_npz, render_demonstration, save_npz

    path = cache_dir() / f"{robot}_{gait}_{ground}_{CACHE_VERSION}_{_cache_key(robot, gait)}.npz"
    if use_cache and path.is_file():
        try:
            return load_npz(path)
        except (ValueError, KeyError, OSError):
            pass  # corrupt cache entry: render again
    d = render_demonstration(gait_motion(robot, gait), robot, source=f"gait:{gait}", ground=ground)
    if use_cache:
        try:
            save_npz(d, path)
        except OSError:
            pass  # read-only home: still return the render
    return d


def motion_demonstration(motion: Motion, robot: str, source: str = "", ground: str = DEFAULT_GROUND) -> Demonstration:
    """Render a motion on ``robot``, retargeting it first when it belongs to another robot."""
    from virl_quad.demo.render import render_demonstration
    from virl_quad.motion.retarget import retarget

    if motion.robot and motion.robot != robot:
        motion = retarget(motion, robot)
    return render_demonstration(motion, robot, source=source or motion.name, ground=ground)


def _for_robot(d: Demonstration, robot: str) -> Demonstration:
    """A saved demonstration made usable on ``robot``: frames resampled to its control rate, and the
    reference motion dropped when it belongs to another robot."""
    spec = robots.get(robot)
    if d.robot == robot or (not d.robot and abs(d.fps - spec.control_hz) < 1e-6 * spec.control_hz):
        return d
    frames = d.frames
    if abs(d.fps - spec.control_hz) > 1e-6 * spec.control_hz:
        from virl_quad.demo.video_import import resample

        frames = np.clip(resample(d.frames, d.fps, spec.control_hz) + 0.5, 0, 255).astype(np.uint8)
    return Demonstration(frames=frames, fps=spec.control_hz, robot=robot, source=d.source, camera=d.camera,
                         motion=None, loop=d.loop, displacement=None)


def load(source: str | os.PathLike, robot: str, ground: str = DEFAULT_GROUND) -> Demonstration:
    """A demonstration for ``robot`` from ``source``.

    ``source``: a built-in gait name (rendered, cached), a ``.npz`` saved by ``save_npz``, a motion
    file (``.txt``/``.json`` motion_imitation clip or the Laikago recording; rendered, retargeted to
    Pupper when needed) or a video file (imported). Renders are made on ``ground`` ("checker" or
    "plain"; a ``.npz`` or a video is what it is). Raises FileNotFoundError for a missing file and a
    one-line ValueError for anything else that cannot be used (naming the valid gait names).
    """
    from virl_quad.motion.gaits import GAIT_NAMES
    from virl_quad.demo.render import load_npz

    robots.get(robot)
    text = str(source)
    name = text.removeprefix("gait:")  # renders of built-in gaits are labelled "gait:<name>"
    if name in GAIT_NAMES:
        return gait_demonstration(name, robot, ground=ground)
    path = Path(text)
    suffix = path.suffix.lower()
    if suffix not in (".npz",) + MOTION_SUFFIXES + VIDEO_SUFFIXES:
        raise _bad_source(text)
    if not path.is_file():
        raise FileNotFoundError(f"demonstration source not found: {path}")
    if suffix == ".npz":
        return _for_robot(load_npz(path), robot)
    if suffix in MOTION_SUFFIXES:
        from virl_quad.motion.motion_io import read_motion

        return motion_demonstration(read_motion(path), robot, source=str(path), ground=ground)
    from virl_quad.demo.video_import import import_video

    return import_video(path, robot)


__all__ = [
    "load", "gait_demonstration", "motion_demonstration", "cache_dir", "load_npz", "save_npz", "evaluate",
    "Demonstration", "MotionLike", "MotionState", "Motion", "GAIT_NAMES", "DEFAULT_GAIT", "CACHE_VERSION",
]
