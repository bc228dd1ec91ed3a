"""The hardware-abstraction layer (HAL): one robot (or simulator) behind the safety layer,
served over Zenoh with the protocol of ``deploy/PROTOCOL.md``.

    python -m virl_quad.deploy.hal --robot pupper --backend sim [--lockstep] [--arm]

Every control period: read the backend's state, publish it on ``virl/<id>/state``, give the
policy a moment to answer, run :meth:`SafetyController.tick` and apply exactly its output
to the backend. Commands from ``virl/<id>/cmd`` only ever reach the backend through the
safety layer. ``estop`` and ``arm`` are handled as the protocol says; STATUS is published at
``--status-hz`` and on every mode change; ``announce`` is answered to every query; the
liveliness token ``virl/<id>/alive/hal`` is held while running.

Real time (default): a fixed-rate loop at the robot's ``control_dt``; after publishing the
state it waits up to ``--cmd-wait`` x control_dt for the command computed from that state
(so the policy's latency is not a whole period), then ticks; late periods count as overruns.

Lock-step (``--lockstep``, simulation and tests): the loop waits for the command answering
the state just published (``ref_seq``), then advances exactly one control period, so a busy
machine changes wall-clock speed but not the simulated run. If no answer comes within
``--lockstep-timeout`` s (default 3 x control_dt), the HAL ticks without a command and keeps
ticking at the real-time pace until the policy answers again: a dead policy server therefore
still meets the watchdog (DAMPING after more than 3 control periods without a command).
"""

from __future__ import annotations

import struct
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zenoh

from virl_quad import robots
from virl_quad.cli import UserError, opt, parse, run_main
from virl_quad.deploy import protocol as P
from virl_quad.deploy._record import Recorder
from virl_quad.deploy._zenoh_io import Log, SeqPublisher, StopFlag, open_config, open_session, undeclare_all
from virl_quad.deploy.backends import Backend, BackendError, backend_names, get_backend
from virl_quad.deploy.protocol import JointCommand, MsgType, RobotState
from virl_quad.deploy.safety import Mode, SafetyConfig, SafetyController

_REF_SEQ = struct.Struct("<Q")          # COMMAND payload offset 0: ref_seq


def _payload(sample: zenoh.Sample) -> bytes | None:
    """A sample's payload; None for a DELETE (no message at all)."""
    return None if sample.kind == zenoh.SampleKind.DELETE else sample.payload.to_bytes()


@dataclass
class HalConfig:
    """Settings of one HAL process (the command line maps onto these fields)."""

    robot: str = opt("pupper", "robot spec: " + ", ".join(robots.names()))
    backend: str = opt("sim", "robot backend: " + ", ".join(backend_names()))
    robot_id: str | None = opt(None, "robot instance id in the key expressions virl/<id>/... (unset: <robot>-01)")
    zenoh: str = opt("peer", "Zenoh config: name in deploy/zenoh/ or a .json5 path")
    listen: list[str] | None = opt(None, "listen endpoint, replaces the config's")
    connect: list[str] | None = opt(None, "connect endpoint, replaces the config's")
    lockstep: bool = opt(False, "advance one control period per answered state (simulation, tests)")
    lockstep_timeout: float | None = opt(None, "s without an answer before ticking anyway (unset: 3 x control_dt)")
    cmd_wait: float = opt(0.5, "real time: fraction of a control period to wait for the answer to the state")
    arm: bool = opt(False, "arm at start (IDLE -> RAMP) without an operator ARM")
    reset_on_arm: bool = opt(False, "sim: an accepted ARM first puts the robot back on its feet (as an "
                                    "operator would)")
    randomize: bool = opt(False, "sim: randomise the physics (seed --seed)")
    seed: int = opt(0, "sim: randomisation seed")
    port: str | None = opt(None, "pupper_serial: serial port of the motor board, e.g. /dev/ttyACM0")
    status_hz: float = opt(5.0, "STATUS rate, Hz (also sent on every mode change)")
    record: str | None = opt(None, "write the last 30000 ticks (state, applied command, mode) to this .npz "
                                   "when stopping")
    max_ticks: int = opt(0, "stop after this many control periods (0: until SIGINT/SIGTERM)")
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    quiet: bool = opt(False, "no log lines on stderr")


