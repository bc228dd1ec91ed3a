"""The trajectory generator: parameters, closed-form leg kinematics against Pinocchio, the gait it draws."""

from __future__ import annotations

import dataclasses
import json
import time

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.motion.gaits import gait_motion, gait_params
from virl_quad.kinematics import Kinematics
from virl_quad.policy.legs import LegKinematics
from virl_quad.policy.tg import AMPLITUDE_SCALE_RANGE, FREQUENCY_SCALE_RANGE, TGParams, TrajectoryGenerator, modulation
from virl_quad.training.prior import gait_tg

ROBOTS = ("pupper", "laikago")
GOOD = {"frequency": 2.0, "offsets": [0.0, 0.5, 0.5, 0.0], "duty": 0.6, "step_length": 0.075,
        "swing_height": 0.03, "stance_height": 0.14}


def test_params_round_trip_through_json() -> None:
    p = TGParams.from_dict(GOOD)
    assert p.offsets == (0.0, 0.5, 0.5, 0.0) and p.neutral_xy is None
    assert TGParams.from_dict(json.loads(json.dumps(p.to_dict()))) == p
    q = dataclasses.replace(p, neutral_xy=((0.1, -0.06), (0.1, 0.06), (-0.1, -0.06), (-0.1, 0.06)))
    assert TGParams.from_dict(json.loads(json.dumps(q.to_dict()))) == q


@pytest.mark.parametrize("change,field", [
    ({"duty": 1.2}, "duty"), ({"duty": "0.6"}, "duty"), ({"frequency": 0.0}, "frequency"),
    ({"frequency": float("nan")}, "frequency"), ({"step_length": -0.01}, "step_length"),
    ({"swing_height": True}, "swing_height"), ({"stance_height": 3.0}, "stance_height"),
    ({"offsets": [0.0, 0.5, 0.5]}, "offsets"), ({"offsets": [0.0, 0.5, 1.0, 0.0]}, "offsets"),
    ({"neutral_xy": [[0.1, 0.0]] * 3}, "neutral_xy"), ({"neutral_xy": [[0.1, 9.0]] * 4}, "neutral_xy"),
    ({"speed": 0.3}, "speed"),
])
def test_bad_params_name_the_field(change: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field) as info:
        TGParams.from_dict({**GOOD, **change})
    assert "\n" not in str(info.value)


def test_missing_field_is_named() -> None:
    with pytest.raises(ValueError, match="'duty' is missing"):
        TGParams.from_dict({k: v for k, v in GOOD.items() if k != "duty"})
    with pytest.raises(ValueError, match="JSON object"):
        TGParams.from_dict([1, 2])


@pytest.mark.parametrize("robot", ROBOTS)
def test_closed_form_forward_kinematics_is_pinocchios(robot: str) -> None:
    spec = robots.get(robot)
    kin, legs = Kinematics(spec, floating_base=False), LegKinematics(spec)
    q = np.random.default_rng(1).uniform(spec.joint_lower, spec.joint_upper, (400, 12))
    feet = kin.foot_positions_batch(q)
    np.testing.assert_allclose(legs.forward(q), feet, atol=1e-5)                          # m
    np.testing.assert_allclose(kin.foot_positions_batch(legs.inverse(feet)), feet, atol=1e-4)
    # the inverse recovers the angles of a leg whose foot is below its abduction axis (a standing
    # leg: the abduction branch) with the knee within its limits (the knee branch)
    below = feet[:, :, 2] - np.asarray(spec.leg.abduction_origin)[:, 2] < -0.05          # (400, 4) legs
    assert below.sum() > 400
    got = legs.inverse(feet).reshape(-1, 4, 3)
    np.testing.assert_allclose(got[below], q.reshape(-1, 4, 3)[below], atol=1e-4)        # rad


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("gait", ["trot", "pace", "walk"])
def test_tg_ik_then_pinocchio_fk_reproduces_the_feet_over_a_cycle(robot: str, gait: str) -> None:
    spec = robots.get(robot)
    tg = TrajectoryGenerator(spec, gait_tg(spec, gait_params(robot, gait)))
    kin = Kinematics(spec, floating_base=False)
    phases = np.linspace(0.0, 1.0, 101)[:, None]
    feet = tg.foot_positions(phases)
    q = tg.joint_targets(phases)
    np.testing.assert_allclose(kin.foot_positions_batch(q), feet, atol=1e-4)              # m
    assert np.all(q >= spec.joint_lower) and np.all(q <= spec.joint_upper)
    # one pose at a time (the control loop's float path) is the batch's (numpy) row, at any amplitude
    for amp in (0.0, 0.6, 1.0, 1.5):
        one = np.array([tg.joint_targets(float(p), amp) for p in phases[:, 0]])
        np.testing.assert_allclose(one, tg.joint_targets(phases, amp), rtol=0, atol=1e-12)


