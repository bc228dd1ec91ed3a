"""The phase clock and the one action -> joint target map."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.motion.gaits import gait_params
from virl_quad.policy import ActionMap, PhaseClock, PolicyContract, TrajectoryGenerator
from virl_quad.training.prior import gait_tg

SPEC = robots.get("pupper")
TG = gait_tg(SPEC, gait_params("pupper", "trot"))          # 2 Hz, 25 steps a cycle at 50 Hz


def _contract(tg=TG, max_step: float | None = 0.2, phase_hz: float | None = None) -> PolicyContract:
    return PolicyContract(action_scale=0.5, action_clip=2.0, max_target_step=max_step, control_dt=SPEC.control_dt,
                          tg=tg, phase_hz=phase_hz)


def test_clock_advances_wraps_and_scales() -> None:
    clock = PhaseClock(2.0, 0.02)                            # 0.04 cycle a step
    for _ in range(25):
        clock.advance()
    assert clock.phase == pytest.approx(0.0, abs=1e-12) or clock.phase == pytest.approx(1.0, abs=1e-12)
    clock.reset(0.9)
    assert clock.advance(1.5) == pytest.approx(0.96)
    assert clock.advance(2.5) == pytest.approx(0.06)
    clock.reset(-1e-17)                                      # wraps into [0, 1), never 1.0
    assert 0.0 <= clock.phase < 1.0
    with pytest.raises(ValueError):
        PhaseClock(0.0, 0.02)


def test_without_tg_targets_are_offsets_from_the_default_pose() -> None:
    am = ActionMap(SPEC, _contract(tg=None, max_step=None, phase_hz=0.5))
    am.reset(SPEC.default_pose)
    a = np.linspace(-3.0, 3.0, 12)
    want = SPEC.clip_to_limits(SPEC.default_pose + 0.5 * np.clip(a, -2.0, 2.0))
    np.testing.assert_allclose(am.step(a), want)
    np.testing.assert_allclose(am.last_action, np.clip(a, -2.0, 2.0))
    assert am.phase == pytest.approx(0.5 * SPEC.control_dt)   # one cycle in 2 s
    with pytest.raises(ValueError, match="12 entries"):
        am.step(np.zeros(14))
    with pytest.raises(ValueError, match="NaN"):
        am.step(np.full(12, np.nan))


def test_with_tg_zero_action_plays_the_tg_and_the_rate_limit_holds() -> None:
    am = ActionMap(SPEC, _contract(max_step=None))
    tg = TrajectoryGenerator(SPEC, TG)
    am.reset(tg.joint_targets(0.0), 0.0)
    for k in range(1, 60):
        target = am.step(np.zeros(14))
        np.testing.assert_allclose(target, tg.joint_targets((k * 0.04) % 1.0), atol=1e-9)
    assert am.last_action.shape == (14,)
    am = ActionMap(SPEC, _contract())
    # from the default pose the TG is reached through the rate limit
    am.reset(SPEC.default_pose, 0.5)
    prev = SPEC.default_pose
    for _ in range(5):
        target = am.step(np.zeros(14))
        assert np.abs(target - prev).max() <= 0.2 + 1e-12
        prev = target
    with pytest.raises(ValueError, match="14 entries"):
        am.step(np.zeros(12))


def test_modulation_and_residual() -> None:
    am = ActionMap(SPEC, _contract(max_step=None))
    tg = TrajectoryGenerator(SPEC, TG)
    am.reset(SPEC.default_pose, 0.25)
    a = np.zeros(14)
    a[12], a[13] = 1.0, -1.0                                 # frequency x1.5, amplitude x0.5
    a[4] = 0.3                                               # FL hip residual
    base = tg.joint_targets(0.25 + 1.5 * 0.04, amplitude=0.5)
    want = base.copy()
    want[4] += 0.5 * 0.3
    np.testing.assert_allclose(am.step(a), SPEC.clip_to_limits(want), atol=1e-12)
    assert am.phase == pytest.approx(0.31) and (am.frequency_scale, am.amplitude_scale) == (1.5, 0.5)
    # base_target: the residual of a target, for a teacher that speaks in targets
    target = am.base_target() + 0.5 * np.linspace(-0.2, 0.2, 12)
    expect = (target - am.base_target()) / 0.5
    got = am.step(np.concatenate([expect, [0.0, 0.0]]))
    np.testing.assert_allclose(got, SPEC.clip_to_limits(target), atol=1e-12)


def test_contract_sizes() -> None:
    assert _contract().action_size == 14 and _contract().observation_size == 48
    assert _contract(tg=None, phase_hz=0.5).observation_size == 46
    assert _contract(tg=None).observation_size == 44 and not _contract(tg=None).with_phase
    with pytest.raises(ValueError, match="phase_hz"):
        _contract(phase_hz=0.5)                              # a TG's clock is its own
    with pytest.raises(ValueError, match="action_scale"):
        PolicyContract(action_scale=-0.5, action_clip=2.0, max_target_step=None, control_dt=0.02)
