"""The agent's pose drawn on another robot's body (virl_quad.sim.shadow), real PyBullet."""

import numpy as np
import pytest

from virl_quad import envs, robots
from virl_quad.policy.legs import LegKinematics
from virl_quad.sim.shadow import Shadow

PUPPER, LAIKAGO = robots.get("pupper"), robots.get("laikago")


@pytest.fixture(scope="module")
def shadow():
    s = Shadow(PUPPER, LAIKAGO, "checker")
    yield s
    s.close()


def test_the_default_pose_is_the_bodys_default_pose(shadow):
    pos, quat, q = shadow.pose(np.array([0.0, 0.0, PUPPER.spawn_height]), np.array([0, 0, 0, 1.0]),
                               PUPPER.default_pose)
    np.testing.assert_allclose(pos, [0.0, 0.0, LAIKAGO.spawn_height], atol=1e-9)
    np.testing.assert_allclose(q, LAIKAGO.default_pose, atol=1e-6)


def test_travel_height_and_feet_scale_by_leg_length(shadow):
    assert shadow.k == pytest.approx(2.65, abs=0.05)                 # 0.50 m / 0.19 m legs
    src, dst = LegKinematics(PUPPER), LegKinematics(LAIKAGO)
    feet = src.forward(PUPPER.default_pose)
    feet[0, 0] += 0.01                                               # FR foot 1 cm forward
    feet[3, 2] += 0.005                                              # RL foot lifted 5 mm
    q = src.inverse(feet)
    pos, _, q_body = shadow.pose(np.array([0.3, -0.1, PUPPER.spawn_height - 0.01]), np.array([0, 0, 0, 1.0]), q)
    np.testing.assert_allclose(pos, [0.3 * shadow.k, -0.1 * shadow.k, LAIKAGO.spawn_height - 0.01 * shadow.k],
                               atol=1e-9)
    moved = dst.forward(q_body) - dst.forward(LAIKAGO.default_pose)  # m, base frame
    np.testing.assert_allclose(moved[0], [0.01 * shadow.k, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(moved[3], [0.0, 0.0, 0.005 * shadow.k], atol=1e-6)
    np.testing.assert_allclose(moved[1:3], 0.0, atol=1e-6)


def test_an_env_drawing_the_agent_on_the_laikago_renders_the_shadow(shadow):
    own = envs.make("pupper", randomize=False)
    drawn = envs.make("pupper", randomize=False, draw_as="laikago")
    try:
        a, _ = own.reset(seed=3)
        b, _ = drawn.reset(seed=3)
        for _ in range(10):
            a, *_ = own.step(np.full(12, 0.3))
            b, *_ = drawn.step(np.full(12, 0.3))
        s = drawn.unwrapped.state
        np.testing.assert_array_equal(b["policy"], a["policy"])     # the robot and its physics are the same
        np.testing.assert_array_equal(b["agent_image"], shadow.render(s.base_pos, s.base_quat, s.q))
        # the Laikago is dark all over, the Pupper light with dark legs: far more dark pixels
        assert (b["agent_image"] < 60).sum() > 2 * (a["agent_image"] < 60).sum()
    finally:
        own.close()
        drawn.close()


def test_an_unknown_body_is_one_clear_error():
    with pytest.raises(ValueError, match="unknown robot 'cat'"):
        envs.make("pupper", draw_as="cat")
