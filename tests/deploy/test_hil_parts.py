"""In-process checks of the HIL parts (no subprocesses): the sim backend, the policy
server's state -> command step and its announce check."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.deploy import protocol as P
from virl_quad.deploy.backends import get_backend
from virl_quad.deploy.backends.sim import SimBackend
from hil_harness import export_untrained
from virl_quad.deploy.protocol import JointCommand, MsgType
from virl_quad.deploy.serve import PolicyRunner, check_announce
from virl_quad.policy import ActionMap, policy_observation, yaw
from virl_quad.policy_io import load_policy


@pytest.fixture(scope="module")
def untrained(tmp_path_factory):
    """An untrained Pupper policy (40-frame demonstration)."""
    return load_policy(export_untrained(tmp_path_factory.mktemp("parts"), "pupper"))


def _cmd(spec, kp_scale: float) -> JointCommand:
    return JointCommand(np.array(spec.default_pose), kp_scale * np.array(spec.kp), kp_scale * np.array(spec.kd),
                        np.zeros(12))


def test_sim_backend_state_and_per_command_gains():
    spec = robots.get("pupper")
    with get_backend("sim", spec=spec) as robot:
        assert isinstance(robot, SimBackend)
        st = robot.read_state()
        assert st.timestamp == 0.0 and st.base_pos is not None and st.base_vel is not None
        np.testing.assert_allclose(st.accel, [0, 0, 9.81], atol=1e-6)          # at rest, level: +g on z
        assert len(P.encode_state(st, 1)) == 464
        for _ in range(25):
            robot.write_command(_cmd(spec, 1.0))                               # spec gains: stands
        st = robot.read_state()
        assert st.timestamp == pytest.approx(25 * spec.control_dt)
        assert st.base_pos[2] > 0.12 and np.all(st.contacts == 1.0)
        assert abs(st.accel[2] - 9.81) < 1.0                                   # standing still
        for _ in range(25):
            robot.write_command(_cmd(spec, 0.0))                               # the command's zero gains: falls
        assert robot.read_state().base_pos[2] < 0.09
    assert robot.closed
    with pytest.raises(Exception):
        robot.read_state()


def test_sim_backend_randomised_physics_is_seeded():
    a, b = SimBackend("pupper", randomize=True, seed=3), SimBackend("pupper", randomize=True, seed=3)
    try:
        assert a.randomization.physics.mass_scale == b.randomization.physics.mass_scale != 1.0
    finally:
        a.close()
        b.close()


def test_runner_uses_the_training_observation_and_skips_bad_states(untrained):
    spec = untrained.spec
    runner = PolicyRunner(untrained)
    rng = np.random.default_rng(4)
    st = P.RobotState.zeros(spec.default_pose + rng.normal(0.0, 0.2, 12))
    st.gyro, st.dq = np.array([0.1, -0.2, 0.3]), rng.normal(0.0, 2.0, 12)
    unit = np.array([0.05, -0.1, 0.02, 1.0]) / np.linalg.norm([0.05, -0.1, 0.02, 1.0])
    st.quat = 1.04 * unit                                  # off unit norm: the runner normalises it
    mine = ActionMap(spec, untrained.contract)             # the training env's map, run beside the server's
    mine.reset(st.q, 0.0)
    for k in range(3):
        out, reason = runner.handle(P.encode_state(st, 10 + k, active=True))
        assert reason == "" and out is not None
        msg = P.decode(out, expect=MsgType.COMMAND)
        obs = policy_observation(spec, unit, st.gyro, st.q, st.dq, mine.last_action, mine.phase, yaw(unit))
        assert mine.phase == pytest.approx((k % 40) / 40)  # one cycle per 40-frame demonstration
        np.testing.assert_allclose(msg.body.q_target, mine.step(untrained.act(obs)))
        np.testing.assert_array_equal(msg.body.kp, untrained.meta["kp"])
        np.testing.assert_array_equal(msg.body.tau_ff, np.zeros(12))
        assert msg.body.ref_seq == 10 + k
    bad = P.RobotState.zeros(spec.default_pose)
    bad.dq[4] = np.nan
    assert runner.handle(P.encode_state(bad, 20, active=True)) == (None, "non_finite_state")
    bad = P.RobotState.zeros(spec.default_pose)
    bad.quat = np.zeros(4)
    assert runner.handle(P.encode_state(bad, 21, active=True)) == (None, "bad_quaternion")
    assert runner.handle(b"junk") == (None, "bad_message:bad_size")
    assert runner.handle(P.encode_state(st, 5, active=True)) == (None, "stale_state")      # older than the last served
    assert runner.handle(P.encode_json(MsgType.STATUS, {}, 30))[1] == "bad_message:wrong_type"
    assert runner.k == 3 and runner.counts["served"] == 3 and runner.counts["non_finite_state"] == 1


def test_runner_clock_starts_at_the_first_active_state(untrained):
    """States the HAL will not act on (IDLE, RAMP, DAMPING) are answered from the episode start
    (phase 0, last action 0) without advancing it; the first ACTIVE state is step 0 of an episode,
    as after a training env's reset. Without the HAL's active_flag the clock runs from the start."""
    spec = untrained.spec
    st = P.RobotState.zeros(spec.default_pose)
    st.dq = np.random.default_rng(1).normal(0.0, 1.0, 12)   # non-zero input: a non-zero action
    runner = PolicyRunner(untrained)
    first = untrained.act(policy_observation(spec, st.quat, st.gyro, st.q, st.dq, np.zeros(12), 0.0))
    mine = ActionMap(spec, untrained.contract)
    mine.reset(st.q, 0.0)
    want = mine.step(first)                                      # an episode's first target from this state
    seq = iter(range(1, 100))
    for _ in range(5):                                           # ramping: not applied
        out, _ = runner.handle(P.encode_state(st, next(seq)))
        np.testing.assert_allclose(P.decode(out).body.q_target, want)
        assert runner.k == 0 and not runner.last_action.any() and runner.phase() == 0.0
    for k in range(3):                                           # ACTIVE: the episode runs
        runner.handle(P.encode_state(st, next(seq), active=True))
        assert runner.k == k + 1 and runner.last_action.any() and runner.phase() == pytest.approx((k + 1) / 40)
    runner.handle(P.encode_state(st, next(seq)))                 # DAMPING: back to the start
    assert runner.k == 0 and not runner.last_action.any() and runner.phase() == 0.0
    legacy = PolicyRunner(untrained)
    legacy.gate_on_active = False                                # a HAL without active_flag
    legacy.handle(P.encode_state(st, 1))
    assert legacy.k == 1


def test_announce_check_names_the_mismatch(untrained):
    spec = untrained.spec
    good = P.announce_body(spec, "pupper-01")
    assert check_announce(good, untrained.meta, "pupper-01") == ""
    assert "robot_id" in check_announce(good, untrained.meta, "pupper-02")
    laikago = P.announce_body(robots.get("laikago"), "pupper-01")
    assert "robot 'laikago'" in check_announce(laikago, untrained.meta, "pupper-01")
    for field, value, word in (("joint_order", list(reversed(spec.joint_names)), "joint_order"),
                               ("control_dt", 0.03, "control_dt"), ("protocol_version", 2, "protocol_version")):
        assert word in check_announce({**good, field: value}, untrained.meta, "pupper-01")
    assert check_announce([1, 2], untrained.meta, "pupper-01")
