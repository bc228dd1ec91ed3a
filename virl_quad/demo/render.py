"""Demonstration videos: play a motion kinematically on the robot and film it with the env's camera.

The motion is placed pose by pose on a PyBullet copy of the robot (``World.set_pose``, no
physics) and rendered by ``World.render`` with ``CameraParams.from_spec(spec)``: the very
camera and renderer the environment uses for the agent, 48x48 gray, one frame per control
step (``spec.control_hz``). A looping motion is first time-warped by a few percent so one
cycle lasts a whole number of control steps; the demonstration then covers whole cycles
and loops seamlessly (the attached motion is the warped one, so RSI and the score agree
with the frames).

Storage: a compact ``.npz`` with the frames, fps, robot, source, camera (JSON), the loop
flag, the root displacement and the reference motion's arrays (rebuilt by
:func:`load_npz`); optionally an ``.mp4`` (OpenCV, mp4v) of a larger RGB preview.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from virl_quad import robots
from virl_quad.demo.demonstration import Demonstration
from virl_quad.motion.motion import Motion, heading
from virl_quad.sim.camera import FRAME_SIZE, CameraParams
from virl_quad.sim.params import DEFAULT_GROUND

PREVIEW_SIZE = 256   # px, side of the RGB preview video
PREVIEWS = ("render", "frames")  # preview video: a larger render, or the 48 px frames enlarged 5x
MAX_LOOP_WARP = 0.1  # largest relative speed change used to make a cycle a whole number of frames
NPZ_VERSION = 1


def fit_loop(motion: Motion, fps: float) -> Motion:
    """A looping motion time-warped so one cycle lasts a whole number of frames at ``fps`` (Hz).

    Clamped motions, and loops that would need more than a 10 % speed change, are returned unchanged.
    """
    if not motion.loop:
        return motion
    exact = motion.duration * fps
    n = max(1, int(round(exact)))
    speed = exact / n
    if abs(speed - 1.0) < 1e-9 or abs(speed - 1.0) > MAX_LOOP_WARP:
        return motion
    return motion.retimed(speed)


def frame_count(motion: Motion, fps: float, min_seconds: float = 2.0) -> int:
    """Frames to render: whole cycles covering at least ``min_seconds`` (s) for a loop, else the clip."""
    per_cycle = max(1, int(round(motion.duration * fps)))
    if not motion.loop:
        return per_cycle + 1
    cycles = max(1, int(np.ceil(min_seconds * fps / per_cycle - 1e-9)))
    return cycles * per_cycle


def render_motion(motion: Motion, robot: str, num_frames: int, fps: float | None = None,
                  cam: CameraParams | None = None, preview_size: int = 0,
                  fixed_target: np.ndarray | None = None,
                  ground: str = DEFAULT_GROUND) -> tuple[np.ndarray, np.ndarray | None]:
    """Render ``num_frames`` frames of ``motion`` at ``fps`` (default: the control rate) from t = 0,
    on the ``ground`` ("checker" or "plain").

    Returns gray frames (T, 48, 48) uint8 and, when ``preview_size`` > 0, RGB frames (T, S, S, 3) uint8.
    Joint angles are clipped to the robot's limits, as the environment does. ``fixed_target`` (m, world):
    a static camera looking at that point instead of the follow camera (to make test videos).
    """
    from virl_quad.sim import camera
    from virl_quad.sim.world import World

    spec = robots.get(robot)
    fps = spec.control_hz if fps is None else fps
    cam = cam or CameraParams.from_spec(spec)
    gray = np.empty((num_frames, FRAME_SIZE, FRAME_SIZE), np.uint8)
    rgb = np.empty((num_frames, preview_size, preview_size, 3), np.uint8) if preview_size else None
    world = World(spec, ground=ground)
    try:
        for i in range(num_frames):
            pos, quat, q = motion.pose_at(i / fps)
            world.set_pose(pos, quat, spec.clip_to_limits(q))
            if fixed_target is not None:
                gray[i] = camera.render(world.client, np.asarray(fixed_target, dtype=np.float64), cam)
                if rgb is not None:
                    rgb[i] = camera.render(world.client, np.asarray(fixed_target, dtype=np.float64), cam,
                                           preview_size, rgb=True)
                continue
            gray[i] = world.render(cam=cam)
            if rgb is not None:
                rgb[i] = world.render(size=preview_size, rgb=True, cam=cam)
    finally:
        world.close()
    return gray, rgb


def root_displacement(motion: Motion, num_frames: int, fps: float) -> np.ndarray:
    """(T, 2) m: root travel along the first frame's heading (forward) and root height change (vertical)."""
    pos = motion.poses(np.arange(num_frames) / fps)[0]
    yaw = float(heading(motion.root_quat[0]))
    direction = np.array([np.cos(yaw), np.sin(yaw)])
    forward = (pos[:, :2] - pos[0, :2]) @ direction
    return np.column_stack([forward, pos[:, 2] - pos[0, 2]])


