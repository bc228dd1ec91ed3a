"""Safety state machine and command validation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, RobotState
from virl_quad.deploy.safety import Mode, SafetyConfig, SafetyController, is_safe_command, roll_pitch


class Seq:
    """Increasing sequence numbers for a test's sender."""

    def __init__(self) -> None:
        self.n = 1000

    def __call__(self) -> int:
        self.n += 1
        return self.n


def ramp_ticks(spec, cfg=SafetyConfig()) -> int:
    return round(cfg.ramp_time / spec.control_dt)


def make_active(spec, cfg=SafetyConfig()):
    """A controller driven IDLE -> RAMP -> ACTIVE with valid commands; returns (ctl, seq)."""
    ctl, seq = SafetyController(spec, cfg), Seq()
    st = RobotState.standing(spec)
    assert ctl.arm()
    for _ in range(ramp_ticks(spec, cfg)):
        assert ctl.receive(P.encode_command(JointCommand.hold(spec), seq()))
        out = ctl.tick(st)
        assert is_safe_command(out, spec, cfg)
    assert ctl.mode == Mode.ACTIVE
    return ctl, seq


def quat_from_rp(roll: float, pitch: float) -> np.ndarray:
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return np.array([sr * cp, cr * sp, -sr * sp, cr * cp])   # x, y, z, w for yaw = 0


def test_roll_pitch_of_quaternion():
    r, p = roll_pitch(quat_from_rp(0.3, -0.2))
    assert r == pytest.approx(0.3) and p == pytest.approx(-0.2)


def test_idle_is_zero_torque_and_commands_are_not_applied(spec):
    ctl, seq = SafetyController(spec), Seq()
    assert ctl.receive(P.encode_command(JointCommand.hold(spec), seq()))
    out = ctl.tick(RobotState.standing(spec))
    assert ctl.mode == Mode.IDLE
    assert not out.kp.any() and not out.kd.any() and not out.tau_ff.any()
    assert is_safe_command(out, spec)


def test_ramp_interpolates_linearly_to_default_pose_then_waits_for_the_policy(spec):
    q0 = spec.joint_lower + 0.25 * (spec.joint_upper - spec.joint_lower)
    ctl, n = SafetyController(spec), ramp_ticks(spec)
    assert ctl.arm()
    outs = [ctl.tick(RobotState.standing(spec, q0)) for _ in range(n + 5)]    # no policy yet
    assert ctl.mode == Mode.RAMP
    np.testing.assert_allclose(outs[0].q_target, q0 + (spec.default_pose - q0) / n)
    k = n // 2
    np.testing.assert_allclose(outs[k - 1].q_target, q0 + (k / n) * (spec.default_pose - q0))
    for o in outs[n - 1:]:
        np.testing.assert_allclose(o.q_target, spec.default_pose)         # holds the pose
    np.testing.assert_array_equal(outs[3].kp, spec.kp)
    np.testing.assert_array_equal(outs[3].kd, spec.kd)
    assert n == round(2.0 / spec.control_dt)                             # ~2 s
    assert ctl.receive(P.encode_command(JointCommand.hold(spec), 5))
    ctl.tick(RobotState.standing(spec))
    assert ctl.mode == Mode.ACTIVE


def test_active_applies_validated_commands(pupper):
    ctl, seq = make_active(pupper)
    q = pupper.default_pose + 0.05
    assert ctl.receive(P.encode_command(JointCommand.hold(pupper, q), seq()))
    out = ctl.tick(RobotState.standing(pupper))
    np.testing.assert_allclose(out.q_target, q)
    assert ctl.applied >= 1


@pytest.mark.parametrize("periods", [1, 3, 5])
def test_watchdog_trips_after_more_than_n_periods_without_a_valid_command(spec, periods):
    cfg = SafetyConfig(watchdog_periods=periods)
    ctl, seq = make_active(spec, cfg)
    assert ctl.receive(P.encode_command(JointCommand.hold(spec, spec.default_pose + 0.01), seq()))
    last = ctl.tick(RobotState.standing(spec))
    for _ in range(periods):      # within the window: hold the last command; garbage does not help
        ctl.receive(b"garbage")
        out = ctl.tick(RobotState.standing(spec))
        assert ctl.mode == Mode.ACTIVE
        np.testing.assert_array_equal(out.q_target, last.q_target)
        np.testing.assert_array_equal(out.kp, last.kp)
    out = ctl.tick(RobotState.standing(spec))
    assert ctl.mode == Mode.DAMPING and ctl.fault == "watchdog" and ctl.events["watchdog"] == 1
    assert not out.kp.any() and not out.tau_ff.any() and out.kd.min() > 0
    assert is_safe_command(out, spec, cfg)


