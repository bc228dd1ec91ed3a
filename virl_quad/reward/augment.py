"""Data augmentation: EESP windows and time warping of the demonstration.

EESP (cropping with early-episode priority): a window of L frames starts at
index i of an episode of n frames with p(i) proportional to n - i, and shorter
windows are more likely, p(L) proportional to L_max - L + 1, where L_max is
the current mean episode length clipped to [window_min, window_max].

Time warping: the clip is replayed at speed delta (frames of the clip per
output frame), with linear interpolation between neighbouring frames.

View jitter: each sequence is seen through its own small camera move, the same
zoom and shift for all of its frames (the agent's follow camera is jittered once
per episode).
"""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F


def eesp_max_length(mean_episode_length: float, lo: int, hi: int) -> int:
    """L_max: the mean episode length (frames) clipped to [lo, hi]."""
    if not np.isfinite(mean_episode_length):
        return hi
    return int(np.clip(round(mean_episode_length), lo, hi))


def eesp_length(rng: np.random.Generator, lo: int, l_max: int) -> int:
    """Draw a window length L in [lo, l_max] with p(L) proportional to l_max - L + 1 (shorter is likelier)."""
    if l_max <= lo:
        return lo
    lengths = np.arange(lo, l_max + 1)
    w = (l_max - lengths + 1).astype(np.float64)
    return int(rng.choice(lengths, p=w / w.sum()))


def eesp_start_probs(n: int, need: int) -> np.ndarray:
    """p(i) for the start i in [0, n - need] of a window of ``need`` frames in an episode of ``n``: ∝ n - i."""
    if need > n:
        raise ValueError(f"window of {need} frames does not fit an episode of {n}")
    w = (n - np.arange(n - need + 1)).astype(np.float64)
    return w / w.sum()


def eesp_start(rng: np.random.Generator, n: int, need: int) -> int:
    """Draw a window start with early-episode priority (see :func:`eesp_start_probs`)."""
    return int(rng.choice(n - need + 1, p=eesp_start_probs(n, need)))


def sample_speed(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A replay speed drawn log-uniformly in [lo, hi] (so 0.5x and 2x are equally likely)."""
    if hi <= lo:
        return float(lo)
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def time_warp(clip: np.ndarray, start: float, speed: float, length: int, cyclic: bool = False) -> np.ndarray:
    """Replay ``clip`` [T, H, W] from time ``start`` (frames) at ``speed`` for ``length`` output frames.

    Output frame k shows clip time start + k * speed, linearly interpolated
    between the two neighbouring frames, as float32 in [0, 1] (uint8 input is
    scaled by 1/255). With ``cyclic`` the time wraps around the clip's end;
    otherwise every time must lie in [0, T - 1].
    """
    T = clip.shape[0]
    t = start + speed * np.arange(length, dtype=np.float64)
    if cyclic:
        t = np.mod(t, T)
    elif t.min() < 0 or t.max() > T - 1 + 1e-9:
        raise ValueError(f"warped window [{t.min():.2f}, {t.max():.2f}] leaves the clip of {T} frames")
    i0 = np.floor(t).astype(np.int64)
    frac = (t - i0).astype(np.float32)[:, None, None]
    i0 = np.minimum(i0, T - 1)
    i1 = (i0 + 1) % T if cyclic else np.minimum(i0 + 1, T - 1)
    scale = np.float32(1.0 / 255.0) if clip.dtype == np.uint8 else np.float32(1.0)
    f0 = clip[i0].astype(np.float32) * scale
    f1 = clip[i1].astype(np.float32) * scale
    return f0 + frac * (f1 - f0)


def warped_window(rng: np.random.Generator, clip: np.ndarray, need: int, lo: float, hi: float,
                  cyclic: bool = False) -> tuple[np.ndarray, float]:
    """A window of ``need`` frames of ``clip`` at a random speed in [lo, hi] from a uniform start.

    Without ``cyclic`` the speed is capped so that the window fits (the clip
    must hold at least ``need`` frames). Returns (frames float32 [need, H, W], speed).
    """
    T = clip.shape[0]
    if not cyclic:
        if need > T:
            raise ValueError(f"window of {need} frames does not fit a clip of {T}")
        hi = min(hi, (T - 1) / max(need - 1, 1))
        lo = min(lo, hi)
    speed = sample_speed(rng, lo, hi)
    span = speed * (need - 1)
    start = rng.uniform(0.0, T) if cyclic else rng.uniform(0.0, max(T - 1 - span, 0.0))
    return time_warp(clip, start, speed, need, cyclic), speed


def view_jitter(x: np.ndarray, rng: np.random.Generator, zoom: float, shift: float) -> np.ndarray:
    """Sequences x float32 [L, B, H, W] in [0, 1], each seen through its own camera move: zoomed
    by a factor in [1 - zoom, 1 + zoom] (log-uniform) about the centre and shifted by up to
    ``shift`` px vertically and ``shift / 2`` horizontally (bilinear; the edge pixels, a painted
    background, extend outwards). The same move for every frame of a sequence."""
    if zoom == 0.0 and shift == 0.0:
        return x
    L, B, H, W = x.shape
    scale = np.exp(rng.uniform(np.log(1.0 - zoom), np.log(1.0 + zoom), B))
    dy = rng.uniform(-shift, shift, B) * 2.0 / H            # px -> normalised image coordinates
    dx = rng.uniform(-0.5 * shift, 0.5 * shift, B) * 2.0 / W
    theta = np.zeros((B, 2, 3), dtype=np.float32)
    theta[:, 0, 0] = theta[:, 1, 1] = 1.0 / scale            # sampling grid: output -> input
    theta[:, 0, 2], theta[:, 1, 2] = dx / scale, dy / scale  # the centre moves by exactly (dx, dy)
    t = torch.from_numpy(np.ascontiguousarray(x.transpose(1, 0, 2, 3)))      # [B, L, H, W]: frames as channels
    grid = F.affine_grid(torch.from_numpy(theta), [B, L, H, W], align_corners=False)
    out = F.grid_sample(t, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return out.numpy().transpose(1, 0, 2, 3).copy()
