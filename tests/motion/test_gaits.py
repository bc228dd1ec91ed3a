"""Built-in gaits: IK joint angles within limits, feet on (never below) the ground, the right phases."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.motion import gaits
from virl_quad.kinematics import Kinematics

PAIRS = {  # legs (FR, FL, RR, RL = 0..3) that move together
    "trot": [(0, 3), (1, 2)], "pace": [(0, 2), (1, 3)], "bound": [(0, 1), (2, 3)], "pronk": [(0, 1, 2, 3)],
}


def _feet(m, robot):
    kin = Kinematics(robots.get(robot))
    return kin.foot_positions_batch(m.q, m.root_pos, m.root_quat)


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
@pytest.mark.parametrize("gait", gaits.GAIT_NAMES)
def test_gait_is_feasible(gait_motions, robot, gait):
    spec = robots.get(robot)
    m = gait_motions[(robot, gait)]
    p = gaits.gait_params(robot, gait)
    assert m.loop and m.cycle_offset_position and m.robot == robot
    # joint limits respected
    assert np.all(m.q >= spec.joint_lower - 1e-9) and np.all(m.q <= spec.joint_upper + 1e-9)
    feet = _feet(m, robot)
    heights = feet[..., 2] - spec.foot_radius                      # sphere bottoms, m
    assert heights.min() > -1e-3                                   # never below the ground (IK tol 1 mm)
    # the feet reach their targets: stance feet on the ground for the duty factor
    on_ground = heights[:-1] < 1e-5                                 # last keyframe repeats the first
    assert on_ground.mean() == pytest.approx(p.duty, abs=0.03)
    # a whole number of control steps per cycle, period close to the requested frequency
    steps = m.duration * spec.control_hz
    assert steps == pytest.approx(round(steps), abs=1e-6)
    assert 1 / m.duration == pytest.approx(p.frequency, rel=0.1)
    # forward at the requested speed, the cycle closes on itself
    assert m.cycle_displacement[0] / m.duration == pytest.approx(p.speed, rel=0.1)
    np.testing.assert_allclose(m.q[-1], m.q[0], atol=1e-3)


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
@pytest.mark.parametrize("gait", sorted(PAIRS))
def test_gait_phases(gait_motions, robot, gait):
    spec = robots.get(robot)
    heights = _feet(gait_motions[(robot, gait)], robot)[..., 2] - spec.foot_radius
    swing = heights > 2e-3
    for group in PAIRS[gait]:
        for leg in group[1:]:
            assert np.array_equal(swing[:, group[0]], swing[:, leg]), (gait, group)
    if gait != "pronk":  # the two groups alternate: never both in swing at mid-swing
        a, b = PAIRS[gait][0][0], PAIRS[gait][1][0]
        assert not np.any((heights[:, a] > 0.5 * heights.max()) & (heights[:, b] > 0.5 * heights.max()))


def test_stance_feet_do_not_slide(gait_motions):
    for (robot, gait), m in gait_motions.items():
        spec = robots.get(robot)
        feet = _feet(m, robot)
        planted = (feet[..., 2] - spec.foot_radius < 1e-4)
        both = planted[1:] & planted[:-1]
        slide = np.linalg.norm(np.diff(feet[..., :2], axis=0), axis=-1)[both]
        assert slide.max() < 2e-3, (robot, gait, slide.max())


def test_pupper_trot_parameters():
    p = gaits.gait_params("pupper", "trot")
    assert 0.2 <= p.speed <= 0.3 and p.frequency == pytest.approx(2.0)
    hip_to_ground = p.height - robots.get("pupper").foot_radius
    assert hip_to_ground == pytest.approx(0.14, abs=0.01)          # feet ~0.14 m below the hips
    assert gaits.gait_params("laikago", "trot").speed > p.speed
    assert gaits.DEFAULT_GAIT == "trot"


def test_in_place_variant(gait_motions):
    m = gaits.gait_motion("pupper", "trot", speed=0.0)
    assert abs(m.cycle_displacement[0]) < 1e-12
    assert m.duration == pytest.approx(gait_motions[("pupper", "trot")].duration)


def test_bad_gait_requests():
    with pytest.raises(ValueError, match="unknown gait 'gallop'; built-in gaits: trot, pace, bound, pronk"):
        gaits.gait_motion("pupper", "gallop")
    with pytest.raises(ValueError, match="unknown robot"):
        gaits.gait_motion("spot", "trot")
    with pytest.raises(ValueError, match="unknown gait parameter"):
        gaits.gait_motion("pupper", "trot", sped=1.0)
    with pytest.raises(ValueError, match="out of reach"):
        gaits.gait_motion("pupper", "trot", height=0.3)