def test_damping_is_latched_until_rearm_and_rearm_ramps_from_current_pose(pupper):
    ctl, seq = make_active(pupper)
    ctl.estop("test")
    q_now = pupper.default_pose + 0.3
    ctl.tick(RobotState.standing(pupper, q_now))
    assert ctl.mode == Mode.DAMPING and ctl.fault == "test"
    for _ in range(20):                                  # valid commands do not leave DAMPING
        ctl.receive(P.encode_command(JointCommand.hold(pupper), seq()))
        out = ctl.tick(RobotState.standing(pupper, q_now))
        assert ctl.mode == Mode.DAMPING and not out.kp.any()
    assert ctl.arm()
    out = ctl.tick(RobotState.standing(pupper, q_now))
    assert ctl.mode == Mode.RAMP
    n = ramp_ticks(pupper)
    np.testing.assert_allclose(out.q_target, q_now + (pupper.default_pose - q_now) / n)


def test_rearm_resets_the_sequence_baseline(pupper):
    ctl, seq = make_active(pupper)
    ctl.estop()
    ctl.tick(RobotState.standing(pupper))
    assert not ctl.receive(P.encode_command(JointCommand.hold(pupper), 1))    # older than baseline
    ctl.arm()
    ctl.tick(RobotState.standing(pupper))
    assert ctl.receive(P.encode_command(JointCommand.hold(pupper), 1))        # restarted policy


@pytest.mark.parametrize("mode", ["idle", "ramp", "active"])
def test_estop_from_every_mode(pupper, mode):
    if mode == "active":
        ctl, _ = make_active(pupper)
    else:
        ctl = SafetyController(pupper)
        if mode == "ramp":
            ctl.arm()
            ctl.tick(RobotState.standing(pupper))
    ctl.estop("button")
    out = ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.DAMPING and ctl.events["estop"] == 1 and not out.kp.any()


@pytest.mark.parametrize("axis", ["roll", "pitch"])
def test_tilt_beyond_spec_limit_damps(spec, axis):
    ctl, seq = make_active(spec)
    lim = spec.max_roll if axis == "roll" else spec.max_pitch
    for angle, expect in ((0.95 * lim, Mode.ACTIVE), (1.05 * lim, Mode.DAMPING)):
        quat = quat_from_rp(angle, 0) if axis == "roll" else quat_from_rp(0, -angle)
        ctl.receive(P.encode_command(JointCommand.hold(spec), seq()))
        ctl.tick(RobotState.standing(spec, quat=quat))
        assert ctl.mode == expect
    assert ctl.fault == "tilt"


def test_arming_a_fallen_robot_damps_at_once(pupper):
    ctl = SafetyController(pupper)
    ctl.arm()
    ctl.tick(RobotState.standing(pupper, quat=quat_from_rp(1.2, 0)))
    assert ctl.mode == Mode.DAMPING and ctl.fault == "tilt"


@pytest.mark.parametrize("bad", ["nan_q", "zero_quat", "none"])
def test_bad_state_damps(pupper, bad):
    ctl, seq = make_active(pupper)
    st = RobotState.standing(pupper)
    if bad == "nan_q":
        st.q[4] = np.nan
    elif bad == "zero_quat":
        st.quat = np.zeros(4)
    out = ctl.tick(None if bad == "none" else st)
    assert ctl.mode == Mode.DAMPING and ctl.fault == ("no_state" if bad == "none" else "bad_state")
    assert is_safe_command(out, pupper)


def test_arm_is_ignored_while_powered(pupper):
    ctl, _ = make_active(pupper)
    assert not ctl.arm() and ctl.events["arm_ignored"] == 1


def _cmd_with(spec, **fields) -> JointCommand:
    c = JointCommand.hold(spec)
    for k, v in fields.items():
        getattr(c, k)[:] = v
    return c


