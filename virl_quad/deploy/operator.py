"""Operator console: watch a HAL's STATUS, re-arm it, E-stop it.

    python -m virl_quad.deploy.operator status --robot-id pupper-01 [--watch] [--json]
    python -m virl_quad.deploy.operator arm    --robot-id pupper-01
    python -m virl_quad.deploy.operator estop  --robot-id pupper-01 --reason "hand on the robot"

Connects like the policy server (``--zenoh``, ``--connect``; default the config's endpoints,
else ``tcp/127.0.0.1:7447``). Under ``secure_client.json5`` the session's user decides what
the HAL accepts: ``operator`` may arm, every authenticated user may E-stop. ``arm`` and
``estop`` wait for a STATUS that shows the effect and exit 1 if none comes. Each prints the
HAL's STATUS for a person (mode, fault, base height and speed, time in ACTIVE, commands and
what the safety layer did to them); ``--watch`` redraws it every second until Ctrl-C and
``--json`` prints the raw STATUS bodies instead, one JSON line each, for scripts.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import zenoh

from virl_quad.cli import UserError, opt, parse, run_main
from virl_quad.deploy import protocol as P
from virl_quad.deploy._zenoh_io import StopFlag, open_config, open_session
from virl_quad.deploy.protocol import MsgType, ProtocolError
from virl_quad.deploy.safety import CLAMPS
from virl_quad.deploy.zenoh_config import DEFAULT_CONNECT, load_config, publisher_options

ACTIONS = ("status", "arm", "estop")
PENDING = " (E-stop received: DAMPING from the next tick)"   # shown beside the mode


def wait_until(pred: Callable[[], Any], timeout: float, interval: float = 0.02) -> Any:
    """Poll ``pred`` until it returns something truthy or ``timeout`` s pass; returns its last value."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(interval)


def _counts(d: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(d.items())) if d else "none"


def format_status(status: dict[str, Any], state: P.RobotState | None = None) -> str:
    """A STATUS body (and the newest STATE, if any) as lines a person reads."""
    dt = status.get("control_dt")                                  # s
    active = status.get("active_ticks")
    lines = [f"{status.get('robot_id', '?')} ({status.get('robot', '?')}, {status.get('backend', '?')} backend)  "
             f"mode {status.get('mode', '?')}{PENDING if status.get('estop_pending') else ''}"
             f"  fault: {status.get('fault') or 'none'}"]
    motion = []
    if state is not None and state.base_pos is not None:
        motion.append(f"base height {state.base_pos[2]:.3f} m")
    if state is not None and state.base_vel is not None:
        motion.append(f"forward speed {state.base_vel[0]:+.2f} m/s")
    if state is not None and state.base_pos is None:
        motion.append("base height and speed: not measured on this robot")
    if status.get("mode") == "ACTIVE" and active is not None:
        motion.append(f"ACTIVE for {active * dt:.1f} s" if dt else f"ACTIVE for {active} ticks")
    if motion:
        lines.append("  ".join(motion))
    accepted, applied = status.get("accepted", 0), status.get("applied", 0)
    lines.append(f"commands: {accepted} accepted, {applied} applied; rejected: {_counts(status.get('rejected', {}))}")
    clamped = status.get("clamped", {})
    if clamped:
        lines.append("changed by the safety layer before being applied:")
        for kind, n in sorted(clamped.items()):
            share = f" of {applied} applied ({100.0 * n / applied:.0f} %)" if applied else ""
            meaning = CLAMPS.get(kind, "")
            if kind == "q_step" and status.get("max_step") is not None:
                meaning = meaning.replace("max_step (rad)", f"{status['max_step']:g} rad")
            lines.append(f"  {kind} {n}{share}: {meaning}")
    else:
        lines.append("changed by the safety layer before being applied: none")
    lines.append(f"events: {_counts(status.get('events', {}))}")
    extra = [f"policy alive: {'yes' if status.get('policy_alive') else 'no'}"] if "policy_alive" in status else []
    extra += [f"{k} {status[k]}" for k in ("overruns", "unanswered") if k in status]
    if status.get("errors"):
        extra.append(f"errors: {_counts(status['errors'])}")
    if extra:
        lines.append("  ".join(extra))
    return "\n".join(lines)