class Hal:
    """The HAL's Zenoh side and control loop (see the module docstring)."""

    def __init__(self, config: HalConfig, spec: Any, robot_id: str, backend: Backend,
                 session: zenoh.Session, log: Log) -> None:
        self.config, self.spec, self.robot_id, self.backend, self.log = config, spec, robot_id, backend, log
        self.ctl = SafetyController(spec, config.safety)
        self.dt = float(spec.control_dt)                       # s
        self.lockstep_timeout = (config.lockstep_timeout if config.lockstep_timeout is not None
                                 else 3.0 * self.dt)           # s
        self.errors: Counter[str] = Counter()                  # backend / callback failures
        self.overruns = 0            # real time: periods that ended late
        self.unanswered = 0          # lock-step: ticks without an answer to the state
        self.cmd_tick: int | None = None     # tick that last applied a new command
        self.fault_tick: int | None = None   # tick that last entered DAMPING
        self.last_t = float("nan")           # s, backend time of the last state
        self.policy_alive = False            # a policy server's alive/policy token is present
        self.recorder = Recorder() if config.record else None
        self._cv = threading.Condition()
        self._resp_ref = 0           # highest ref_seq of an accepted command answering a published state
        self._state_seq = 0          # sequence number of the newest state published
        self._resp_any = 0           # accepted commands with ref_seq 0 (unknown)
        self._announce = P.announce_body(spec, robot_id, limits=self.ctl.limits())
        k = lambda topic: P.key(robot_id, topic)  # noqa: E731
        self.state_pub = SeqPublisher(session, robot_id, "state")
        self.status_pub = SeqPublisher(session, robot_id, "status")
        self.announce_pub = SeqPublisher(session, robot_id, "announce")
        self._entities: list[Any] = [self.state_pub, self.status_pub, self.announce_pub]
        self._entities += [
            session.declare_subscriber(k("cmd"), self._on_cmd),
            session.declare_subscriber(k("estop"), self._on_estop),
            session.declare_subscriber(k("arm"), self._on_arm),
            session.declare_queryable(k("announce"), self._on_announce_query),
            session.liveliness().declare_token(P.liveliness_key(robot_id, "hal")),
            session.liveliness().declare_subscriber(P.liveliness_key(robot_id, "policy"), self._on_policy,
                                                    history=True),
        ]
        self.announce_pub.put(lambda s: P.encode_json(MsgType.ANNOUNCE, self._announce, s))
        self._status_stop = threading.Event()
        self._status_thread = threading.Thread(target=self._status_loop, name="hal-status", daemon=True)

    # ------------------------------------------------------------------ Zenoh callbacks

    def _guard(self, name: str, fn: Any, *args: Any) -> None:
        try:
            fn(*args)
        except Exception as e:   # a callback must never take the HAL down
            self.errors[f"callback_{name}"] += 1
            self.log.once(f"cb-{name}-{type(e).__name__}", f"error in the {name} callback (counted): {e!r}")

    def _on_cmd(self, sample: zenoh.Sample) -> None:
        self._guard("cmd", self._handle_cmd, sample)

    def _handle_cmd(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        if not self.ctl.receive(data):
            for reason in list(self.ctl.rejected):
                self.log.once(f"rej-{reason}", f"rejected command(s): {reason} (counted in STATUS)")
            return
        (ref,) = _REF_SEQ.unpack_from(data, P.HEADER_SIZE)
        with self._cv:
            if ref == 0:
                self._resp_any += 1
            elif ref <= self._state_seq:    # a ref_seq beyond the newest state answers nothing: one
                self._resp_ref = max(self._resp_ref, ref)   # such command must not free-run lock-step
            self._cv.notify_all()

    def _on_policy(self, sample: zenoh.Sample) -> None:
        alive = sample.kind == zenoh.SampleKind.PUT
        if alive != self.policy_alive:
            self.policy_alive = alive
            self.log("policy server attached" if alive else "policy server gone")

    def _on_estop(self, sample: zenoh.Sample) -> None:
        self.log("E-stop received")
        self._guard("estop", self.ctl.receive_estop, _payload(sample))

    def _on_arm(self, sample: zenoh.Sample) -> None:
        self._guard("arm", self.ctl.receive_arm, _payload(sample), self.robot_id)

    def _begin_period(self) -> None:
        """Open the safety layer's period (ARMs received since the last one, with no E-stop in
        their period, take effect at this period's tick); with ``reset_on_arm`` the sim robot is
        put back on its feet first, so that the tick starting the ramp measures that pose."""
        if not self.ctl.begin_period():
            return
        self.log("ARM taken: ramp to the default pose")
        if self.config.reset_on_arm:
            try:
                self.backend.reset()           # type: ignore[attr-defined]  (sim only)
                self.log("simulated robot put back on its feet")
            except Exception as e:
                self.errors["reset"] += 1
                self.log.once("reset", f"sim reset failed (counted): {e}")

    def _on_announce_query(self, query: zenoh.Query) -> None:
        def reply(q: zenoh.Query) -> None:
            q.reply(self.announce_pub.key, P.encode_json(MsgType.ANNOUNCE, self._announce, P.SeqCounter()()))
        self._guard("announce", reply, query)

    # ------------------------------------------------------------------ STATUS

    def status_body(self) -> dict[str, Any]:
        """The safety layer's STATUS plus this HAL's loop counters."""
        body = self.ctl.status()
        body.update({
            "robot": self.spec.name, "robot_id": self.robot_id, "backend": self.config.backend,
            "control_dt": float(self.spec.control_dt), "max_step": float(self.ctl.config.max_step),
            "lockstep": self.config.lockstep, "t": self.last_t if np.isfinite(self.last_t) else None,
            "overruns": self.overruns, "unanswered": self.unanswered, "cmd_tick": self.cmd_tick,
            "fault_tick": self.fault_tick, "policy_alive": self.policy_alive, "errors": dict(self.errors),
        })
        return body

    def publish_status(self) -> None:
        """Publish one STATUS message (never raises)."""
        self._guard("status", lambda: self.status_pub.put(
            lambda s: P.encode_json(MsgType.STATUS, self.status_body(), s)))

    def _status_loop(self) -> None:
        period = 1.0 / max(self.config.status_hz, 0.1)   # s
        while not self._status_stop.wait(period):
            self.publish_status()

    # ------------------------------------------------------------------ control loop

    def _read(self) -> RobotState | None:
        try:
            return self.backend.read_state()
        except Exception as e:   # BackendError, or anything a driver throws: DAMPING via no_state
            self.errors["read_state"] += 1
            self.log.once(f"read-{type(e).__name__}", f"backend read failed (counted): {e}")
            return None

    def _write(self, cmd: JointCommand, state: RobotState | None) -> None:
        """Apply ``cmd`` (a SafetyController.tick output); the record (``--record``) gets
        exactly what the backend is given, with the state the tick started from."""
        if self.recorder is not None:
            self._guard("record", self.recorder.add, state, self.ctl.mode, cmd, self.ctl.ticks)
        try:
            self.backend.write_command(cmd)
        except Exception as e:
            self.errors["write_command"] += 1
            self.log.once(f"write-{type(e).__name__}", f"backend write failed (counted): {e}")

    def _publish_state(self, state: RobotState | None) -> int | None:
        """Publish ``state``; its sequence number, or None if there is none to publish."""
        if state is None:
            return None
        try:
            self.last_t = float(state.timestamp)
            return self.state_pub.put(lambda s: self._encode_state(state, s))
        except Exception as e:   # a malformed state from a driver: the tick will judge it
            self.errors["publish_state"] += 1
            self.log.once(f"pub-{type(e).__name__}", f"could not publish a state (counted): {e}")
            return None

    def _encode_state(self, state: RobotState, seq: int) -> bytes:
        """Encode ``state`` as number ``seq``, which answers may name from now on (set before the
        message leaves, so a fast answer is never taken for one from the future)."""
        data = P.encode_state(state, seq, active=self.ctl.mode == Mode.ACTIVE)
        with self._cv:
            self._state_seq = seq
        return data

    def _wait_answer(self, seq: int, any_before: int, deadline: float, stop: StopFlag) -> bool:
        """Wait until a command answering state ``seq`` was accepted, or ``deadline``."""
        with self._cv:
            while not (self._resp_ref >= seq or self._resp_any > any_before):
                remaining = deadline - time.monotonic()
                if remaining <= 0 or stop.is_set():
                    return False
                self._cv.wait(min(remaining, 0.05))
            return True

    def run(self, stop: StopFlag) -> None:
        """Run the control loop until ``stop`` (or ``max_ticks``)."""
        cfg, dt = self.config, self.dt
        if cfg.arm:
            self.ctl.arm()
        self._status_thread.start()
        self.log(f"ready: robot {self.spec.name} as {self.robot_id!r}, backend {cfg.backend}, "
                 f"{'lock-step' if cfg.lockstep else 'real time'} at {1 / dt:g} Hz, mode {self.ctl.mode.value}")
        absent = True                      # lock-step: no policy answering (pace at real time)
        t_next = time.monotonic()
        mode = self.ctl.mode
        while not stop.is_set():
            t0 = time.monotonic()
            self._begin_period()
            state = self._read()
            with self._cv:
                any_before = self._resp_any
            seq = self._publish_state(state)
            wait = (dt if absent else self.lockstep_timeout) if cfg.lockstep else cfg.cmd_wait * dt
            answered = seq is not None and self._wait_answer(seq, any_before, t0 + wait, stop)
            if stop.is_set():
                break
            if cfg.lockstep:
                absent = not answered
                self.unanswered += int(not answered)
            applied_before = self.ctl.applied
            cmd = self.ctl.tick(state)
            self._write(cmd, state)
            if self.ctl.applied > applied_before:
                self.cmd_tick = self.ctl.ticks
            if self.ctl.mode != mode:
                if self.ctl.mode == Mode.DAMPING:
                    self.fault_tick = self.ctl.ticks
                self.log(f"mode {mode.value} -> {self.ctl.mode.value}"
                         + (f" ({self.ctl.fault})" if self.ctl.mode == Mode.DAMPING else ""))
                mode = self.ctl.mode
                self.publish_status()
            if cfg.max_ticks and self.ctl.ticks >= cfg.max_ticks:
                break
            if not cfg.lockstep:
                t_next += dt
                now = time.monotonic()
                if now > t_next:
                    self.overruns += 1
                    t_next = now           # do not try to catch up: the next period starts now
                else:
                    stop.wait(t_next - now)

    def close(self) -> None:
        """Stop STATUS, publish a last one, undeclare every Zenoh entity (never raises)."""
        self._status_stop.set()
        if self._status_thread.is_alive():
            self._status_thread.join(timeout=2.0)
        self.publish_status()
        undeclare_all(self._entities)
        if self.recorder is not None and self.config.record:
            try:
                self.recorder.save(self.config.record, self.spec)
            except OSError as e:
                self.log(f"could not write the record {self.config.record}: {e}")


def backend_kwargs(config: HalConfig, spec: Any) -> dict[str, Any]:
    """Constructor arguments of the chosen backend; UserError for options it does not take."""
    kw: dict[str, Any] = {"spec": spec}
    if config.backend == "sim":
        kw.update(randomize=config.randomize, seed=config.seed)
    elif config.randomize:
        raise UserError("--randomize works with the sim backend only")
    if config.reset_on_arm and config.backend != "sim":
        raise UserError("--reset-on-arm works with the sim backend only")
    if config.backend == "pupper_serial":
        if not config.port:
            raise UserError("the pupper_serial backend needs --port (e.g. /dev/ttyACM0)")
        kw["port"] = config.port
    elif config.port:
        raise UserError(f"--port is for the pupper_serial backend, not {config.backend!r}")
    return kw


def main(config: HalConfig) -> int:
    """Run a HAL until SIGINT/SIGTERM (or ``max_ticks``); returns the exit code.

    Bad input (unknown robot or backend, bad Zenoh config) raises UserError / ValueError /
    FileNotFoundError, which :func:`virl_quad.cli.run_main` prints as one line (exit 2)."""
    spec = robots.get(config.robot)
    robot_id = P.check_robot_id(config.robot_id or f"{spec.name}-01")
    if config.backend not in backend_names():
        raise UserError(f"unknown backend {config.backend!r}; choose one of: {', '.join(backend_names())}")
    if config.lockstep_timeout is not None and config.lockstep_timeout <= 0:
        raise UserError("--lockstep-timeout must be positive")
    if not 0 <= config.cmd_wait < 1:
        raise UserError("--cmd-wait must lie in [0, 1)")
    conf = open_config(config.zenoh, config.listen, config.connect)
    log = Log("hal", quiet=config.quiet)
    zenoh.init_log_from_env_or("error")
    try:
        backend = get_backend(config.backend, **backend_kwargs(config, spec))
    except BackendError as e:
        raise UserError(str(e)) from None
    with StopFlag() as stop:
        try:
            with open_session(conf) as session:
                hal = Hal(config, spec, robot_id, backend, session, log)
                try:
                    hal.run(stop)
                finally:
                    backend.close()            # leaves the robot damped
                    hal.close()
                    session.close()
            status = hal.status_body()
            log(f"stopped: mode {status['mode']}, {status['ticks']} ticks, {status['applied']} commands "
                f"applied, rejected {status['rejected'] or 'none'}, overruns {hal.overruns}")
        finally:
            backend.close()
    return 0


def config_from_args(argv: list[str] | None = None) -> HalConfig:
    """Parse the command line into a :class:`HalConfig` (its fields are the options)."""
    return parse(HalConfig, argv, __doc__.split("\n\n")[0], "python -m virl_quad.deploy.hal")


if __name__ == "__main__":
    run_main(lambda: main(config_from_args()))