@pytest.mark.parametrize("field, value, reason", [
    ("q_target", np.nan, "non_finite"), ("kp", np.inf, "non_finite"), ("kd", -np.inf, "non_finite"),
    ("tau_ff", np.nan, "non_finite"), ("kp", -1.0, "negative_gain"), ("kd", -0.1, "negative_gain"),
])
def test_invalid_content_is_rejected_and_counted(pupper, field, value, reason):
    ctl, seq = make_active(pupper)
    c = JointCommand.hold(pupper)
    getattr(c, field)[3] = value
    assert not ctl.receive(P.encode_command(c, seq()))
    assert ctl.rejected == {reason: 1}


def test_replays_and_protocol_errors_are_rejected_and_counted(pupper):
    ctl, seq = make_active(pupper)
    data = P.encode_command(JointCommand.hold(pupper), seq())
    assert ctl.receive(data)
    assert not ctl.receive(data)                                         # replay
    assert not ctl.receive(P.encode_command(JointCommand.hold(pupper), seq.n - 5))   # older
    assert not ctl.receive(data[:-3])
    assert not ctl.receive(P.encode_state(RobotState.standing(pupper), seq()))  # STATE on the cmd key
    assert not ctl.receive_command(JointCommand(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)), seq())
    assert not ctl.receive_command(JointCommand.hold(pupper), -1)
    assert ctl.rejected == {"stale_seq": 2, "bad_size": 1, "wrong_type": 1, "bad_shape": 1, "bad_seq": 1}
    assert ctl.status()["rejected"] == dict(ctl.rejected)


def test_targets_gains_and_torques_are_clamped(pupper):
    cfg = SafetyConfig(max_step=0.2, gain_factor=2.0)
    ctl, seq = make_active(pupper, cfg)
    c = _cmd_with(pupper, q_target=1e9, kp=1e300, kd=50.0, tau_ff=-1e6)
    assert ctl.receive(P.encode_command(c, seq()))
    out = ctl.tick(RobotState.standing(pupper))
    np.testing.assert_allclose(out.q_target, np.minimum(pupper.default_pose + 0.2, pupper.joint_upper))
    np.testing.assert_array_equal(out.kp, 2 * pupper.kp)
    np.testing.assert_array_equal(out.kd, 2 * pupper.kd)
    np.testing.assert_array_equal(out.tau_ff, -pupper.torque_limit)
    assert ctl.clamped == {"q_limit": 1, "q_step": 1, "gain": 1, "tau_ff": 1}
    assert is_safe_command(out, pupper, cfg)


def test_step_limit_walks_toward_a_far_target(pupper):
    cfg = SafetyConfig(max_step=0.1)
    ctl, seq = make_active(pupper, cfg)
    target = pupper.joint_lower.copy()
    prev = None
    for _ in range(40):
        ctl.receive(P.encode_command(JointCommand.hold(pupper, target), seq()))
        out = ctl.tick(RobotState.standing(pupper))
        if prev is not None:
            assert is_safe_command(out, pupper, cfg, prev=prev)
        prev = out
    np.testing.assert_allclose(out.q_target, target)


def test_is_safe_command_detects_each_violation(pupper):
    good = JointCommand.hold(pupper)
    assert is_safe_command(good, pupper)
    for field, idx, value in [("q_target", 0, 5.0), ("q_target", 2, np.nan), ("kp", 1, -0.1),
                              ("kp", 1, 100.0), ("kd", 0, 10.0), ("tau_ff", 5, 1.8)]:
        bad = JointCommand.hold(pupper)
        getattr(bad, field)[idx] = value
        assert not is_safe_command(bad, pupper), (field, value)
    assert not is_safe_command(JointCommand(np.zeros(11), good.kp, good.kd, good.tau_ff), pupper)
    moved = JointCommand.hold(pupper, pupper.default_pose + 0.3)
    assert not is_safe_command(moved, pupper, SafetyConfig(max_step=0.2), prev=good)


def test_status_is_json_ready(pupper):
    ctl, seq = make_active(pupper)
    ctl.receive(b"x")
    st = ctl.status()
    assert st["mode"] == "ACTIVE" and st["rejected"] == {"bad_size": 1}
    data = P.encode_json(MsgType.STATUS, st, seq=1)
    assert P.decode(data).body["mode"] == "ACTIVE"


def test_config_is_checked():
    for kw in (dict(ramp_time=0), dict(watchdog_periods=0), dict(max_step=-1),
               dict(damping_kd_factor=3.0, gain_factor=2.0), dict(tilt_factor=0)):
        with pytest.raises(ValueError):
            SafetyConfig(**kw)


