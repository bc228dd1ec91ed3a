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
