"""Import any video (``.mp4``, ``.avi``, ...) as a 48x48 gray demonstration at the control rate.

Pipeline:

1. Read with OpenCV, shrinking large frames to at most ``WORK_SIZE`` px (INTER_AREA), to gray
   (BT.601 luma, as the simulator's frames).
2. Resample to the robot's control rate by linear interpolation between neighbouring frames.
3. Find the moving subject: median background over time, absolute difference, threshold,
   morphological opening; per frame the subject's centroid and bounding box.
4. Decide whether to follow it. The sim camera follows the robot, so the video must too:
   - static background (under ``MOVING_BG`` of the pixels differ from the median, and those
     pixels span at most ``SPREAD`` of the frame) and a subject that travels (a line fit of its centroid moves more than ``TRAVEL`` of the frame): crop a fixed-size
     square around the smoothed centroid, frame by frame, sized so the subject spans the same
     share of it as the robot does in the sim camera's view (:func:`robot_fill`);
   - otherwise the camera already follows the subject (the background moves, e.g. a rendered
     demonstration whose ground slides past) or nothing travels: keep the central square.
5. Resize to 48x48 with INTER_AREA.

Forward progress: in a followed crop, the background slides past as the ground texture does in
the simulator's follow camera, so progress stays visible in the frames; for a followed subject
the crop centre's travel is also returned as ``Demonstration.displacement`` (m, estimated from
the crop size and the sim camera's field of view).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from virl_quad import robots
from virl_quad.demo.demonstration import Demonstration
from virl_quad.sim.camera import FRAME_SIZE, CameraParams

WORK_SIZE = 320       # px, largest side kept while processing
DIFF_THRESHOLD = 25   # gray levels, |frame - background| counted as subject
MOVING_BG = 0.25      # share of differing pixels above which the background is taken as moving
TRAVEL = 0.15         # share of the frame the subject must travel to be followed
SPREAD = 0.8          # differing pixels spanning more of the frame than this: the background moves
SMOOTH = 5            # frames, moving-average window of the crop centre
MAX_SECONDS = 120.0   # s, longest video read


def read_video(path: str | os.PathLike, max_seconds: float = MAX_SECONDS) -> tuple[np.ndarray, float]:
    """Gray frames (N, H, W) uint8 (shrunk to at most WORK_SIZE px) and the video's fps (Hz).

    Raises FileNotFoundError for a missing file and a one-line ValueError for an unreadable or empty one.
    """
    import cv2

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"video file not found: {p}")
    from virl_quad.quiet import quiet_fd

    with quiet_fd(2):  # FFmpeg's own messages about broken files
        cap = cv2.VideoCapture(str(p))
    if not cap.isOpened():
        raise ValueError(f"cannot read video {p} (unsupported or corrupt file)")
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    if not (np.isfinite(fps) and 0.5 < fps < 1000.0):
        fps = 30.0
    frames = []
    try:
        while len(frames) < max_seconds * fps:
            with quiet_fd(2):
                ok, frame = cap.read()
            if not ok or frame is None:
                break
            h, w = frame.shape[:2]
            if max(h, w) > WORK_SIZE:
                s = WORK_SIZE / max(h, w)
                frame = cv2.resize(frame, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
            frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame)
    finally:
        cap.release()
    if not frames:
        raise ValueError(f"video {p} has no readable frames")
    return np.stack(frames), fps


def resample(frames: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Frames (N, H, W) at ``fps_in`` -> (M, H, W) float32 at ``fps_out`` (Hz), linear interpolation."""
    n = len(frames)
    m = max(1, int(np.floor(n * fps_out / fps_in + 1e-9)))
    pos = np.minimum(np.arange(m) * fps_in / fps_out, n - 1)
    i = np.floor(pos).astype(int)
    j = np.minimum(i + 1, n - 1)
    a = (pos - i)[:, None, None].astype(np.float32)
    f = frames.astype(np.float32)
    return (1.0 - a) * f[i] + a * f[j]