def test_any_sample_on_the_estop_key_stops_the_robot(pupper):
    for payload in (P.encode_json(MsgType.ESTOP, {"reason": "red button"}, 1), b"", b"\xff" * 7,
                    P.encode_command(JointCommand.hold(pupper), 99)):
        ctl, _ = make_active(pupper)
        ctl.receive_estop(payload)
        ctl.tick(RobotState.standing(pupper))
        assert ctl.mode == Mode.DAMPING and ctl.fault.startswith("estop")
    assert ctl.rejected_other == {"estop:wrong_type": 1}
    ctl2, _ = make_active(pupper)
    ctl2.receive_estop(P.encode_json(MsgType.ESTOP, {"reason": "red button"}, 1))
    ctl2.tick(RobotState.standing(pupper))
    assert ctl2.fault == "estop: red button" and ctl2.status()["fault"] == "estop: red button"


def test_only_a_valid_arm_for_this_robot_rearms(pupper):
    ctl = SafetyController(pupper)
    good = P.encode_json(MsgType.ARM, {"robot_id": "pupper-01"}, 5)
    assert not ctl.receive_arm(P.encode_json(MsgType.ARM, {"robot_id": "pupper-02"}, 6), "pupper-01")
    assert not ctl.receive_arm(good[:-1], "pupper-01")
    assert not ctl.receive_arm(P.encode_json(MsgType.ESTOP, {"robot_id": "pupper-01"}, 7), "pupper-01")
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.IDLE
    assert ctl.rejected_other == {"arm:wrong_robot": 1, "arm:bad_size": 1, "arm:wrong_type": 1}
    assert ctl.receive_arm(good, "pupper-01")
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.RAMP


def _arm(seq: int = 5) -> bytes:
    return P.encode_json(MsgType.ARM, {"robot_id": "pupper-01"}, seq)


def _damped(spec) -> SafetyController:
    ctl = SafetyController(spec)
    ctl.estop("first")
    ctl.tick(RobotState.standing(spec))
    assert ctl.mode == Mode.DAMPING
    return ctl


@pytest.mark.parametrize("order", ["arm_then_estop", "estop_then_arm"])
def test_an_estop_cancels_every_arm_of_its_period_whatever_the_order(pupper, order):
    """PROTOCOL.md section 8: within one period the E-stop wins, before or after the ARM."""
    ctl = _damped(pupper)
    ctl.begin_period()
    for what in order.split("_then_"):
        ctl.receive_arm(_arm(), "pupper-01") if what == "arm" else ctl.receive_estop(
            P.encode_json(MsgType.ESTOP, {"reason": "stop!"}, 9))
    for _ in range(3):          # nothing left to take in the following periods either
        ctl.begin_period()
        ctl.tick(RobotState.standing(pupper))
        assert ctl.mode == Mode.DAMPING and ctl.fault == "first"
    ev = ctl.status()["events"]
    assert ev["arm_received"] == 1 and ev["arm_cancelled"] == 1 and "arm" not in ev, ev
    assert ev["estop_received"] == 1


def test_an_estop_cancels_an_arm_taken_at_the_start_of_its_period(pupper):
    ctl = _damped(pupper)
    assert ctl.receive_arm(_arm(), "pupper-01")
    assert ctl.begin_period()                 # the ARM of the closed period is taken ...
    ctl.estop("stop!")                        # ... and an E-stop arrives before the tick
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.DAMPING and ctl.status()["events"]["arm_cancelled"] == 1


def test_an_arm_in_a_later_period_than_the_estop_rearms(pupper):
    ctl = _damped(pupper)
    ctl.begin_period()
    ctl.estop("stop!")
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.DAMPING
    ctl.begin_period()
    assert ctl.receive_arm(_arm(), "pupper-01")
    ctl.tick(RobotState.standing(pupper))     # taken at the next period's start
    assert ctl.mode == Mode.DAMPING
    assert ctl.begin_period()
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.RAMP and ctl.fault == ""


def test_arm_in_ramp_or_active_is_an_event_not_a_rejection(pupper):
    ctl, _ = make_active(pupper)
    assert not ctl.receive_arm(_arm(), "pupper-01")
    st = ctl.status()
    assert st["events"]["arm_ignored"] == 1 and st["events"]["arm_received"] == 1
    assert st["rejected_other"] == {} and st["rejected"] == {} and st["mode"] == "ACTIVE"


