"""The operator's STATUS view and answers: what a person reads, from a real safety layer and a real HAL."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import zenoh

from virl_quad import robots
from virl_quad.deploy import protocol as P
from hil_harness import start_hal
from virl_quad.deploy.operator import format_status, wait_until
from virl_quad.deploy.protocol import JointCommand, MsgType, RobotState
from virl_quad.deploy.safety import CLAMPS, Mode, SafetyConfig, SafetyController
from virl_quad.deploy.zenoh_config import free_port, load_config, publisher_options

SPEC = robots.get("pupper")


def test_view_explains_clamps_and_time_active() -> None:
    ctl = SafetyController(SPEC, SafetyConfig())
    st = RobotState.standing(SPEC)
    assert ctl.arm()
    seq = 1000
    while ctl.mode != Mode.ACTIVE:                       # ramp on valid commands
        seq += 1
        ctl.receive(P.encode_command(JointCommand.hold(SPEC), seq))
        ctl.tick(st)
    far = JointCommand.hold(SPEC, np.asarray(SPEC.default_pose) + 0.5)   # 0.5 rad away: rate-limited
    for k in range(50):
        seq += 1
        ctl.receive(P.encode_command(far if k % 2 else JointCommand.hold(SPEC), seq))
        ctl.tick(st)
    status = {**ctl.status(), "robot": "pupper", "robot_id": "pupper-01", "backend": "sim",
              "control_dt": SPEC.control_dt, "max_step": ctl.config.max_step}
    state = RobotState.standing(SPEC)
    state.base_pos, state.base_vel = np.array([1.0, 0.0, 0.17]), np.array([0.25, 0.0, 0.0])
    text = format_status(status, state)
    n = status["clamped"]["q_step"]
    assert 0 < n <= status["applied"]
    assert "mode ACTIVE" in text and "fault: none" in text
    assert "base height 0.170 m" in text and "forward speed +0.25 m/s" in text
    assert f"ACTIVE for {status['active_ticks'] * SPEC.control_dt:.1f} s" in text and status["active_ticks"] == 50
    assert f"q_step {n} of {status['applied']} applied" in text
    assert "at most 0.2 rad per period" in text                        # the meaning, with the limit
    assert set(status["clamped"]) <= set(CLAMPS)
    assert "not measured" in format_status(status, RobotState.standing(SPEC))   # hardware: no base position


def test_operator_status_against_a_real_hal(tmp_path) -> None:
    ep, robot_id = f"tcp/127.0.0.1:{free_port()}", "pupper-view"
    hal = start_hal(ep, robot_id, "--status-hz", "20")
    try:
        base = [sys.executable, "-m", "virl_quad.deploy.operator", "status", "--robot-id", robot_id,
                "--connect", ep, "--wait", "60"]
        view = subprocess.run(base, capture_output=True, text=True, timeout=120)
        raw = subprocess.run([*base, "--json"], capture_output=True, text=True, timeout=120)
    finally:
        hal.close()
    assert view.returncode == 0, view.stderr[-2000:]
    assert "mode IDLE" in view.stdout and "commands: 0 accepted" in view.stdout, view.stdout
    assert "{" not in view.stdout                                       # a view, not a JSON line
    assert raw.returncode == 0, raw.stderr[-2000:]
    body = json.loads(raw.stdout.strip().splitlines()[-1])
    assert body["mode"] == "IDLE" and body["robot_id"] == robot_id and body["control_dt"] == SPEC.control_dt


def test_operator_arm_says_why_the_hal_did_not_take_it() -> None:
    """A HAL in RAMP ignores an ARM; an ARM stamped before an E-stop (here: one stamped an hour
    ahead, as from a clock running ahead) is cancelled. The operator exits 1 and says why."""
    ep, robot_id = f"tcp/127.0.0.1:{free_port()}", "pupper-arm"
    hal = start_hal(ep, robot_id, "--status-hz", "20", "--arm")
    base = [sys.executable, "-m", "virl_quad.deploy.operator", "arm", "--robot-id", robot_id,
            "--connect", ep, "--wait", "5"]
    try:
        ignored = subprocess.run(base, capture_output=True, text=True, timeout=120)
        with zenoh.open(load_config("peer", listen=[], connect=[ep])) as s:
            ahead = time.time_ns() + 3600 * 10**9
            pub = s.declare_publisher(P.key(robot_id, "estop"), **publisher_options("estop"))
            assert wait_until(lambda: pub.matching_status.matching, 30.0)
            operator = subprocess.Popen(base, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            k = 1
            while operator.poll() is None:         # E-stops every 0.2 s: one is always < 1 s old
                pub.put(P.encode_json(MsgType.ESTOP, {"reason": "test"}, k, stamp_ns=ahead + k))
                k += 1
                time.sleep(0.2)
            out, err = operator.communicate(timeout=60)
            pub.undeclare()
        before = subprocess.CompletedProcess(base, operator.returncode, out, err)
    finally:
        hal.close()
    assert ignored.returncode == 1 and "ARM not taken: the HAL is already in RAMP or ACTIVE" in ignored.stderr, \
        ignored.stderr[-2000:]
    assert before.returncode == 1 and "ARM not taken: it was sent before an E-stop" in before.stderr, \
        before.stderr[-2000:]
