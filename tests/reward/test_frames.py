"""What the distance model sees of a frame: the background painted out."""

from __future__ import annotations

import numpy as np

from virl_quad.reward.frames import background_levels, paint, painted_levels

SKY, DARK, LIGHT, ROBOT = 255, 95, 150, 40


def _scene(offsets, square: int = 10) -> np.ndarray:
    """[T, 48, 48] uint8: sky over a checker ground shifted by ``offsets[t]`` px, a dark robot block."""
    yy, xx = np.mgrid[0:48, 0:48]
    out = np.empty((len(offsets), 48, 48), dtype=np.uint8)
    for t, off in enumerate(offsets):
        img = np.where(((xx - int(off)) // square + yy // square) % 2 == 0, DARK, LIGHT).astype(np.uint8)
        img[:16] = SKY
        img[12:30, 16:32] = ROBOT
        out[t] = img
    return out


def test_a_flat_ground_paints_its_own_levels() -> None:
    frames = _scene(np.arange(10))
    np.testing.assert_array_equal(painted_levels(frames), background_levels(frames))
    painted = paint(frames, painted_levels(frames))
    assert set(np.unique(painted)) == {ROBOT, 255}


def test_a_textured_ground_leaves_the_darker_subject_alone() -> None:
    """A video resampled in time blends the checker into many levels; every level from the
    ground's darkest up is painted, so its frames and the env's sharp checker look alike."""
    frames = _scene(-np.arange(41)).astype(np.float32)
    blended = np.clip(0.5 * (frames[:-1] + frames[1:]) + np.random.default_rng(0).normal(0, 4, (40, 48, 48)),
                      0, 255).astype(np.uint8)
    levels = painted_levels(blended)
    assert levels[0] > ROBOT + 10 and levels[-1] == 255 and np.all(np.diff(levels) == 1)
    video, agent = paint(blended, levels), paint(_scene(np.arange(40) * 3), levels)
    block = np.zeros((48, 48), bool)
    block[12:30, 16:32] = True
    assert np.all(video[:, block] < 255) and np.all(agent[:, block] == ROBOT)      # the subject kept
    assert np.mean(video[:, ~block] < 255) < 1e-3                  # the ground gone from the video (noise aside)
    assert np.all(agent[:, ~block] == 255)                         # and from the agent's sharp checker
