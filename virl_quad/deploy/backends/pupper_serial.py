"""Stanford Pupper v2 hardware backend: msgpack dictionaries to and from the Teensy motor
board over a 500000-baud serial link (pyserial).

ASSUMED board protocol (this project's design; check it against the firmware you flash,
the stock firmware's framing and keys may differ):

Framing, both directions::

    b"\\xa5\\x5a" | u16 LE n | n bytes: one msgpack map | u32 LE zlib.crc32(those n bytes)

with 1 <= n <= MAX_BODY. A receiver scans for the sync bytes and drops frames whose
length or CRC is wrong, so it resynchronises after line noise.

Host -> board (string keys, float values, board motor order)::

    {"t": "cfg", "max_cur": 7.0}                  once at open: current limit, A
    {"t": "cmd", "pos": [12] rad, "kp": [12] A/rad, "kd": [12] A·s/rad, "ff": [12] A,
     "max_cur": 7.0}                              every control period

Board -> host::

    {"t": "state", "ts": int µs (board clock), "pos": [12] rad, "vel": [12] rad/s,
     "cur": [12] A, "quat": [w, x, y, z], "gyro": [3] rad/s, "acc": [3] m/s²}

Angles are of the output shafts. The board computes, per motor,
``current = kp (pos - measured) - kd velocity + ff`` and saturates it at ``max_cur``.

Units: currents map to torques through TORQUE_CONSTANT (N·m/A at the output shaft,
assumed for a DJI M2006 P36: 0.18), so kp [A/rad] = kp [N·m/rad] / TORQUE_CONSTANT; the
default 7 A cap is then 1.26 N·m, below the spec's 1.7 N·m. Joint mapping: canonical
joint j is board motor ``order[j]`` with ``q = sign * motor_pos + offset`` (MotorMap).
The Pupper has no foot sensors: contacts are reported unknown (NaN).
"""

from __future__ import annotations

import struct
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np
import serial

from virl_quad.deploy.backends.base import Backend, BackendError, BackendTimeout, check_command
from virl_quad.deploy.protocol import NUM_FEET, NUM_JOINTS, JointCommand, RobotState

BAUDRATE: int = 500_000
SYNC: bytes = b"\xa5\x5a"
MAX_BODY: int = 1024                  # bytes of msgpack per frame
TORQUE_CONSTANT: float = 0.18         # N·m/A at the output shaft (assumed M2006 P36)
DEFAULT_MAX_CURRENT: float = 7.0      # A (board default)
_LEN = struct.Struct("<H")
_CRC = struct.Struct("<I")

#: Assumed motor directions: left legs' hip and knee motors are mirrored. Calibrate!
DEFAULT_SIGN: tuple[float, ...] = (1, 1, 1, 1, -1, -1, 1, 1, 1, 1, -1, -1)


def encode_frame(obj: dict[str, Any]) -> bytes:
    """Frame one msgpack map: sync, u16 length, body, CRC32 of the body."""
    body = msgpack.packb(obj, use_bin_type=True)
    if not 1 <= len(body) <= MAX_BODY:
        raise ValueError(f"frame body of {len(body)} bytes exceeds {MAX_BODY}")
    return SYNC + _LEN.pack(len(body)) + body + _CRC.pack(zlib.crc32(body))


