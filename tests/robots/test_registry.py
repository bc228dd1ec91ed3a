"""Robot registry and specs: consistent shapes, limits and timing."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.envs import make


@pytest.mark.parametrize("name", robots.names())
def test_spec_is_consistent(name: str) -> None:
    s = robots.get(name)
    assert len(s.joint_names) == 12 and len(s.foot_links) == 4
    for arr in (s.default_pose, s.joint_lower, s.joint_upper, s.kp, s.kd, s.torque_limit, s.velocity_limit):
        assert arr.shape == (12,) and not arr.flags.writeable
    assert np.all(s.joint_lower < s.default_pose) and np.all(s.default_pose < s.joint_upper)
    assert s.control_dt == pytest.approx(s.sim_dt * s.substeps)


def test_unknown_robot_names_the_choices() -> None:
    with pytest.raises(ValueError, match="choose one of: pupper, laikago"):
        robots.get("spot")


def test_physics_step_and_substeps_are_configurable() -> None:
    env = make("pupper", sim_dt=0.0005, substeps=40, randomize=False)
    assert env.unwrapped.robot.control_dt == pytest.approx(0.02) and env.unwrapped.robot.substeps == 40
    env.reset(seed=0)
    env.step(np.zeros(12))
    env.close()
    with pytest.raises(ValueError, match="substeps"):
        make("pupper", substeps=0)


@pytest.mark.parametrize("name", ["pupper", "laikago"])
def test_clip_to_limits_is_np_clip(name: str) -> None:
    spec = robots.get(name)
    q = np.random.default_rng(0).normal(0.0, 3.0, (50, 12))
    q[3, 4], q[7, 0] = np.nan, np.inf
    got = spec.clip_to_limits(q)
    np.testing.assert_array_equal(got, np.clip(q, spec.joint_lower, spec.joint_upper))   # NaN stays NaN
    assert got.shape == q.shape


def test_a_spec_object_is_its_own_lookup() -> None:
    """Functions that take a robot take its name or the spec itself (a variant the registry
    does not hold is not looked up again by name)."""
    import dataclasses

    variant = dataclasses.replace(robots.get("pupper"), name="pupper-heavier")
    assert robots.get(variant) is variant
    with pytest.raises(ValueError, match="unknown robot 'pupper-heavier'"):
        robots.get("pupper-heavier")