def subject_masks(frames: np.ndarray) -> np.ndarray:
    """Boolean masks (N, H, W) of the pixels that differ from the median background."""
    import cv2

    step = max(1, len(frames) // 200)
    background = np.median(frames[::step], axis=0).astype(np.float32)
    diff = np.abs(frames - background[None])
    kernel = np.ones((3, 3), np.uint8)
    masks = [cv2.morphologyEx((d > DIFF_THRESHOLD).astype(np.uint8), cv2.MORPH_OPEN, kernel) for d in diff]
    return np.stack(masks).astype(bool)


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average of a (N, 2) track, edges padded with the end values."""
    if window <= 1 or len(x) < 2:
        return x
    pad = window // 2
    padded = np.concatenate([np.repeat(x[:1], pad, 0), x, np.repeat(x[-1:], pad, 0)])
    kernel = np.ones(window) / window
    return np.column_stack([np.convolve(padded[:, k], kernel, mode="valid")[:len(x)] for k in range(2)])


def robot_fill(robot: str) -> float:
    """Share of the sim frame's side that the robot's silhouette spans (larger of width, height).

    Rendered once in the default pose with the robot's follow camera, against the empty scene.
    """
    from virl_quad.sim import camera
    from virl_quad.sim.world import World

    spec = robots.get(robot)
    cam = CameraParams.from_spec(spec)
    target = np.array([0.0, 0.0, spec.spawn_height])
    with World(spec) as world:
        world.set_pose(target, [0, 0, 0, 1], spec.default_pose)
        with_robot = camera.render(world.client, target, cam, 96).astype(np.int16)
        world.set_pose([0.0, 0.0, -50.0], [0, 0, 0, 1], spec.default_pose)
        empty = camera.render(world.client, target, cam, 96).astype(np.int16)
    ys, xs = np.nonzero(np.abs(with_robot - empty) > DIFF_THRESHOLD)
    if len(xs) == 0:
        return 0.6
    return float(max(np.ptp(xs), np.ptp(ys)) + 1) / 96.0


def track_subject(frames: np.ndarray, fill: float = 0.6) -> dict:
    """Where the moving subject is, and whether to follow it.

    Returns ``track`` (N, 2) px (x, y) smoothed centroids (None when no subject is found in a
    quarter of the frames), ``side`` the crop side (px) at which the subject's median extent spans
    ``fill`` of it, ``follow`` the decision (see module doc) and the figures behind it.
    """
    n, h, w = frames.shape
    masks = subject_masks(frames)
    share = masks.reshape(n, -1).mean(axis=1)
    centres = np.full((n, 2), np.nan)
    extents = np.zeros(n)
    for k, m in enumerate(masks):
        ys, xs = np.nonzero(m)
        if len(xs) >= 4:
            centres[k] = (xs.mean(), ys.mean())
            extents[k] = max(np.ptp(xs) / w, np.ptp(ys) / h)
    found = ~np.isnan(centres[:, 0])
    # A moving camera (or a background that changes) makes most of the frame differ from the median,
    # or makes the differing pixels spread over (nearly) the whole frame.
    spread = float(np.median(extents[found])) if found.any() else 0.0
    moving_background = float(np.median(share)) > MOVING_BG or spread > SPREAD
    track, side, travel = None, float(min(h, w)), 0.0
    if found.sum() >= max(2, n // 4):
        idx = np.arange(n)
        for c in range(2):  # fill frames without a subject from their neighbours
            centres[:, c] = np.interp(idx, idx[found], centres[found, c])
        # Net travel: slope of a straight-line fit (periodic limb motion in place averages out).
        slopes = [np.polyfit(idx[found], centres[found, c], 1)[0] for c in range(2)]
        travel = float(max(abs(slopes[0]) * n / w, abs(slopes[1]) * n / h))
        track = _smooth(centres, SMOOTH)
        side = float(np.clip(np.median(extents[found]) * max(w, h) / fill, 16, min(h, w)))
    return {"track": track, "side": side, "follow": bool(track is not None and not moving_background
                                                          and travel > TRAVEL),
            "moving_background": moving_background, "subject_share": float(np.median(share)),
            "spread": spread, "travel": travel}


def crop_frames(frames: np.ndarray, centres: np.ndarray, side: float, size: int = FRAME_SIZE) -> np.ndarray:
    """Square crops of ``side`` px around ``centres`` (N, 2), resized to ``size`` px (INTER_AREA), uint8."""
    import cv2

    out = np.empty((len(frames), size, size), np.uint8)
    s = max(1, int(round(side)))
    for k, (f, c) in enumerate(zip(frames, centres)):
        patch = cv2.getRectSubPix(f.astype(np.float32), (s, s), (float(c[0]), float(c[1])))
        out[k] = np.clip(cv2.resize(patch, (size, size), interpolation=cv2.INTER_AREA) + 0.5, 0, 255)
    return out


def import_video(path: str | os.PathLike, robot: str, follow: bool | None = None,
                 max_seconds: float = MAX_SECONDS) -> Demonstration:
    """Import a video file as a :class:`Demonstration` for ``robot`` (frames at its control rate).

    ``follow``: force (True) or forbid (False) following the subject; None decides from the video.
    """
    spec = robots.get(robot)
    raw, fps_in = read_video(path, max_seconds)
    frames = resample(raw, fps_in, spec.control_hz)
    info = track_subject(frames, robot_fill(robot))
    followed = info["follow"] if follow is None else bool(follow)
    if followed and info["track"] is None:
        raise ValueError(f"video {path}: no moving subject found to follow")
    h, w = frames.shape[1:]
    if followed:
        centres, side = info["track"], info["side"]
    else:
        centres, side = np.tile([(w - 1) / 2.0, (h - 1) / 2.0], (len(frames), 1)), float(min(h, w))
    out = crop_frames(frames, centres, side)
    cam = CameraParams.from_spec(spec)
    displacement = None
    if followed:
        view = 2.0 * cam.distance * np.tan(np.radians(cam.fov) / 2.0)   # m seen across the sim frame
        displacement = np.column_stack([centres[:, 0] - centres[0, 0], -(centres[:, 1] - centres[0, 1])]) / side * view
    camera = dataclasses.asdict(cam)
    camera.update(imported_fps=fps_in, followed=followed, crop_side_px=side)
    return Demonstration(frames=out, fps=spec.control_hz, robot=robot, source=str(path), camera=camera,
                         motion=None, loop=True, displacement=displacement)
