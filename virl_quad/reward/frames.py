"""Input checking and conversion of grayscale frames.

Frames are uint8 in [0, 255] or float in [0, 1], numpy arrays or torch tensors,
with the two last axes the 48x48 image. Anything else raises a one-line
ValueError; nothing is broadcast silently.
"""

from __future__ import annotations

import numpy as np
import torch

FRAME = 48  # px


def check_frames(x, name: str, axes: str, size: int = FRAME) -> None:
    """Raise ValueError unless ``x`` has shape [*axes, size, size], a frame dtype and finite values.

    ``axes`` names the leading axes, one letter each: "N" for [N, H, W], "TN" for [T, N, H, W].
    """
    lead = len(axes)
    if not isinstance(x, (np.ndarray, torch.Tensor)):
        raise ValueError(f"{name}: expected a numpy array or torch tensor, got {type(x).__name__}")
    shape = tuple(x.shape)
    want = "[" + "".join(f"{a}, " for a in axes) + f"{size}, {size}]"
    if len(shape) != lead + 2 or shape[-2:] != (size, size):
        raise ValueError(f"{name}: expected shape {want}, got {list(shape)}")
    if any(s == 0 for s in shape[:lead]):
        raise ValueError(f"{name}: empty input, shape {list(shape)}")
    if isinstance(x, np.ndarray):
        kind = x.dtype
        if kind == np.uint8:
            return
        if not np.issubdtype(kind, np.floating):
            raise ValueError(f"{name}: dtype must be uint8 or float, got {kind}")
        if not np.isfinite(x).all():
            raise ValueError(f"{name}: frames contain NaN or inf")
        lo, hi = float(x.min()), float(x.max())
    else:
        if x.dtype == torch.uint8:
            return
        if not x.is_floating_point():
            raise ValueError(f"{name}: dtype must be uint8 or float, got {x.dtype}")
        if not bool(torch.isfinite(x).all()):
            raise ValueError(f"{name}: frames contain NaN or inf")
        lo, hi = float(x.min()), float(x.max())
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{name}: float frames must lie in [0, 1], got range [{lo:.3g}, {hi:.3g}]")


def to_float(x, name: str, axes: str, device: torch.device | str = "cpu") -> torch.Tensor:
    """Check ``x`` (see :func:`check_frames`) and return float32 frames in [0, 1] on ``device``."""
    check_frames(x, name, axes)
    t = torch.from_numpy(np.ascontiguousarray(x)) if isinstance(x, np.ndarray) else x
    t = t.to(device)
    if t.dtype == torch.uint8:
        return t.to(torch.float32).mul_(1.0 / 255.0)
    return t.to(torch.float32)


def to_uint8(x, name: str, axes: str) -> np.ndarray:
    """Check ``x`` and return a contiguous uint8 numpy copy (float frames are scaled by 255 and rounded)."""
    check_frames(x, name, axes)
    a = x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
    if a.dtype != np.uint8:
        a = np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
    return np.array(a, dtype=np.uint8, copy=True, order="C")


def to_mask(m, name: str, shape: tuple[int, ...], device: torch.device | str = "cpu") -> torch.Tensor:
    """Return a bool tensor of exactly ``shape`` from a bool or 0/1 array/tensor; else ValueError."""
    if not isinstance(m, (np.ndarray, torch.Tensor)):
        raise ValueError(f"{name}: expected a numpy array or torch tensor, got {type(m).__name__}")
    if tuple(m.shape) != tuple(shape):
        raise ValueError(f"{name}: expected shape {list(shape)}, got {list(m.shape)}")
    t = torch.from_numpy(np.ascontiguousarray(m)) if isinstance(m, np.ndarray) else m
    if t.dtype != torch.bool:
        if t.is_floating_point() and not bool(torch.isfinite(t).all()):
            raise ValueError(f"{name}: mask contains NaN or inf")
        if not bool(((t == 0) | (t == 1)).all()):
            raise ValueError(f"{name}: mask must be bool or 0/1")
        t = t != 0
    return t.to(device)


BACKGROUND_SHARE = 0.1   # a gray level filling this share of the top or bottom rows is background
BORDER_ROWS = 2          # px rows at the top and at the bottom that show only sky and ground
TOLERANCE = 6            # gray levels: a pixel this close to a background level is background too
                         # (a video file's codec moves flat areas by a few levels; a render's
                         # robot shades sit farther than this from its sky and ground)
PAINT = 255              # the background's new gray level: white (a mid gray, the ground's own,
                         # let the distance model collapse, every frame alike: docs/experiments.md)


