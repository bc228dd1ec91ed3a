"""Measurements of the demo pipeline: video round trip and the visibility of forward progress.

- :func:`roundtrip`: render a gait -> ``.mp4`` -> :func:`~virl_quad.demo.video_import.import_video`,
  and the mean absolute error (gray levels of 255) of the imported frames against the rendered ones.
- :func:`progress_visibility`: the follow camera keeps the robot still in the frame, so forward
  progress shows only as the ground texture sliding past. Rendered forward and in place, then
  both imported, the ground strip below the robot should change from frame to frame only in the
  forward demo; reported as the mean frame-to-frame change of that strip and its horizontal shift
  (px/frame, phase correlation).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from virl_quad import robots

GROUND_ROWS = slice(38, 48)  # px rows of the 48x48 frame below the robot's feet


def _mae(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(a.astype(np.float64) - b.astype(np.float64))))


def ground_motion(frames: np.ndarray) -> tuple[float, float]:
    """Mean |frame-to-frame change| of the ground strip (gray levels) and its median shift (px/frame)."""
    import cv2

    g = np.asarray(frames, dtype=np.float32)[:, GROUND_ROWS, :]
    change = float(np.mean(np.abs(np.diff(g, axis=0))))
    shifts = [cv2.phaseCorrelate(g[i], g[i + 1])[0][0] for i in range(len(g) - 1)]
    return change, float(np.median(shifts))


def roundtrip(robot: str, gait: str = "trot", preview: str = "render", folder: str | Path | None = None,
              seconds: float = 2.0, **gait_overrides) -> dict:
    """Render ``gait`` with an ``.mp4`` preview, import the video, compare with the rendered frames.

    Returns ``mae`` (gray levels), frame counts, whether the importer followed a subject, the
    rendered and imported demonstrations.
    """
    from virl_quad.motion.gaits import gait_motion
    from virl_quad.demo.render import render_demonstration
    from virl_quad.demo.video_import import import_video

    robots.get(robot)
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(folder or tmp) / f"{robot}_{gait}_{preview}.mp4"
        rendered = render_demonstration(gait_motion(robot, gait, **gait_overrides), robot, min_seconds=seconds,
                                        video=video, preview=preview)
        imported = import_video(video, robot)
    n = min(rendered.num_frames, imported.num_frames)
    return {"mae": _mae(rendered.frames[:n], imported.frames[:n]), "rendered_frames": rendered.num_frames,
            "imported_frames": imported.num_frames, "followed": bool(imported.camera.get("followed")),
            "rendered": rendered, "imported": imported}


def progress_visibility(robot: str, gait: str = "trot", preview: str = "render", seconds: float = 2.0) -> dict:
    """Ground-strip motion of the forward and in-place versions of ``gait``, rendered and imported."""
    fwd = roundtrip(robot, gait, preview, seconds=seconds)
    still = roundtrip(robot, gait, preview, seconds=seconds, speed=0.0)
    out = {"roundtrip_mae_forward": fwd["mae"], "roundtrip_mae_in_place": still["mae"],
           "forward_vs_in_place_imported_mae": _mae(fwd["imported"].frames, still["imported"].frames)}
    for name, d in (("rendered_forward", fwd["rendered"]), ("rendered_in_place", still["rendered"]),
                    ("imported_forward", fwd["imported"]), ("imported_in_place", still["imported"])):
        change, shift = ground_motion(d.frames)
        out[f"{name}_ground_change"] = change
        out[f"{name}_ground_shift_px"] = shift
    return out
