"""Hardware-in-the-loop with a simulated Pupper: REAL processes, real Zenoh on loopback.

``python -m virl_quad.deploy.hal --lockstep`` (sim backend) and ``python -m
virl_quad.deploy.serve`` run as subprocesses on free ports (peer config: multicast scouting
off); this test process is the operator (STATUS, ARM, E-stop). Lock-step makes the simulated
run independent of machine load: no assertion depends on wall-clock timing, only on ticks.

(a) the shipped policy (the server's default: ``policies/pupper_trot.pt``, the VIRL trot, else
    ``policies/pupper_trot_tracker_bc.pt``, the privileged tracker distilled by
    ``python -m virl_quad.distill``) drives the Pupper for 10 s of sim time: every
    applied command is safe, the robot stays up, and it moves forward, as far as it does in
    the training env from the same standing start, within 25% (the deployment chain reproduces
    training)
(b) SIGKILL of the server -> DAMPING after 3 held periods (seen in STATUS); a restarted
    server drives the robot again only after a re-arm
(c) E-stop (also with an undecodable payload) damps and latches; bad commands are counted
(+) CLI errors: one line on stderr, exit code 2
"""

from __future__ import annotations

import signal
import sys
import time

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.deploy import protocol as P
from hil_harness import Monitor, Proc, export_untrained, policy_for_tests, start_hal, start_server
from virl_quad.deploy.protocol import JointCommand
from virl_quad.deploy.safety import SafetyConfig, is_safe_command, roll_pitch
from virl_quad.deploy.zenoh_config import free_port, publisher_options

ROBOT_ID = "pupper-hil"
SPEC = robots.get("pupper")
TIMEOUT = 120.0                  # s, generous waits for a loaded 2-core machine (never asserted)
LOCKSTEP = ("--lockstep", "--lockstep-timeout", "2.0")   # a slow server never misses a period
DRIVE_SECONDS = 10.0             # s of simulated time driven by the policy
MIN_FORWARD = 0.25               # m in DRIVE_SECONDS: "moves forward" for the shipped policy


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    """(path, shipped?): the shipped Pupper policy if present, else an untrained export."""
    return policy_for_tests(tmp_path_factory.mktemp("hil_policy"))


def _endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


def _logs(*procs: Proc) -> str:
    return "\n".join(f"--- {p.name} ---\n{p.output()}" for p in procs)


class Rig:
    """A lock-step sim HAL + a monitor session (+ servers started by the test); cleans up."""

    def __init__(self, *hal_args: str, lockstep: bool = True) -> None:
        self.ep = _endpoint()
        self.hal = start_hal(self.ep, ROBOT_ID, *(LOCKSTEP if lockstep else ()), *hal_args)
        self.mon = Monitor.peer(self.ep, ROBOT_ID)
        self.procs = [self.hal]

    def server(self, policy, *args: str) -> Proc:
        proc = start_server(policy, self.ep, ROBOT_ID, *args)
        self.procs.append(proc)
        return proc

    def logs(self) -> str:
        return _logs(*self.procs)

    def wait(self, pred, what: str) -> dict:
        st = self.mon.wait_status(pred, TIMEOUT)
        assert st and pred(st), f"STATUS never showed {what}; last {st}\n{self.logs()}"
        return st

    def close(self) -> None:
        self.mon.close()
        for p in self.procs:
            p.close()


@pytest.fixture
def rig_factory():
    rigs: list[Rig] = []

    def make(*hal_args: str, lockstep: bool = True) -> Rig:
        rigs.append(Rig(*hal_args, lockstep=lockstep))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


# ----------------------------------------------------------------------------- (a) drive 10 s

@pytest.fixture(scope="module")
def drive(policy, tmp_path_factory):
    """Run HAL + server until the policy has driven DRIVE_SECONDS of sim time; the HAL's record."""
    path, shipped = policy
    rec = tmp_path_factory.mktemp("hil_drive") / "run.npz"
    rig = Rig("--arm", "--record", str(rec))
    try:
        srv = rig.server(path)
        n = int(round(DRIVE_SECONDS / SPEC.control_dt))
        st = rig.wait(lambda s: s["applied"] >= n + 5 or s["mode"] == "DAMPING", f"{n} applied commands")
        assert st["mode"] == "ACTIVE", f"the HAL left ACTIVE: {st}\n{rig.logs()}"
        assert rig.hal.stop(signal.SIGINT) == 0, rig.logs()
        assert srv.stop(signal.SIGINT) == 0, rig.logs()
        logs = rig.logs()
    finally:
        rig.close()
    return dict(np.load(rec)), n, shipped, st, logs