FLAT_SHARE = 0.8         # share of a video's bottom rows its flat background levels must fill; else its
                         # ground is textured (a video resampled to the control rate blends the
                         # checker between frames into many levels)


def textured_ground(frames: np.ndarray) -> tuple[int, int] | None:
    """The gray-level range (lo, hi) of a video's ground (T, H, W) uint8 when it is textured: its
    flat levels (:func:`background_levels`) fill less than :data:`FLAT_SHARE` of its bottom
    :data:`BORDER_ROWS` rows; the 1st to 99th percentile of those rows, widened by
    :data:`TOLERANCE`. None for a flat ground."""
    frames = np.asarray(frames, dtype=np.uint8)
    ground = frames[:, -BORDER_ROWS:]
    if level_table(background_levels(frames))[ground].mean() >= FLAT_SHARE:
        return None
    lo, hi = np.percentile(ground, [1, 99])
    return max(0, int(lo) - TOLERANCE), min(255, int(hi) + TOLERANCE)


def background_levels(frames: np.ndarray) -> np.ndarray:
    """The gray levels that count as the flat background of a video (T, H, W) uint8: those filling
    at least :data:`BACKGROUND_SHARE` of its top or bottom :data:`BORDER_ROWS` rows (sky and ground
    of a render; none for a textured background), and every level within :data:`TOLERANCE` of
    one. int64 array, sorted."""
    frames = np.asarray(frames, dtype=np.uint8)
    return flat_levels(frames[:, :BORDER_ROWS], frames[:, -BORDER_ROWS:])


def flat_levels(*strips: np.ndarray) -> np.ndarray:
    """The gray levels filling at least :data:`BACKGROUND_SHARE` of any of the uint8 ``strips``
    (rows of a video), each widened by :data:`TOLERANCE`. int64 array, sorted (empty: none)."""
    levels: set[int] = set()
    for rows in strips:
        counts = np.bincount(np.asarray(rows, dtype=np.uint8).reshape(-1), minlength=256)
        levels.update(int(v) for v in np.flatnonzero(counts >= BACKGROUND_SHARE * rows.size))
    if not levels:
        return np.zeros(0, np.int64)
    lv = np.array(sorted(levels), dtype=np.int64)
    return np.unique(np.clip(lv[:, None] + np.arange(-TOLERANCE, TOLERANCE + 1)[None], 0, 255))


def level_table(levels) -> np.ndarray:
    """A 256-entry bool table, True at each of ``levels`` (gray levels 0-255): ``table[frames]``
    is ``np.isin(frames, levels)`` for uint8 frames, at a fraction of its cost."""
    table = np.zeros(256, dtype=bool)
    table[np.asarray(levels, dtype=np.int64)] = True
    return table


def painted_levels(demo: np.ndarray) -> np.ndarray:
    """The gray levels the distance model paints white in every frame, from its demonstration
    (T, H, W) uint8: the flat background's (:func:`background_levels`), or on a textured ground
    (:func:`dark_level`: a video resampled in time, a real scene) every level from the
    ground's low end up, so that the darker subject alone is left: the agent's frames show the
    env's own ground, and a ground drawn otherwise than the video's (sharper, another pattern)
    would tell the two apart at a glance. int64 array, sorted."""
    level = dark_level(demo)
    return background_levels(demo) if level is None else np.arange(level, 256, dtype=np.int64)


def dark_level(video: np.ndarray) -> int | None:
    """For a video (T, H, W) uint8 on a textured ground (:func:`textured_ground`), the gray level
    below which a pixel is the subject: the low end of the ground's range. None for a flat
    ground, or a textured one with nothing darker than it (the frames are then used as they are)."""
    ground = textured_ground(video)
    return ground[0] if ground is not None and ground[0] > 0 else None


def paint(frames: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """uint8 frames with every pixel at one of ``levels`` (:func:`background_levels`) set to white
    (:data:`PAINT`): the robot's silhouette, with its shading, on a blank background."""
    frames = np.asarray(frames, dtype=np.uint8)
    if len(levels) == 0:
        return frames.copy()
    return np.where(level_table(levels)[frames], np.uint8(PAINT), frames)


def paint_float(x: torch.Tensor, levels: torch.Tensor) -> torch.Tensor:
    """:func:`paint` for float frames in [0, 1] (levels as an int64 tensor on x's device)."""
    if levels.numel() == 0:
        return x
    table = torch.from_numpy(level_table(levels.cpu().numpy())).to(x.device)
    hit = table[torch.round(x * 255.0).to(torch.int64).clamp_(0, 255)]
    return torch.where(hit, torch.full_like(x, PAINT / 255.0), x)
