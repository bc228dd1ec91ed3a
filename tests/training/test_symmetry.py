"""The left-right mirror of observations and actions (rsl-rl symmetry augmentation)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from virl_quad import robots
from virl_quad.policy.observation import policy_observation
from virl_quad.training.symmetry import JOINT_SIGN, JOINT_SWAP, mirror_action, mirror_policy, phase_shift


def _mirror_quat(q: np.ndarray) -> np.ndarray:
    """xyzw of the orientation reflected in the xz plane (y -> -y)."""
    x, y, z, w = q
    return np.array([-x, y, -z, w])


@pytest.mark.parametrize("offsets,shift", [((0.0, 0.5, 0.5, 0.0), 0.5), ((0.0, 0.5, 0.0, 0.5), 0.5),
                                           ((0.0, 0.0, 0.5, 0.5), 0.0)])
def test_mirror_of_an_observation_is_the_observation_of_the_mirrored_robot(offsets, shift) -> None:
    spec = robots.get("pupper")
    rng = np.random.default_rng(0)
    assert phase_shift(offsets) == pytest.approx(shift)
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    gyro, q, dq, act = rng.normal(size=3), spec.default_pose + 0.2 * rng.normal(size=12), rng.normal(size=12), \
        rng.normal(size=14)
    phase, start_yaw = 0.3, 0.4
    obs = policy_observation(spec, quat, gyro, q, dq, act, phase, start_yaw)
    sw, sign = JOINT_SWAP, JOINT_SIGN.numpy()
    mirrored = policy_observation(spec, _mirror_quat(quat), gyro * [-1, 1, -1], spec.default_pose + (q - spec.default_pose)[sw] * sign,
                                  dq[sw] * sign, np.concatenate([act[:12][sw] * sign, act[12:]]),
                                  (phase + shift) % 1.0, -start_yaw)
    got = mirror_policy(torch.as_tensor(obs)[None], True, 14, shift)[0].numpy()
    np.testing.assert_allclose(got, mirrored, atol=1e-5)


def test_a_gait_without_a_mirror_is_refused() -> None:
    with pytest.raises(ValueError, match="not left-right symmetric"):
        phase_shift((0.0, 0.25, 0.5, 0.75))


def test_mirroring_twice_gives_the_action_back() -> None:
    a = torch.randn(5, 14)
    torch.testing.assert_close(mirror_action(mirror_action(a)), a)