def _window(data: dict, n: int, logs: str) -> tuple[np.ndarray, np.ndarray]:
    """(mode name per tick, the n + 1 ticks from the first ACTIVE one)."""
    modes = [str(m) for m in data["modes"]]
    mode = np.array([modes[i] for i in data["mode"]])
    active = np.flatnonzero(mode == "ACTIVE")
    assert active.size >= n, f"only {active.size} ACTIVE ticks recorded\n{logs}"
    return mode, np.arange(int(active[0]), int(active[0]) + n + 1)


def test_policy_drives_pupper_10_s_safely_and_upright(drive):
    data, n, shipped, status, logs = drive
    mode, win = _window(data, n, logs)
    assert np.all(mode[win] == "ACTIVE"), f"fault during the run: {status}\n{logs}"
    t = data["t"]
    assert t[win[-1]] - t[win[0]] == pytest.approx(DRIVE_SECONDS, abs=1e-6)    # lock-step: exact sim time
    # every command the backend received is safe, and consecutive powered targets move <= max_step
    powered = np.isin(mode, ["RAMP", "ACTIVE"])
    cmds = [JointCommand(*(data[k][i] for k in ("q_target", "kp", "kd", "tau_ff"))) for i in range(len(mode))]
    for i, c in enumerate(cmds):
        assert is_safe_command(c, SPEC), f"unsafe command at tick {data['tick'][i]} ({mode[i]}): {c}"
        if i > 0 and powered[i] and powered[i - 1]:
            assert is_safe_command(c, SPEC, prev=cmds[i - 1]), f"target jump at tick {data['tick'][i]}"
    # the policy (not a constant) drove the joints, with the metadata's gains
    q_t = data["q_target"][win]
    assert np.ptp(q_t, axis=0).max() > 1e-3
    np.testing.assert_allclose(data["kp"][win], np.broadcast_to(SPEC.kp, (len(win), 12)))
    # upright and off the ground all along
    tilt = np.array([np.abs(roll_pitch(q)) for q in data["quat"][win]])
    assert tilt[:, 0].max() < SPEC.max_roll and tilt[:, 1].max() < SPEC.max_pitch
    assert data["base_pos"][win, 2].min() > SPEC.min_base_height
    dx = data["base_pos"][win[-1], 0] - data["base_pos"][win[0], 0]
    print(f"\nHIL: {'shipped' if shipped else 'untrained'} policy, {DRIVE_SECONDS:g} s of sim time: "
          f"forward distance {dx:+.3f} m, base height {data['base_pos'][win, 2].min():.3f}.."
          f"{data['base_pos'][win, 2].max():.3f} m, status rejected {status['rejected']} clamped {status['clamped']}")
    assert "skipped none" in logs and "Traceback" not in logs, logs


def _env_run(path) -> tuple[float, bool]:
    """(forward distance m, fell?) of the policy in the training env, started as the HAL starts it:
    the env's standing start (the default pose held for the safety layer's ramp time, phase 0), no
    randomisation. A start dropped from the spawn height instead can put a policy in another
    limit cycle of its gait (one trot walked twice as far from it as from a stand)."""
    from virl_quad import demo as demo_lib
    from virl_quad import envs
    from virl_quad.evaluation.rollout import record_episode
    from virl_quad.policy_io import load_policy

    policy = load_policy(path)
    env = envs.make("pupper", demo=demo_lib.load("trot", "pupper"), randomize=False, render=False,
                    stand_start=True, episode_seconds=DRIVE_SECONDS,
                    **policy.contract.env_overrides())   # its own actions (TG)
    try:
        obs, _ = env.reset(seed=0)
        traj, _, fell = record_episode(env, lambda o: policy.act(o["policy"]), obs)
    finally:
        env.close()
    return float(traj.root_pos[-1, 0] - traj.root_pos[0, 0]), fell


def test_shipped_policy_moves_forward_as_in_the_training_env(drive, policy):
    """The deployment chain (observation builder, phase clock, gains, safety limits, protocol)
    reproduces the training environment: the shipped policy walks there and here."""
    data, n, shipped, _, logs = drive
    if not shipped:
        pytest.skip("no shipped policy in policies/ (see virl_quad.deploy.serve.SHIPPED_POLICIES): the "
                    "'moves forward' check needs one (the pipeline and safety checks ran with an untrained export)")
    _, win = _window(data, n, logs)
    dx = data["base_pos"][win[-1], 0] - data["base_pos"][win[0], 0]
    dx_env, fell = _env_run(policy[0])
    print(f"\nHIL: shipped policy {policy[0].name} moved {dx:+.3f} m in {DRIVE_SECONDS:g} s through HAL + server; "
          f"{dx_env:+.3f} m in the training env")
    assert dx > MIN_FORWARD, f"moved only {dx:.3f} m (want > {MIN_FORWARD} m)\n{logs}"
    assert not fell and 0.8 < dx / dx_env < 1.25, f"HIL {dx:.3f} m against env {dx_env:.3f} m (fell {fell})"


