"""EESP windows and demonstration time warping."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad.reward import augment


def test_eesp_start_probabilities_follow_len_minus_i():
    p = augment.eesp_start_probs(20, 5)                # starts 0..15, p ∝ 20 - i
    want = (20 - np.arange(16)) / (20 - np.arange(16)).sum()
    assert np.allclose(p, want)
    rng = np.random.default_rng(0)
    starts = np.array([augment.eesp_start(rng, 20, 5) for _ in range(20000)])
    freq = np.bincount(starts, minlength=16) / starts.size
    assert np.abs(freq - want).max() < 0.01
    assert starts.max() <= 15                           # the window always fits


def test_eesp_lengths_shorter_more_likely_and_scaled_by_mean_episode():
    rng = np.random.default_rng(0)
    ls = np.array([augment.eesp_length(rng, 8, 20) for _ in range(20000)])
    assert ls.min() == 8 and ls.max() <= 20
    counts = np.bincount(ls, minlength=21)[8:]
    assert (np.diff(counts[::3]) < 0).all()            # decreasing with length
    assert augment.eesp_max_length(12.4, 8, 64) == 12  # mean episode length caps the window
    assert augment.eesp_max_length(500, 8, 64) == 64
    assert augment.eesp_max_length(3, 8, 64) == 8
    assert augment.eesp_max_length(float("nan"), 8, 64) == 64


def test_time_warp_linear_interpolation():
    clip = (np.arange(10, dtype=np.uint8) * 20)[:, None, None] * np.ones((1, 48, 48), np.uint8)
    vals = lambda w: np.round(w[:, 0, 0] * 255).tolist()
    assert vals(augment.time_warp(clip, 0, 1.0, 10)) == [20.0 * i for i in range(10)]
    assert vals(augment.time_warp(clip, 0, 2.0, 5)) == [0.0, 40.0, 80.0, 120.0, 160.0]
    assert vals(augment.time_warp(clip, 1, 0.5, 4)) == [20.0, 30.0, 40.0, 50.0]   # midpoints averaged
    assert vals(augment.time_warp(clip, 8, 1.0, 4, cyclic=True)) == [160.0, 180.0, 0.0, 20.0]
    with pytest.raises(ValueError):
        augment.time_warp(clip, 5, 1.0, 6)


def test_warped_window_speed_range():
    rng = np.random.default_rng(0)
    clip = np.zeros((100, 48, 48), np.uint8)
    speeds = np.array([augment.warped_window(rng, clip, 20, 0.5, 2.0)[1] for _ in range(2000)])
    assert speeds.min() >= 0.5 and speeds.max() <= 2.0
    assert (speeds < 0.7).mean() > 0.1 and (speeds > 1.5).mean() > 0.1
    # a short clip caps the speed so the window fits
    short = np.zeros((30, 48, 48), np.uint8)
    capped = [augment.warped_window(rng, short, 25, 0.5, 2.0)[1] for _ in range(200)]
    assert max(capped) <= 29 / 24 + 1e-9


def _square_frames(L: int = 3, B: int = 6) -> np.ndarray:
    """[L, B, 48, 48] white frames with a dark 8 px square in the middle (a painted render's look)."""
    x = np.ones((L, B, 48, 48), dtype=np.float32)
    x[:, :, 20:28, 20:28] = 0.0
    return x


def test_view_jitter_moves_each_sequence_by_its_own_small_camera_move():
    x = _square_frames()
    y = augment.view_jitter(x, np.random.default_rng(0), 0.05, 2.0)
    assert y.shape == x.shape and y.dtype == np.float32 and y.min() >= 0.0 and y.max() <= 1.0
    assert np.array_equal(y[0], y[2])                  # one move for every frame of a sequence
    assert any(not np.allclose(y[0, 0], y[0, b]) for b in range(1, 6))   # each sequence its own
    for b in range(6):
        dark = 1.0 - y[0, b]
        rows, cols = np.mgrid[0:48, 0:48]
        cy, cx = (dark * rows).sum() / dark.sum(), (dark * cols).sum() / dark.sum()
        assert abs(cy - 23.5) <= 2.0 + 1e-3 and abs(cx - 23.5) <= 1.0 + 1e-3      # px
        assert 64 * 0.95 ** 2 - 1 <= dark.sum() <= 64 * 1.05 ** 2 + 1               # area: zoom +-5 %
    assert np.array_equal(augment.view_jitter(x, np.random.default_rng(0), 0.0, 0.0), x)


def test_view_jitter_zooms_and_shifts_as_far_as_asked():
    x = _square_frames(1, 400)
    y = augment.view_jitter(x, np.random.default_rng(1), 0.2, 4.0)
    dark = 1.0 - y[0]
    rows = np.arange(48)[None, :, None]
    cy = (dark * rows).sum((1, 2)) / dark.sum((1, 2))
    assert cy.min() < 23.5 - 3.0 and cy.max() > 23.5 + 3.0          # shifts fill the range
    area = dark.sum((1, 2)) / 64
    assert area.min() < 0.8 ** 2 * 1.1 and area.max() > 1.2 ** 2 * 0.9   # zooms fill the range
