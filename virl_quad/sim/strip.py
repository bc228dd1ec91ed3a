"""The speed strip: a frame's forward speed drawn into its bottom rows (pure numpy).

The follow camera keeps the robot centred, so on a plain ground a frame shows the legs
but not the travel. The strip puts the travel back beside the image, as the authors'
public code joined the base velocity to the image: the bottom :data:`STRIP_ROWS` rows
turn black with a white bar from the centre column, rightwards for forward travel,
leftwards for backward, half the width at the robot's ``strip_full_speed`` (m/s). The
bar's end pixel is partly lit, so the drawing is continuous in the speed, and the bar's
length can be read back from the pixels (:func:`bar_px`).
"""

from __future__ import annotations

import numpy as np

SIZE = 48          # px, frame side
STRIP_ROWS = 3     # px, bottom rows the strip overwrites
SPEED_WINDOW = 4   # control steps over which the strip's forward speed is measured (0.08 s at 50 Hz)
_HALF = SIZE // 2
_COLS = np.arange(SIZE, dtype=np.float64) + 0.5   # pixel centres, px


def bar_row(end_px) -> np.ndarray:
    """Coverage in [0, 1], [..., 48], of a bar from the centre to ``end_px`` (signed px from the
    centre, clipped to half the width)."""
    end = _HALF + np.clip(np.asarray(end_px, dtype=np.float64), -_HALF, _HALF)
    lo, hi = np.minimum(end, _HALF)[..., None], np.maximum(end, _HALF)[..., None]
    return np.clip(np.minimum(_COLS + 0.5, hi) - np.maximum(_COLS - 0.5, lo), 0.0, 1.0)


def stamp_speed(frames: np.ndarray, speed, full_speed: float) -> np.ndarray:
    """A copy of gray uint8 ``frames`` (..., 48, 48) with ``speed`` (m/s, one per frame) drawn in
    the strip, half the width at ``full_speed`` (m/s)."""
    out = np.array(frames, dtype=np.uint8, copy=True)
    if out.shape[-2:] != (SIZE, SIZE):
        raise ValueError(f"frames must be (..., {SIZE}, {SIZE}), got {out.shape}")
    v = np.broadcast_to(np.asarray(speed, dtype=np.float64), out.shape[:-2])
    if not np.all(np.isfinite(v)) or not full_speed > 0:
        raise ValueError("speed must be finite and full_speed positive")
    row = np.rint(bar_row(v / full_speed * _HALF) * 255.0).astype(np.uint8)
    out[..., SIZE - STRIP_ROWS:, :] = row[..., None, :]
    return out


def bar_px(frames: np.ndarray) -> np.ndarray:
    """The signed bar length (px) of float frames [..., 48, 48] in [0, 1], read from the last row."""
    row = np.asarray(frames)[..., -1, :]
    return row[..., _HALF:].sum(axis=-1) - row[..., :_HALF].sum(axis=-1)


def redraw(frames: np.ndarray, end_px) -> np.ndarray:
    """A copy of float frames [..., 48, 48] in [0, 1] with the strip redrawn ending at ``end_px``."""
    out = np.array(frames, dtype=np.float32, copy=True)
    out[..., SIZE - STRIP_ROWS:, :] = bar_row(end_px).astype(np.float32)[..., None, :]
    return out