# ----------------------------------------------------------------------------- (b) server killed

def test_killed_server_damps_within_3_periods_and_restart_needs_rearm(policy, rig_factory):
    """``--reset-on-arm``: a damped sim Pupper collapses into a crouch from which the safety
    layer's joint-space RAMP pitches it past its 0.4 rad tilt limit (a tilt fault, correctly),
    so the simulated operator puts it back on its feet when re-arming, as one would by hand."""
    path, _ = policy
    rig = rig_factory("--arm", "--reset-on-arm")
    srv = rig.server(path)
    st = rig.wait(lambda s: s["mode"] == "ACTIVE" and s["applied"] >= 25, "ACTIVE with 25 commands applied")
    srv.popen.kill()                                         # SIGKILL: no goodbye
    srv.wait(30)
    st = rig.wait(lambda s: s["mode"] == "DAMPING" and not s["policy_alive"], "DAMPING after the kill")
    assert st["fault"] == "watchdog", st
    held = SafetyConfig().watchdog_periods
    # the last command was applied at cmd_tick, held for 3 periods, the 4th period is damped
    assert st["fault_tick"] - st["cmd_tick"] == held + 1, st
    applied = st["applied"]
    # a restarted server talks to the HAL (commands accepted) but nothing is applied until ARM
    rig.server(path)
    acc = st["accepted"]
    st = rig.wait(lambda s: s["accepted"] >= acc + 50 and s["policy_alive"], "the new server's commands")
    assert st["mode"] == "DAMPING" and st["applied"] == applied, st
    rig.mon.arm()
    st = rig.wait(lambda s: s["mode"] == "ACTIVE" and s["applied"] >= applied + 25, "ACTIVE again after ARM")
    assert st["events"]["arm"] == 2 and st["fault"] == "", st
    # an E-stop whose payload does not even decode still stops the robot (fail-safe direction)
    rig.mon.session.put(P.key(ROBOT_ID, "estop"), b"garbage")
    st = rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING after a garbage E-stop")
    assert st["fault"] == "estop" and st["rejected_other"].get("estop:bad_size") == 1, st
    assert rig.hal.stop() == 0, rig.logs()


# ----------------------------------------------------------------------------- (c) E-stop

def test_estop_damps_and_latches_bad_input_is_counted(policy, rig_factory, tmp_path):
    path, _ = policy
    rec = tmp_path / "estop.npz"
    rig = rig_factory("--arm", "--record", str(rec))
    rig.server(path)
    st = rig.wait(lambda s: s["mode"] == "ACTIVE" and s["applied"] >= 25, "ACTIVE")
    cmd_key = P.key(ROBOT_ID, "cmd")
    rig.mon.session.put(cmd_key, b"\x00junk")                            # malformed: bad_size
    rig.mon.session.put(cmd_key, b"VIRL" + bytes(28))                     # bad_version
    st = rig.wait(lambda s: sum(s["rejected"].values()) >= 2, "the bad commands counted")
    assert st["rejected"] == {"bad_size": 1, "bad_version": 1} and st["mode"] == "ACTIVE", st
    rig.mon.estop("hil test")
    st = rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING after the E-stop")
    assert st["fault"] == "estop: hil test" and st["events"]["estop"] == 1, st
    applied, acc = st["applied"], st["accepted"]
    st = rig.wait(lambda s: s["accepted"] >= acc + 50, "the server still sending")
    assert st["mode"] == "DAMPING" and st["applied"] == applied, st        # latched: nothing applied
    rig.mon.arm(robot_id="someone-else")                                 # ARM for another robot: ignored
    st = rig.wait(lambda s: s["rejected_other"].get("arm:wrong_robot") == 1, "the foreign ARM counted")
    assert st["mode"] == "DAMPING" and st["events"].get("arm") == 1 and st["applied"] == applied, st
    rig.mon.session.put(P.key(ROBOT_ID, "estop"), b"garbage")            # any payload is an E-stop
    st = rig.wait(lambda s: s["events"]["estop"] == 2, "the garbage E-stop")
    assert st["rejected_other"].get("estop:bad_size") == 1 and st["mode"] == "DAMPING", st
    assert rig.hal.alive() and rig.hal.stop(signal.SIGTERM) == 0, rig.logs()
    assert "hal: stopped: mode DAMPING" in rig.hal.output()
    # what the simulated motors received: from the E-stop on, only damping (kp 0, spec kd)
    data = np.load(rec)
    mode = np.array([str(data["modes"][i]) for i in data["mode"]])
    after = np.arange(int(np.flatnonzero(mode == "DAMPING")[0]), len(mode))
    assert len(after) >= 50 and np.all(mode[after] == "DAMPING")
    assert np.all(data["kp"][after] == 0) and np.all(data["tau_ff"][after] == 0)
    np.testing.assert_array_equal(data["kd"][after], np.broadcast_to(SPEC.kd, (len(after), 12)))