class Operator:
    """A Zenoh session on one robot: newest STATUS and STATE, ARM, E-stop."""

    def __init__(self, conf: zenoh.Config, robot_id: str, session: zenoh.Session | None = None) -> None:
        """Open a session with ``conf`` (or use ``session``) and subscribe to STATUS and STATE."""
        self.robot_id = P.check_robot_id(robot_id)
        self.session = session if session is not None else zenoh.open(conf)
        self.status: dict[str, Any] = {}
        self.state: P.RobotState | None = None
        self.statuses = 0                      # STATUS messages received
        self._lock = threading.Lock()
        self._seq = P.SeqCounter()
        self._subs = [self.session.declare_subscriber(P.key(robot_id, "status"), self._on_status),
                      self.session.declare_subscriber(P.key(robot_id, "state"), self._on_state)]

    @classmethod
    def peer(cls, endpoint: str, robot_id: str) -> "Operator":
        """An operator on the plain peer config connecting to ``endpoint``."""
        return cls(load_config("peer", listen=[], connect=[endpoint]), robot_id)

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            body = P.decode(sample.payload.to_bytes(), expect=MsgType.STATUS).body
        except ProtocolError:
            return
        with self._lock:
            self.status = body  # type: ignore[assignment]
            self.statuses += 1

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            st = P.decode(sample.payload.to_bytes(), expect=MsgType.STATE).body
        except ProtocolError:
            return
        with self._lock:
            self.state = st  # type: ignore[assignment]

    def latest(self) -> dict[str, Any]:
        """A copy of the newest STATUS body ({} before the first)."""
        with self._lock:
            return dict(self.status)

    def latest_state(self) -> P.RobotState | None:
        """The newest STATE (None before the first)."""
        with self._lock:
            return self.state

    def wait_status(self, pred: Callable[[dict[str, Any]], bool], timeout: float = 60.0) -> dict[str, Any]:
        """Wait up to ``timeout`` s for a STATUS satisfying ``pred``; returns it, or the last
        one seen (for which ``pred`` is false)."""
        got = wait_until(lambda: (lambda s: s if s and pred(s) else None)(self.latest()), timeout)
        return got or self.latest()

    def alive(self, role: str, timeout: float = 2.0) -> bool:
        """True if the ``alive/<role>`` liveliness token of this robot is visible."""
        replies = self.session.liveliness().get(P.liveliness_key(self.robot_id, role), timeout=timeout)
        return any(r.ok is not None for r in replies)

    def arm(self, robot_id: str | None = None) -> None:
        """Publish an ARM for ``robot_id`` (default this operator's robot)."""
        body = {"robot_id": robot_id or self.robot_id}
        self.session.put(P.key(self.robot_id, "arm"), P.encode_json(MsgType.ARM, body, self._seq()),
                         **publisher_options("arm"))

    def estop(self, reason: str = "operator") -> None:
        """Publish an E-stop with ``reason``."""
        self.session.put(P.key(self.robot_id, "estop"),
                         P.encode_json(MsgType.ESTOP, {"reason": reason, "source": "operator"}, self._seq()),
                         **publisher_options("estop"))

    def close(self) -> None:
        """Undeclare the subscribers and close the session."""
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:
                pass
        self.session.close()


