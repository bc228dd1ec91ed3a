"""The one observation builder: closed-form gravity, heading, NaN/inf rejection, layout."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from virl_quad import robots
from virl_quad.policy import observation as O


def test_projected_gravity_is_gravity_in_the_body_frame() -> None:
    quats = Rotation.random(500, random_state=3).as_quat()
    for q in quats:
        want = Rotation.from_quat(q).inv().apply([0.0, 0.0, -1.0])
        np.testing.assert_allclose(O.projected_gravity(q), want, atol=1e-12)
    np.testing.assert_allclose(O.projected_gravity([0, 0, 0, 1.0]), [0, 0, -1.0])


@pytest.mark.parametrize("block,value", [("gyro", np.nan), ("q", np.inf), ("dq", -np.inf), ("act", np.nan),
                                         ("dq", 1e300)])   # 1e300 * 0.05 overflows float32 to inf
def test_non_finite_input_is_refused(block: str, value: float) -> None:
    spec = robots.get("pupper")
    args = {"gyro": np.zeros(3), "q": spec.default_pose.copy(), "dq": np.zeros(12), "act": np.zeros(12)}
    args[block] = args[block].copy()
    args[block][1] = value
    with pytest.raises(ValueError, match="NaN or inf"):
        O.policy_observation(spec, [0, 0, 0, 1.0], args["gyro"], args["q"], args["dq"], args["act"], 0.25)
    args[block][1] = 3.0e4   # large but finite: accepted
    obs = O.policy_observation(spec, [0, 0, 0, 1.0], args["gyro"], args["q"], args["dq"], args["act"], 0.25)
    assert obs.dtype == np.float32 and obs.shape == (O.policy_size(True),) and np.all(np.isfinite(obs))


def test_policy_block_finds_each_block_in_the_built_observation():
    policy_block, policy_observation = O.policy_block, O.policy_observation
    spec = robots.get("pupper")
    q = np.asarray(spec.default_pose) + np.linspace(-0.3, 0.3, 12)
    last = np.linspace(-1.0, 1.0, 12)
    obs = policy_observation(spec, np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), q, np.zeros(12), last, 0.25)
    np.testing.assert_allclose(obs[policy_block("joint_pos_minus_default")], q - spec.default_pose, atol=1e-6)
    np.testing.assert_allclose(obs[policy_block("last_action")], last, atol=1e-6)
    np.testing.assert_allclose(obs[policy_block("phase_sin_cos")], [1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(obs[policy_block("heading_sin_cos")], [0.0, 1.0], atol=1e-6)
    with pytest.raises(KeyError):
        policy_block("phase_sin_cos", with_phase=False)
    # with a trajectory generator the last action has 14 entries, and the phase follows it
    last14 = np.linspace(-1.0, 1.0, 14)
    obs = policy_observation(spec, np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), q, np.zeros(12), last14, 0.5)
    assert obs.shape == (O.policy_size(True, 14),) == (48,)
    np.testing.assert_allclose(obs[policy_block("last_action", True, 14)], last14, atol=1e-6)
    np.testing.assert_allclose(obs[policy_block("phase_sin_cos", True, 14)], [0.0, -1.0], atol=1e-6)
    with pytest.raises(ValueError, match="sizes"):
        policy_observation(spec, np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), q, np.zeros(12), np.zeros(13))


def test_heading_is_the_yaw_relative_to_the_start() -> None:
    spec = robots.get("pupper")
    cols = O.policy_block("heading_sin_cos", with_phase=False)
    rng = np.random.default_rng(2)
    for _ in range(50):
        roll, pitch, yaw, start = rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-np.pi, np.pi), \
            rng.uniform(-np.pi, np.pi)
        quat = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()   # z-y-x: yaw, then pitch, roll
        assert O.yaw(quat) == pytest.approx(yaw, abs=1e-9)
        obs = O.policy_observation(spec, quat, np.zeros(3), spec.default_pose, np.zeros(12), np.zeros(12), None,
                                   start)
        np.testing.assert_allclose(obs[cols], [np.sin(yaw - start), np.cos(yaw - start)], atol=1e-6)
    with pytest.raises(ValueError, match="NaN or inf"):
        O.policy_observation(spec, [0, 0, 0, 1.0], np.zeros(3), spec.default_pose, np.zeros(12), np.zeros(12),
                             None, float("inf"))