@pytest.mark.parametrize("robot", ROBOTS)
def test_tg_of_a_builtin_gait_draws_that_gait(robot: str) -> None:
    """The built-in trot (feet placed by Pinocchio's numerical IK) and its TG (closed-form IK)
    give the same joint angles at the same phase: one gait definition."""
    spec = robots.get(robot)
    motion = gait_motion(robot, "trot")
    tg = TrajectoryGenerator(spec, gait_tg(spec, gait_params(robot, "trot")))
    phases = (motion.frame_times / motion.duration)[:, None]
    np.testing.assert_allclose(tg.joint_targets(phases), motion.q, atol=2e-3)             # rad


def test_stance_is_a_straight_line_and_swing_lifts() -> None:
    spec = robots.get("pupper")
    p = gait_tg(spec, gait_params("pupper", "trot"))
    tg = TrajectoryGenerator(spec, p)
    phi = np.linspace(0.0, 1.0, 400, endpoint=False)
    fr = tg.foot_positions(phi[:, None])[:, 0]                          # leg FR (offset 0)
    stance, swing = phi < p.duty, phi >= p.duty
    assert np.ptp(fr[stance, 2]) < 1e-12 and fr[stance, 2][0] == pytest.approx(-p.stance_height)
    assert np.all(np.diff(fr[stance, 0]) < 0)                            # backwards, constant speed
    assert np.ptp(np.diff(fr[stance, 0])) < 1e-12
    assert fr[0, 0] - fr[stance, 0][-1] == pytest.approx(p.step_length * (1 - 1 / 400 / p.duty), rel=1e-6)
    assert fr[swing, 2].max() - fr[stance, 2].max() == pytest.approx(p.swing_height, abs=2e-4)
    half = tg.foot_positions(0.1, amplitude=0.5) - tg.foot_positions(0.1)
    assert abs(half[0, 0]) > 1e-3                                        # amplitude scales the stroke
    still = tg.foot_positions(phi[:, None], amplitude=0.0)
    assert np.ptp(still, axis=0).max() < 1e-12                           # amplitude 0: feet at rest


def test_modulation_ranges() -> None:
    assert modulation(np.zeros(2)) == (1.0, 1.0)
    assert modulation(np.array([1.0, -1.0])) == (1.5, 0.5)
    assert modulation(np.array([10.0, 10.0])) == (FREQUENCY_SCALE_RANGE[1], AMPLITUDE_SCALE_RANGE[1])
    assert modulation(np.array([-10.0, -10.0])) == (FREQUENCY_SCALE_RANGE[0], AMPLITUDE_SCALE_RANGE[0])


def test_out_of_reach_and_undescribed_legs_are_refused() -> None:
    spec = robots.get("pupper")
    with pytest.raises(ValueError, match="reach"):
        TrajectoryGenerator(spec, TGParams.from_dict({**GOOD, "stance_height": 0.25}))   # legs are 0.19 m
    with pytest.raises(ValueError, match="joint limits"):
        TrajectoryGenerator(spec, TGParams.from_dict({**GOOD, "stance_height": 0.07}))   # knee folds too far
    with pytest.raises(ValueError, match="no leg geometry"):
        TrajectoryGenerator(dataclasses.replace(spec, leg=None), TGParams.from_dict(GOOD))


def test_one_tg_evaluation_is_cheap() -> None:
    spec = robots.get("pupper")
    tg = TrajectoryGenerator(spec, gait_tg(spec, gait_params("pupper", "trot")))
    n = 2000
    t0 = time.perf_counter()
    for k in range(n):
        tg.joint_targets(k / n, 1.0)
    us = (time.perf_counter() - t0) / n * 1e6
    print(f"\none TG evaluation (feet + closed-form IK, 4 legs): {us:.1f} µs")
    assert us < 200                                                      # 50 Hz leaves 20,000 µs