@dataclass
class OperatorConfig:
    """One operator command."""

    action: str = opt("status", "what to do", choices=ACTIONS, positional=True)
    robot_id: str = opt("pupper-01", "the HAL's robot id")
    zenoh: str = opt("peer", "Zenoh config: name in deploy/zenoh/ or a .json5 path")
    connect: list[str] | None = opt(None, f"HAL endpoint (unset: the config's, else {DEFAULT_CONNECT})")
    reason: str = opt("operator", "estop: reason shown in the STATUS fault")
    wait: float = opt(10.0, "s to wait for the HAL and for the effect")
    watch: bool = opt(False, "keep showing the newest STATUS every second until Ctrl-C")
    json: bool = opt(False, "raw STATUS bodies as JSON lines, for scripts")


def _shower(as_json: bool, op: Operator) -> Callable[[dict[str, Any]], None]:
    """How a STATUS is shown: a JSON line, or the text view (redrawn in place on a terminal)."""
    redraw = sys.stdout.isatty()

    def show(status: dict[str, Any]) -> None:
        if as_json:
            print(json.dumps(status, sort_keys=True), flush=True)
            return
        text = format_status(status, op.latest_state())
        print(("\x1b[H\x1b[J" if redraw else "") + text + ("" if redraw else "\n"), flush=True)
    return show


#: Why the HAL did not take an ARM, by the STATUS event that counted it (most specific first).
_NOT_ARMED: tuple[tuple[str, str], ...] = (
    ("arm_before_estop", "it was sent before an E-stop that the HAL received just before it (or this "
                         "machine's clock is behind the E-stop sender's); send it again"),
    ("arm_cancelled", "an E-stop arrived in the same control period"),
    ("arm_ignored", "the HAL is already in RAMP or ACTIVE"),
)


def _why_not_armed(before: dict, after: dict) -> str:
    """The reason an ARM was not taken, read from the STATUS events before and after it."""
    b, a = before.get("events", {}), after.get("events", {})
    for event, why in _NOT_ARMED:
        if a.get(event, 0) > b.get(event, 0):
            return why
    return "no STATUS showed it taken in time (wrong robot id, or not allowed to arm under the secure config?)"


def main(config: OperatorConfig) -> int:
    """Run one operator command; 0 if the HAL confirmed it in STATUS, 1 if not."""
    if config.action not in ACTIONS:
        raise UserError(f"unknown action {config.action!r}; choose {', '.join(ACTIONS)}")
    conf = open_config(config.zenoh, listen=[], connect=config.connect)
    if not config.connect and conf.get_json("connect/endpoints").strip() in ("[]", "null"):
        conf.insert_json5("connect/endpoints", json.dumps([DEFAULT_CONNECT]))
    zenoh.init_log_from_env_or("error")
    with open_session(conf) as session:
        op = Operator(conf, config.robot_id, session=session)
        try:
            before = op.wait_status(lambda s: True, config.wait)
            if not before:
                print(f"no STATUS from HAL {config.robot_id!r} within {config.wait:g} s", file=sys.stderr)
                return 1
            if config.action == "arm":
                op.arm()
                n = before.get("events", {}).get("arm", 0)
                st = op.wait_status(lambda s: s.get("events", {}).get("arm", 0) > n, config.wait)
                ok = st.get("events", {}).get("arm", 0) > n
                if not ok:
                    print(f"ARM not taken: {_why_not_armed(before, st)}", file=sys.stderr)
            elif config.action == "estop":
                op.estop(config.reason)
                st = op.wait_status(lambda s: s.get("mode") == "DAMPING", config.wait)
                ok = st.get("mode") == "DAMPING"
            else:
                st, ok = before, True
            show = _shower(config.json, op)
            show(st)
            with StopFlag() as stop:
                while config.watch and not stop.wait(1.0):
                    show(op.latest())
            return 0 if ok else 1
        finally:
            op.close()


def config_from_args(argv: list[str] | None = None) -> OperatorConfig:
    """Parse the command line into an :class:`OperatorConfig` (its fields are the options)."""
    return parse(OperatorConfig, argv, __doc__.split("\n\n")[0], "python -m virl_quad.deploy.operator")


if __name__ == "__main__":
    run_main(lambda: main(config_from_args()))
