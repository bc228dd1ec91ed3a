"""Host-side safety layer: the only path from a policy's command to a motor.

Pure logic, no Zenoh, no policy: the HAL's control loop calls
:meth:`SafetyController.tick` once per control period with the latest
measured state and applies the :class:`JointCommand` it returns. Commands
arrive through :meth:`SafetyController.receive` (raw protocol bytes) at any
time, from any thread.

Modes::

    IDLE ──arm()──> RAMP ──ramp done + fresh valid command──> ACTIVE
      (zero torque)  (PD to default pose over ramp_time)      (validated policy commands)
    any powered mode ──E-stop / tilt / bad state / watchdog──> DAMPING ──arm()──> RAMP

DAMPING (kp = 0, kd = damping gains, no feed-forward) is latched: only an
explicit :meth:`SafetyController.arm` leaves it.

E-stop and ARM requests are gathered per control period: a period opens at
:meth:`SafetyController.begin_period` (or at the tick itself when the caller never opens
one). An E-stop cancels every ARM requested in its own period, before or after it in
arrival order, and an ARM already taken at the start of its period: an E-stop always
wins over every ARM received before it in the same period or earlier.

Arrival order is not sending order: Zenoh lets an E-stop (highest priority) overtake an ARM
sent before it. So an ARM message stamped (header ``stamp_ns``, the sender's clock) no later
than an E-stop message received at most ``SafetyConfig.arm_stamp_window`` s before it is
cancelled too. The senders' clocks can only refuse an ARM this way, never cause one; the window
(on the controller's own monotonic clock) bounds what a sender's clock running ahead can block.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from enum import Enum
from typing import Any, Callable

import numpy as np

from virl_quad.deploy.limits import (CLAMPS, SafetyConfig, command_error, is_safe_command, roll_pitch,
                                     state_fault)
from virl_quad.deploy.limits import limits as limits_of
from virl_quad.deploy.protocol import NUM_JOINTS, JointCommand, MsgType, ProtocolError, RobotState, decode

__all__ = ["CLAMPS", "Mode", "SafetyConfig", "SafetyController", "is_safe_command", "roll_pitch"]


def _copy(c: JointCommand) -> JointCommand:
    ref = getattr(c, "ref_seq", 0)
    return JointCommand(*(np.array(a, dtype=np.float64) for a in (c.q_target, c.kp, c.kd, c.tau_ff)),
                        ref_seq=int(ref) if isinstance(ref, (int, np.integer)) and ref >= 0 else 0)


class Mode(str, Enum):
    """Safety state machine modes."""

    IDLE = "IDLE"
    RAMP = "RAMP"
    ACTIVE = "ACTIVE"
    DAMPING = "DAMPING"


class SafetyController:
    """State machine + command validator for one robot (see the module docstring)."""

    def __init__(self, spec: Any, config: SafetyConfig = SafetyConfig(),
                 clock: Callable[[], float] = time.monotonic) -> None:
        """``clock`` (s, monotonic) times only the ``arm_stamp_window``."""
        self.spec = spec
        self.config = config
        self._clock = clock
        self.mode = Mode.IDLE
        self.fault: str = ""                      # why the last DAMPING was entered
        self.ticks = 0                            # tick() calls so far
        self.rejected: Counter[str] = Counter()   # command rejections by reason
        self.clamped: Counter[str] = Counter()    # accepted commands modified, by kind
        self.events: Counter[str] = Counter()     # estop, tilt, watchdog, bad_state, arm, ...
        self.rejected_other: Counter[str] = Counter()  # bad ESTOP / ARM messages, "arm:bad_crc" etc.
        self.accepted = 0                         # commands that passed receive()
        self.applied = 0                          # ACTIVE ticks that applied a new command
        self.active_ticks = 0                     # ticks in ACTIVE since it was last entered
        self._lock = threading.Lock()
        self._last_seq: int | None = None         # newest accepted sequence number
        self._pending: JointCommand | None = None  # newest accepted, not yet consumed by tick()
        self._since_valid = 0                     # ticks since a valid command was consumed
        self._ramp_k = 0
        self._ramp_n = max(1, round(config.ramp_time / spec.control_dt))
        self._ramp_start = np.array(spec.default_pose, dtype=np.float64)
        self._last: JointCommand = self._zero_torque(np.array(spec.default_pose, dtype=np.float64))
        # the q_target of IDLE/DAMPING commands is irrelevant to the motor (kp = 0) but is kept
        # within the joint limits so that every output passes is_safe_command
        self._arm_requested = False               # an ARM arrived in the open period
        self._arm_pending = False                 # taken at begin_period: RAMP at the next tick
        self._estop_pending = ""                  # DAMPING at the next tick, with this fault text
        self._estop_in_period = False             # an E-stop arrived in the open period
        self._period_open = False                 # begin_period() was called since the last tick
        self._estop_stamp = -1                    # ns, largest sender stamp of any decoded E-stop message
        self._estop_rx = -math.inf                # s (clock), when the last decoded E-stop message arrived

    # ------------------------------------------------------------------ inputs (any thread)

    def receive(self, data: Any) -> bool:
        """Decode and validate one COMMAND message (bytes or zenoh.ZBytes from the cmd key).
        Returns True if accepted; otherwise counts the rejection reason. Never raises."""
        try:
            msg = decode(data, expect=MsgType.COMMAND)
        except ProtocolError as e:
            with self._lock:
                self.rejected[e.reason] += 1
            return False
        return self.receive_command(msg.body, msg.seq)  # type: ignore[arg-type]

    def receive_command(self, cmd: JointCommand, seq: int) -> bool:
        """Validate an already-decoded command (in-process policies use this). Never raises."""
        reason = command_error(cmd)
        if reason is None and (isinstance(seq, bool) or not isinstance(seq, (int, np.integer)) or seq < 0):
            reason = "bad_seq"
        with self._lock:
            if reason is None and self._last_seq is not None and seq <= self._last_seq:
                reason = "stale_seq"
            if reason is not None:
                self.rejected[reason] += 1
                return False
            self._last_seq = int(seq)
            self._pending = _copy(cmd)
            self.accepted += 1
            return True

    def receive_estop(self, data: Any) -> None:
        """Handle a sample from the estop key: E-stop whatever the payload (fail-safe). Every
        sample counts in ``events["estop_received"]``; one that does not decode as ESTOP also
        in ``rejected_other`` (``None``, a sample without payload such as a Zenoh DELETE, as
        ``estop:delete``). Never raises."""
        reason, stamp = "estop", None
        try:
            if data is None:
                raise ProtocolError("delete")
            msg = decode(data, expect=MsgType.ESTOP)
            stamp, body = msg.stamp_ns, msg.body
            if isinstance(body, dict) and isinstance(body.get("reason"), str) and body["reason"]:
                reason = f"estop: {body['reason'][:80]}"
        except ProtocolError as e:
            with self._lock:
                self.rejected_other[f"estop:{e.reason}"] += 1
        with self._lock:
            self.events["estop_received"] += 1
            if stamp is not None:              # ARMs stamped up to here were sent before it
                self._estop_stamp = max(self._estop_stamp, stamp)
                self._estop_rx = self._clock()
        self.estop(reason)

    def receive_arm(self, data: Any, robot_id: str) -> bool:
        """Handle a sample from the arm key: request re-arming only for a valid ARM message
        naming ``robot_id`` (counted in ``events["arm_received"]``, then see :meth:`arm`);
        anything else is counted in ``rejected_other`` (``arm:<reason>``, ``arm:wrong_robot``,
        ``arm:delete`` for ``None``) and ignored. An ARM stamped no later than an E-stop message
        received within ``arm_stamp_window`` s was sent before it: cancelled
        (``events["arm_cancelled"]`` and ``events["arm_before_estop"]``). Never raises."""
        try:
            if data is None:
                raise ProtocolError("delete")
            msg = decode(data, expect=MsgType.ARM)
            body = msg.body
        except ProtocolError as e:
            with self._lock:
                self.rejected_other[f"arm:{e.reason}"] += 1
            return False
        if body.get("robot_id") != robot_id:
            with self._lock:
                self.rejected_other["arm:wrong_robot"] += 1
            return False
        with self._lock:
            self.events["arm_received"] += 1
            return self._request_arm(msg.stamp_ns)

    def estop(self, reason: str = "estop") -> None:
        """Request an emergency stop: DAMPING from the next tick on, latched until arm().
        Cancels (``events["arm_cancelled"]``) every ARM of the open period and one taken at
        its start."""
        with self._lock:
            self._estop_pending = reason or "estop"
            self._estop_in_period = True
            for attr in ("_arm_requested", "_arm_pending"):
                if getattr(self, attr):
                    setattr(self, attr, False)
                    self.events["arm_cancelled"] += 1

    def arm(self) -> bool:
        """Request (re-)arming: IDLE or DAMPING -> RAMP at the first tick after the next
        :meth:`begin_period`. Returns False (and does nothing) in RAMP or ACTIVE
        (``events["arm_ignored"]``) or when an E-stop arrived in the open period
        (``events["arm_cancelled"]``). Re-arming resets the sequence baseline: a restarted
        policy may begin again from any sequence number."""
        with self._lock:
            return self._request_arm(None)

    def _request_arm(self, stamp_ns: int | None) -> bool:
        if self.mode in (Mode.RAMP, Mode.ACTIVE):
            self.events["arm_ignored"] += 1
            return False
        if (stamp_ns is not None and stamp_ns <= self._estop_stamp
                and self._clock() - self._estop_rx <= self.config.arm_stamp_window):
            self.events["arm_before_estop"] += 1     # sent before an E-stop that overtook it
            self.events["arm_cancelled"] += 1
            return False
        if self._estop_in_period:
            self.events["arm_cancelled"] += 1
            return False
        self._arm_requested = True
        return True

    def begin_period(self) -> bool:
        """Open a control period: ARMs of the closed period with no E-stop in it are taken,
        to start the RAMP at the next tick unless an E-stop arrives first. Returns True if
        the next tick will start a RAMP (a simulator may reset the robot before it)."""
        with self._lock:
            return self._begin_period()

    def _begin_period(self) -> bool:
        self._arm_pending = self._arm_requested and not self._estop_pending
        self._arm_requested = False
        self._estop_in_period = False
        self._period_open = True
        return self._arm_pending

    # ------------------------------------------------------------------ the control tick

    def tick(self, state: RobotState | None) -> JointCommand:
        """Advance one control period and return the command to apply now (always safe).

        ``state`` is the latest measurement; pass None when the backend could not read one
        (in RAMP or ACTIVE that is a fault: DAMPING). Never raises on bad input."""
        with self._lock:
            if not self._period_open:
                self._begin_period()
            self._period_open = False
            self.ticks += 1
            pending, self._pending = self._pending, None
            q_meas = self._safe_q(getattr(state, "q", None), fallback=self._last.q_target)
            if self._estop_pending:                  # estop() has cancelled every earlier ARM
                self._enter_damping(self._estop_pending, "estop")
                self._estop_pending = ""
            elif self._arm_pending:
                self._arm_pending = False
                self.events["arm"] += 1
                self._last_seq = None
                self.fault = ""
                self.mode = Mode.RAMP
                self._ramp_k = 0
                self._ramp_start = q_meas
            if self.mode in (Mode.RAMP, Mode.ACTIVE):
                fault = state_fault(state, self.spec, self.config)
                if fault:
                    self._enter_damping(fault, fault)
            self._since_valid = 0 if pending is not None else self._since_valid + 1
            if self.mode == Mode.RAMP:
                out = self._ramp_step(pending)
            elif self.mode == Mode.ACTIVE:
                self.active_ticks += 1
                out = self._active_step(pending)
            elif self.mode == Mode.DAMPING:
                out = self._damping(q_meas)
            else:
                out = self._zero_torque(q_meas)
            self._last = out
            return _copy(out)

    def _ramp_step(self, pending: JointCommand | None) -> JointCommand:
        s = self.spec
        self._ramp_k = min(self._ramp_k + 1, self._ramp_n)
        a = self._ramp_k / self._ramp_n
        q = self._ramp_start + a * (np.asarray(s.default_pose) - self._ramp_start)
        out = JointCommand(np.clip(q, s.joint_lower, s.joint_upper), np.array(s.kp, dtype=np.float64),
                           np.array(s.kd, dtype=np.float64), np.zeros(NUM_JOINTS))
        if self._ramp_k >= self._ramp_n and pending is not None:
            self.mode = Mode.ACTIVE            # the policy is live: its next command is applied
            self.events["active"] += 1
            self.active_ticks = 0
        return out

    def _active_step(self, pending: JointCommand | None) -> JointCommand:
        if pending is None:
            if self._since_valid > self.config.watchdog_periods:
                self._enter_damping("watchdog", "watchdog")
                return self._damping(self._last.q_target)
            return self._last                  # hold the last applied command (tick() copies it)
        self.applied += 1
        return self._limit(pending)

    def _limit(self, cmd: JointCommand) -> JointCommand:
        s, c = self.spec, self.config
        q = np.clip(cmd.q_target, s.joint_lower, s.joint_upper)
        if np.any(q != cmd.q_target):
            self.clamped["q_limit"] += 1
        prev = self._last.q_target
        q_step = np.clip(q, prev - c.max_step, prev + c.max_step)
        if np.any(q_step != q):
            self.clamped["q_step"] += 1
        q = np.clip(q_step, s.joint_lower, s.joint_upper)
        kp = np.minimum(cmd.kp, c.gain_factor * s.kp)
        kd = np.minimum(cmd.kd, c.gain_factor * s.kd)
        if np.any(kp != cmd.kp) or np.any(kd != cmd.kd):
            self.clamped["gain"] += 1
        tau = np.clip(cmd.tau_ff, -s.torque_limit, s.torque_limit)
        if np.any(tau != cmd.tau_ff):
            self.clamped["tau_ff"] += 1
        return JointCommand(q, kp, kd, tau, ref_seq=cmd.ref_seq)

    # ------------------------------------------------------------------ helpers

    def _enter_damping(self, fault: str, event: str) -> None:
        if self.mode != Mode.DAMPING:
            self.fault = fault
        self.events[event] += 1
        self.mode = Mode.DAMPING

    def _safe_q(self, q: Any, fallback: np.ndarray | None = None) -> np.ndarray:
        """``q`` clipped to the joint limits if it is 12 finite values, else ``fallback``
        (or the default pose)."""
        try:
            a = np.asarray(q, dtype=np.float64)
            if a.shape == (NUM_JOINTS,) and np.all(np.isfinite(a)):
                return np.clip(a, self.spec.joint_lower, self.spec.joint_upper)
        except (TypeError, ValueError):
            pass
        return np.array(self.spec.default_pose if fallback is None else fallback, dtype=np.float64)

    def _zero_torque(self, q: np.ndarray) -> JointCommand:
        z = np.zeros(NUM_JOINTS)
        return JointCommand(np.array(q, dtype=np.float64), z, z.copy(), z.copy())

    def _damping(self, q: np.ndarray) -> JointCommand:
        kd = self.config.damping_kd_factor * np.asarray(self.spec.kd, dtype=np.float64)
        return JointCommand(np.array(q, dtype=np.float64), np.zeros(NUM_JOINTS), kd, np.zeros(NUM_JOINTS))

    def limits(self) -> dict[str, Any]:
        """The limits this controller enforces, JSON-ready (see :func:`virl_quad.deploy.limits.limits`)."""
        return limits_of(self.spec, self.config)

    def status(self) -> dict[str, Any]:
        """Counters and mode, JSON-ready: the body of a STATUS message."""
        with self._lock:
            return {
                "mode": self.mode.value, "fault": self.fault, "ticks": self.ticks,
                "accepted": self.accepted, "applied": self.applied, "active_ticks": self.active_ticks,
                "rejected": dict(self.rejected), "clamped": dict(self.clamped), "events": dict(self.events),
                "rejected_other": dict(self.rejected_other),
                "last_seq": self._last_seq,
                "estop_pending": bool(self._estop_pending),
            }