def test_real_time_loop_serves_state_and_obeys_the_operator(rig_factory):
    """The fixed-rate loop (no lock-step, no policy): states flow, ARM ramps, E-stop damps."""
    rig = rig_factory(lockstep=False)
    st = rig.wait(lambda s: s["ticks"] >= 10 and s["t"] > 0, "a running real-time loop")
    assert st["mode"] == "IDLE" and st["lockstep"] is False, st
    assert rig.mon.state is not None and rig.mon.state.base_pos is not None    # sim: HAS_BASE
    rig.mon.arm()
    rig.wait(lambda s: s["mode"] == "RAMP", "RAMP after ARM")
    rig.mon.estop("rt")
    st = rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING after the E-stop")
    assert st["fault"] == "estop: rt" and st["accepted"] == 0, st
    assert rig.hal.stop(signal.SIGTERM) == 0, rig.logs()


def test_a_command_naming_a_future_state_does_not_free_run_lock_step(rig_factory):
    """A lock-step HAL advances one period per answered state; a command whose ref_seq names a
    state not yet published (here 2**63) answers nothing, so with no policy the loop keeps the
    real-time pace instead of running as fast as the CPU allows."""
    rig = rig_factory()
    st = rig.wait(lambda s: s["ticks"] >= 10, "a running lock-step loop")
    cmd = JointCommand(SPEC.default_pose.copy(), SPEC.kp.copy(), SPEC.kd.copy(), np.zeros(12), ref_seq=2**63)
    rig.mon.session.put(P.key(ROBOT_ID, "cmd"), P.encode_command(cmd, 1), **publisher_options("arm"))
    st = rig.wait(lambda s: s["accepted"] >= 1, "the command accepted")
    t0, ticks0 = time.monotonic(), st["ticks"]
    time.sleep(2.0)
    st = rig.mon.wait_status(lambda s: s["ticks"] > ticks0, TIMEOUT)
    rate = (st["ticks"] - ticks0) / (time.monotonic() - t0)          # ticks per wall second
    print(f"\n[lock-step after a future ref_seq] {rate:.1f} ticks/s (control rate {1 / SPEC.control_dt:g} Hz)")
    assert rate < 1.5 / SPEC.control_dt, (rate, st)


# ----------------------------------------------------------------------------- CLI errors

def _run(module: str, *args: str, timeout: float = 120.0) -> tuple[int, str]:
    import subprocess

    from hil_harness import ROOT

    r = subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=timeout)
    return r.returncode, r.stderr


def _one_line_error(rc: int, err: str, needle: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("argv[0]")]
    assert rc == 2 and "Traceback" not in err, err
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], err


def test_cli_bad_input_is_one_line_exit_2(policy, tmp_path, rig_factory):
    hal = "virl_quad.deploy.hal"
    _one_line_error(*_run(hal, "--backend", "warp-drive"), "unknown backend")
    _one_line_error(*_run(hal, "--robot", "spot"), "unknown robot")
    _one_line_error(*_run(hal, "--zenoh", str(tmp_path / "missing.json5")), "no Zenoh config")
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: 'peer', listen: { endpoints: [ }")
    _one_line_error(*_run(hal, "--zenoh", str(bad)), "bad Zenoh config")
    serve = "virl_quad.deploy.serve"
    _one_line_error(*_run(serve, "--policy", str(tmp_path / "nothing.pt")), "does not exist")
    path, _ = policy
    fake = tmp_path / "fake.pt"
    fake.write_bytes(b"not a torchscript archive")
    fake.with_suffix(".json").write_text(path.with_suffix(".json").read_text())
    _one_line_error(*_run(serve, "--policy", str(fake)), "not a TorchScript policy")
    notes = tmp_path / "notes.md"              # a file of another type, no metadata beside it
    notes.write_text("# not a policy\n")
    _one_line_error(*_run(serve, "--policy", str(notes)), "not a TorchScript policy")
    # a Laikago policy against a running Pupper HAL: refused after the announce
    laikago = export_untrained(tmp_path, "laikago")
    rig = rig_factory()
    rc, err = _run(serve, "--policy", str(laikago), "--robot-id", ROBOT_ID, "--connect", rig.ep, "--quiet")
    _one_line_error(rc, err, "robot 'pupper' does not match the policy's 'laikago'")