def write_mp4(frames: np.ndarray, fps: float, path: str | os.PathLike) -> Path:
    """Write gray (T, H, W) or RGB (T, H, W, 3) uint8 frames to an ``.mp4`` (mp4v) at ``fps`` (Hz)."""
    import cv2

    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim not in (3, 4) or len(frames) == 0:
        raise ValueError(f"video frames must be (T, H, W[, 3]) with T > 0, got {frames.shape}")
    h, w = frames.shape[1:3]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (w, h))
    if not writer.isOpened():
        raise ValueError(f"cannot open a video writer for {path}")
    try:
        for f in frames:
            writer.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) if f.ndim == 2 else cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    return path


def enlarge(frames: np.ndarray, factor: int = 5) -> np.ndarray:
    """Gray frames (T, H, W) enlarged ``factor`` times (pixel blocks) as RGB (T, fH, fW, 3) uint8."""
    big = np.repeat(np.repeat(np.asarray(frames, dtype=np.uint8), factor, axis=1), factor, axis=2)
    return np.repeat(big[..., None], 3, axis=3)


def render_demonstration(motion: Motion, robot: str, source: str = "", min_seconds: float = 2.0,
                         video: str | os.PathLike | None = None, preview_size: int = PREVIEW_SIZE,
                         cam: CameraParams | None = None, preview: str = "frames",
                         ground: str = DEFAULT_GROUND) -> Demonstration:
    """Render ``motion`` (of ``robot``) into a :class:`Demonstration` at the control rate, on
    the ``ground`` ("checker" or "plain"; recorded as ``camera["ground"]``).

    ``video``: also write an ``.mp4`` there: ``preview="render"`` a larger RGB render
    (``preview_size`` px square, same camera); ``preview="frames"`` the 48x48 frames themselves,
    enlarged 5x (what the reward sees; imports back to the frames almost exactly).
    """
    if preview not in PREVIEWS:
        raise ValueError(f"unknown preview {preview!r}; choose one of: {', '.join(PREVIEWS)}")
    spec = robots.get(robot)
    if motion.robot and motion.robot != robot:
        raise ValueError(f"motion {motion.name!r} is for {motion.robot}, not {robot}; retarget it first")
    fps = spec.control_hz
    cam = cam or CameraParams.from_spec(spec)
    motion = fit_loop(motion, fps)
    n = frame_count(motion, fps, min_seconds)
    big = preview_size if (video is not None and preview == "render") else 0
    gray, rgb = render_motion(motion, robot, n, fps, cam, big, ground=ground)
    if video is not None:
        write_mp4(rgb if preview == "render" else enlarge(gray), fps, video)
    return Demonstration(frames=gray, fps=fps, robot=robot, source=source or motion.name,
                         camera={**dataclasses.asdict(cam), "ground": ground}, motion=motion, loop=motion.loop,
                         displacement=root_displacement(motion, n, fps))


def save_npz(demo: Demonstration, path: str | os.PathLike) -> Path:
    """Save a demonstration as a compressed ``.npz`` (atomic write); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {
        "version": np.int64(NPZ_VERSION), "frames": demo.frames, "fps": np.float64(demo.fps),
        "robot": np.str_(demo.robot), "source": np.str_(demo.source),
        "camera": np.str_(json.dumps(demo.camera)), "loop": np.bool_(demo.loop),
    }
    if demo.displacement is not None:
        arrays["displacement"] = np.asarray(demo.displacement, dtype=np.float64)
    if isinstance(demo.motion, Motion):
        arrays.update(demo.motion.to_arrays())
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)
    return path


def load_npz(path: str | os.PathLike) -> Demonstration:
    """Load a demonstration saved by :func:`save_npz` (motion rebuilt when stored)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"demonstration file not found: {path}")
    import zipfile

    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a demonstration .npz (not a zip archive)")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot read demonstration {path}: {e}") from None
    if "frames" not in data or "fps" not in data:
        raise ValueError(f"{path} is not a demonstration .npz (needs 'frames' and 'fps')")
    motion = Motion.from_arrays(data) if "motion_root_pos" in data else None
    return Demonstration(frames=data["frames"], fps=float(data["fps"]), robot=str(data.get("robot", "")),
                         source=str(data.get("source", "")),
                         camera=json.loads(str(data["camera"])) if "camera" in data else {},
                         motion=motion, loop=bool(data.get("loop", True)),
                         displacement=data.get("displacement"))