def test_an_estop_in_idle_damps_and_a_delete_sample_counts(pupper):
    ctl = SafetyController(pupper)
    ctl.receive_arm(None, "pupper-01")        # a Zenoh DELETE on arm: counted, ignored
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.IDLE
    ctl.receive_estop(None)                   # a Zenoh DELETE on estop: an E-stop
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.DAMPING and ctl.fault == "estop"
    assert ctl.rejected_other == {"arm:delete": 1, "estop:delete": 1}


def test_limits_are_the_ones_enforced(pupper):
    ctl = SafetyController(pupper, SafetyConfig(gain_factor=1.5, max_step=0.1))
    lim = ctl.limits()
    json.dumps(lim, allow_nan=False)
    np.testing.assert_allclose(lim["kp_max"], 1.5 * pupper.kp)
    assert lim["max_step"] == 0.1 and lim["tau_max"] == pupper.torque_limit.tolist()
    # a command at exactly the published limits is safe; one beyond any of them is not
    at = JointCommand(np.array(lim["q_upper"]), np.array(lim["kp_max"]), np.array(lim["kd_max"]),
                      np.array(lim["tau_max"]))
    cfg = ctl.config
    assert is_safe_command(at, pupper, cfg)
    for field, delta in (("q_target", 1e-3), ("kp", 1e-3), ("kd", 1e-3), ("tau_ff", 1e-3)):
        over = JointCommand(*(np.array(getattr(at, f)) for f in ("q_target", "kp", "kd", "tau_ff")))
        getattr(over, field)[0] += delta
        assert not is_safe_command(over, pupper, cfg), field


class _Clock:
    """A settable monotonic clock (s) for the ARM stamp window."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_an_arm_sent_before_an_estop_that_overtook_it_is_cancelled(pupper):
    """PROTOCOL.md section 8: an ARM stamped no later than an E-stop received less than
    arm_stamp_window s before it was sent before that E-stop: cancelled, in any later period;
    an ARM stamped after it re-arms; the window bounds what a clock running ahead can block."""
    clock = _Clock()
    ctl = SafetyController(pupper, clock=clock)
    ctl.estop("first")
    ctl.tick(RobotState.standing(pupper))
    t0 = 1_000_000_000_000
    ctl.receive_estop(P.encode_json(MsgType.ESTOP, {"reason": "stop!"}, 9, stamp_ns=t0 + 5))
    ctl.tick(RobotState.standing(pupper))
    clock.t += 0.1                                  # the ARM arrives 0.1 s (five periods) later
    for stamp in (t0, t0 + 5):                      # sent before the E-stop, or in the same ns
        assert not ctl.receive_arm(P.encode_json(MsgType.ARM, {"robot_id": "pupper-01"}, 5, stamp_ns=stamp),
                                   "pupper-01")
        for _ in range(3):
            ctl.begin_period()
            ctl.tick(RobotState.standing(pupper))
            assert ctl.mode == Mode.DAMPING
    ev = ctl.status()["events"]
    assert ev["arm_before_estop"] == 2 and ev["arm_cancelled"] == 2 and "arm" not in ev, ev
    assert ctl.receive_arm(P.encode_json(MsgType.ARM, {"robot_id": "pupper-01"}, 6, stamp_ns=t0 + 6),
                           "pupper-01")
    ctl.begin_period()
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.RAMP
    # a sender clock far ahead blocks ARMs for arm_stamp_window s, not longer
    ctl.estop("again")
    ctl.receive_estop(P.encode_json(MsgType.ESTOP, {}, 10, stamp_ns=t0 + 10**12))
    ctl.tick(RobotState.standing(pupper))
    late = P.encode_json(MsgType.ARM, {"robot_id": "pupper-01"}, 7, stamp_ns=t0 + 7)
    clock.t += ctl.config.arm_stamp_window
    assert not ctl.receive_arm(late, "pupper-01")
    clock.t += 0.01
    assert ctl.receive_arm(late, "pupper-01")


def test_an_estop_that_does_not_decode_sets_no_stamp(pupper):
    clock = _Clock()
    ctl = SafetyController(pupper, clock=clock)
    ctl.receive_estop(b"junk")
    ctl.tick(RobotState.standing(pupper))
    ctl.begin_period()
    assert ctl.receive_arm(_arm(), "pupper-01")     # a later period, no stamp to compare with
    ctl.begin_period()
    ctl.tick(RobotState.standing(pupper))
    assert ctl.mode == Mode.RAMP