class FrameDecoder:
    """Incremental decoder of the framing above; bad frames are dropped and counted."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.errors: Counter[str] = Counter()   # bad_length, bad_crc, bad_msgpack, not_a_map

    def feed(self, data: bytes) -> list[dict[str, Any]]:
        """Add received bytes; return the complete, valid maps found so far, in order."""
        self._buf += data
        out: list[dict[str, Any]] = []
        while True:
            start = self._buf.find(SYNC)
            if start < 0:
                del self._buf[:max(0, len(self._buf) - 1)]   # keep a possible first sync byte
                return out
            del self._buf[:start]
            if len(self._buf) < 4:
                return out
            (n,) = _LEN.unpack_from(self._buf, 2)
            if not 1 <= n <= MAX_BODY:
                self.errors["bad_length"] += 1
                del self._buf[:1]
                continue
            if len(self._buf) < 4 + n + 4:
                return out
            body = bytes(self._buf[4:4 + n])
            (crc,) = _CRC.unpack_from(self._buf, 4 + n)
            if zlib.crc32(body) != crc:
                self.errors["bad_crc"] += 1
                del self._buf[:1]
                continue
            del self._buf[:4 + n + 4]
            try:
                obj = msgpack.unpackb(body, raw=False, strict_map_key=False)
            except Exception:   # msgpack raises several unrelated types on garbage
                self.errors["bad_msgpack"] += 1
                continue
            if isinstance(obj, dict):
                out.append(obj)
            else:
                self.errors["not_a_map"] += 1


@dataclass(frozen=True)
class MotorMap:
    """Canonical joint j <-> board motor order[j]; q = sign * motor_pos + offset (rad)."""

    order: tuple[int, ...] = tuple(range(NUM_JOINTS))
    sign: tuple[float, ...] = DEFAULT_SIGN
    offset: tuple[float, ...] = (0.0,) * NUM_JOINTS          # rad

    def __post_init__(self) -> None:
        if sorted(self.order) != list(range(NUM_JOINTS)):
            raise ValueError("MotorMap.order must be a permutation of 0..11")
        if len(self.sign) != NUM_JOINTS or any(s not in (1, -1) for s in self.sign):
            raise ValueError("MotorMap.sign must be 12 values of +1 or -1")
        if len(self.offset) != NUM_JOINTS:
            raise ValueError("MotorMap.offset must have 12 values")

    def to_board(self, joint_values: np.ndarray, offset: bool = False, signed: bool = True) -> list[float]:
        """Canonical per-joint values -> board-ordered motor values. ``offset`` for angles,
        ``signed`` for angles, velocities and torques (not for gains)."""
        v = (np.asarray(joint_values, dtype=np.float64) - (np.asarray(self.offset) if offset else 0.0))
        if signed:
            v = v * np.asarray(self.sign)
        out = np.empty(NUM_JOINTS)
        out[list(self.order)] = v
        return [float(x) for x in out]

    def from_board(self, motor_values: Any, offset: bool = False) -> np.ndarray:
        """Board-ordered motor values -> canonical per-joint values."""
        m = np.asarray(motor_values, dtype=np.float64)
        if m.shape != (NUM_JOINTS,):
            raise ValueError(f"expected {NUM_JOINTS} motor values, got shape {m.shape}")
        v = m[list(self.order)] * np.asarray(self.sign)
        return v + (np.asarray(self.offset) if offset else 0.0)


@dataclass
class _Latest:
    state: RobotState | None = None
    received: int = 0                 # state frames parsed so far
    bad: Counter = field(default_factory=Counter)


class PupperSerialBackend(Backend):
    """The real Pupper v2 through its Teensy board (see the module docstring)."""

    name = "pupper_serial"

    def __init__(self, port: str, spec: Any = "pupper", motor_map: MotorMap = MotorMap(),
                 max_current: float = DEFAULT_MAX_CURRENT, torque_constant: float = TORQUE_CONSTANT,
                 state_timeout: float = 0.1, baudrate: int = BAUDRATE) -> None:
        super().__init__(spec)
        if max_current <= 0 or torque_constant <= 0 or state_timeout <= 0:
            raise ValueError("max_current, torque_constant and state_timeout must be positive")
        self.map = motor_map
        self.max_current = float(max_current)         # A
        self.kt = float(torque_constant)              # N·m/A
        self.state_timeout = float(state_timeout)     # s
        self.decoder = FrameDecoder()
        self._latest = _Latest()
        try:
            self._ser = serial.serial_for_url(port, baudrate=baudrate, timeout=0, write_timeout=0.5)
        except (serial.SerialException, ValueError, OSError) as e:
            raise BackendError(f"cannot open Pupper board on {port!r}: {e}") from e
        self._send({"t": "cfg", "max_cur": self.max_current})

    @property
    def bad_frames(self) -> dict[str, int]:
        """Dropped frames by reason (framing errors and malformed state maps)."""
        return dict(self.decoder.errors + self._latest.bad)

    def _send(self, obj: dict[str, Any]) -> None:
        try:
            self._ser.write(encode_frame(obj))
        except (serial.SerialException, OSError) as e:
            raise BackendError(f"serial write failed: {e}") from e

    def _parse_state(self, m: dict[str, Any]) -> RobotState:
        mp = self.map
        w, x, y, z = (float(v) for v in m["quat"])
        gyro = np.asarray(m["gyro"], dtype=np.float64)
        acc = np.asarray(m["acc"], dtype=np.float64)
        if gyro.shape != (3,) or acc.shape != (3,):
            raise ValueError("gyro and acc need 3 values")
        return RobotState(
            q=mp.from_board(m["pos"], offset=True), dq=mp.from_board(m["vel"]),
            tau=mp.from_board(m["cur"]) * self.kt, quat=np.array([x, y, z, w]), gyro=gyro, accel=acc,
            contacts=np.full(NUM_FEET, np.nan), timestamp=int(m["ts"]) * 1e-6,
        )

    def read_state(self) -> RobotState:
        """Newest state frame from the board; waits up to ``state_timeout`` s for one that
        arrived since the last call, else raises BackendTimeout."""
        if self.closed:
            raise BackendError("Pupper backend is closed")
        deadline = time.monotonic() + self.state_timeout
        before = self._latest.received
        while True:
            try:
                waiting = self._ser.in_waiting
                data = self._ser.read(waiting) if waiting else b""
            except (serial.SerialException, OSError) as e:
                raise BackendError(f"serial read failed: {e}") from e
            for m in self.decoder.feed(data):
                if m.get("t") != "state":
                    continue
                try:
                    self._latest.state = self._parse_state(m)
                    self._latest.received += 1
                except (KeyError, TypeError, ValueError, OverflowError):
                    self._latest.bad["bad_state_msg"] += 1
            if self._latest.received > before and not data:
                return self._latest.state  # type: ignore[return-value]
            if time.monotonic() > deadline:
                if self._latest.received > before:
                    return self._latest.state  # type: ignore[return-value]
                raise BackendTimeout(f"no state from the Pupper board within {self.state_timeout} s")
            if not data:
                time.sleep(0.0005)

    def command_message(self, cmd: JointCommand) -> dict[str, Any]:
        """The board message for ``cmd`` (N·m gains -> A; joint -> motor order and sign)."""
        q, kp, kd, ff = check_command(cmd)
        ff_a = np.clip(ff / self.kt, -self.max_current, self.max_current)
        return {"t": "cmd", "pos": self.map.to_board(q, offset=True),
                "kp": self.map.to_board(kp / self.kt, signed=False),
                "kd": self.map.to_board(kd / self.kt, signed=False),
                "ff": self.map.to_board(ff_a), "max_cur": self.max_current}

    def write_command(self, cmd: JointCommand) -> None:
        """Send one command frame; ValueError for NaN/inf or wrong shapes (nothing is sent)."""
        if self.closed:
            raise BackendError("Pupper backend is closed")
        self._send(self.command_message(cmd))

    def close(self) -> None:
        """Leave the motors damped (kp 0, spec kd, no feed-forward), then close the port."""
        if self.closed:
            return
        self.closed = True
        try:
            damp = JointCommand(np.array(self.spec.default_pose, dtype=np.float64), np.zeros(NUM_JOINTS),
                                np.array(self.spec.kd, dtype=np.float64), np.zeros(NUM_JOINTS))
            self._send(self.command_message(damp))
            self._ser.flush()
        except BackendError:
            pass                                    # the port is gone: nothing more to do
        finally:
            self._ser.close()
