"""Backend registry and the loopback backend under the safety layer."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad.deploy import protocol as P
from virl_quad.deploy.backends import (
    BACKENDS,
    Backend,
    BackendError,
    LoopbackBackend,
    backend_names,
    get_backend,
    register_backend,
)
from virl_quad.deploy.protocol import JointCommand
from virl_quad.deploy.safety import Mode, SafetyController, is_safe_command


def test_unknown_backend_names_the_choices():
    with pytest.raises(ValueError) as e:
        get_backend("nope")
    for name in ("loopback", "pupper_serial", "sim"):
        assert name in str(e.value) and name in backend_names()


def test_lazy_registration_and_import_failure():
    register_backend("tmp_loop", "virl_quad.deploy.backends.base:LoopbackBackend")
    register_backend("tmp_missing", "virl_quad.deploy.backends.not_there:Nothing")
    try:
        b = get_backend("tmp_loop", spec="laikago")
        assert isinstance(b, LoopbackBackend) and b.spec.name == "laikago"
        with pytest.raises(BackendError):
            get_backend("tmp_missing")
        with pytest.raises(ValueError):
            register_backend("bad", "no_colon_here")
    finally:
        BACKENDS.pop("tmp_loop", None)
        BACKENDS.pop("tmp_missing", None)


def test_backend_is_abstract():
    with pytest.raises(TypeError):
        Backend("pupper")  # type: ignore[abstract]


def test_loopback_refuses_bad_commands_and_closes(pupper):
    with get_backend("loopback", spec=pupper) as robot:
        c = JointCommand(np.array(pupper.default_pose), np.array(pupper.kp), np.array(pupper.kd), np.zeros(12))
        c.kd[0] = np.inf
        with pytest.raises(ValueError):
            robot.write_command(c)
        c.kd[0] = -1.0
        with pytest.raises(ValueError):
            robot.write_command(c)
    assert robot.closed
    with pytest.raises(BackendError):
        robot.read_state()


def test_hal_style_loop_ramps_a_crouched_robot_and_follows_the_policy(spec):
    """IDLE -> RAMP -> ACTIVE -> (policy stops) -> DAMPING on a loopback robot."""
    q0 = np.clip(spec.default_pose + np.array([0.2, -0.3, 0.4] * 4), spec.joint_lower, spec.joint_upper)
    robot, ctl = LoopbackBackend(spec, q0=q0), SafetyController(spec)
    seq = P.SeqCounter(start=1)
    ctl.arm()
    n_ramp = round(2.0 / spec.control_dt)
    target = spec.default_pose + np.array([0.0, 0.1, -0.1] * 4)
    for k in range(n_ramp + 60):
        st = robot.read_state()
        if k >= n_ramp - 1 and k < n_ramp + 40:            # the policy starts after the ramp
            cmd = JointCommand(target, np.array(spec.kp), np.array(spec.kd), np.zeros(12), ref_seq=k)
            ctl.receive(P.encode_command(cmd, seq()))
        out = ctl.tick(st)
        assert is_safe_command(out, spec)
        robot.write_command(out)
        if k == n_ramp + 30:
            assert ctl.mode == Mode.ACTIVE
            np.testing.assert_allclose(robot.q, target, atol=0.03)
    assert ctl.mode == Mode.DAMPING and ctl.fault == "watchdog"
    assert ctl.status()["applied"] == 40
