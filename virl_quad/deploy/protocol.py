"""Wire protocol between the HAL and a policy server (spec: ``deploy/PROTOCOL.md``).

Every message is ``header (32 bytes) + payload``, little-endian, no padding::

    offset size type  field
    0      4    bytes magic        b"VIRL"
    4      2    u16   version      PROTOCOL_VERSION
    6      2    u16   type         MsgType
    8      8    u64   seq          sender's sequence number, strictly increasing
    16     8    u64   stamp_ns     sender's wall clock, ns since the Unix epoch
    24     4    u32   payload_len  bytes after the header
    28     4    u32   crc32        zlib.crc32(bytes 0..27 of the header + payload)

STATE and COMMAND payloads are fixed-size binary records; ANNOUNCE, STATUS,
ESTOP and ARM carry UTF-8 JSON objects. :func:`decode` raises
:class:`ProtocolError` with a short reason code and never anything else.
"""

from __future__ import annotations

import json
import struct
import time
import zlib
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Union

import numpy as np

from virl_quad.deploy.strict_json import loads_strict

MAGIC: bytes = b"VIRL"
PROTOCOL_VERSION: int = 1
NUM_JOINTS: int = 12
NUM_FEET: int = 4
MAX_JSON_PAYLOAD: int = 16384          # bytes; longer JSON payloads are bad_size

HEADER = struct.Struct("<4sHHQQII")    # magic, version, type, seq, stamp_ns, payload_len, crc32
HEADER_SIZE: int = HEADER.size         # 32
_HEADER_NO_CRC: int = HEADER_SIZE - 4  # 28 bytes covered by the CRC, then the payload

# STATE payload: u32 flags, 4 x u8 contacts, then float64: q[12] dq[12] tau[12] quat[4] gyro[3]
# accel[3] t_sensor base_pos[3] base_vel[3]
_STATE_HEAD = struct.Struct("<I4B")
_STATE_FLAGS = struct.Struct("<I")
_STATE_NF = 3 * NUM_JOINTS + 4 + 3 + 3 + 1 + 3 + 3   # 53 doubles
STATE_PAYLOAD_SIZE: int = _STATE_HEAD.size + 8 * _STATE_NF   # 432
STATE_Q, STATE_DQ = slice(0, 12), slice(12, 24)          # in the doubles: rad, rad/s
STATE_QUAT, STATE_GYRO = slice(36, 40), slice(40, 43)    # xyzw, rad/s
STATE_FLAG_BASE = 0x1                  # base_pos / base_vel are valid (simulation only)
STATE_FLAG_ACTIVE = 0x2                # the HAL is ACTIVE: a command answering this state will be applied
CONTACT_UNKNOWN = 255                  # wire value of a foot without a contact sensor
_CONTACT_OF_WIRE = np.ones(256)        # wire byte -> contact: 0 -> 0.0, 255 -> NaN, other -> 1.0
_CONTACT_OF_WIRE[0], _CONTACT_OF_WIRE[CONTACT_UNKNOWN] = 0.0, np.nan

# COMMAND payload: u64 ref_seq, then float64: q_target[12] kp[12] kd[12] tau_ff[12]
_CMD_HEAD = struct.Struct("<Q")
_CMD_NF = 4 * NUM_JOINTS
COMMAND_PAYLOAD_SIZE: int = _CMD_HEAD.size + 8 * _CMD_NF     # 392

#: Reason codes of :class:`ProtocolError`.
REASONS: tuple[str, ...] = (
    "bad_size", "bad_magic", "bad_version", "bad_type", "bad_crc", "bad_payload", "wrong_type",
)

TOPICS: tuple[str, ...] = ("state", "cmd", "estop", "status", "arm", "announce")
LIVELINESS_ROLES: tuple[str, ...] = ("hal", "policy")
_FORBIDDEN_ID_CHARS = set("/*$?#@ \t\r\n")


class MsgType(IntEnum):
    """Message type codes (header field ``type``)."""

    STATE = 1
    COMMAND = 2
    ANNOUNCE = 3
    STATUS = 4
    ESTOP = 5
    ARM = 6


_JSON_TYPES = frozenset({MsgType.ANNOUNCE, MsgType.STATUS, MsgType.ESTOP, MsgType.ARM})
_TYPE_OF_CODE = {int(m): m for m in MsgType}   # header code -> MsgType (a dict lookup: decode is per state)
_FIXED_SIZE = {MsgType.STATE: STATE_PAYLOAD_SIZE, MsgType.COMMAND: COMMAND_PAYLOAD_SIZE}


class ProtocolError(ValueError):
    """A received message was rejected; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason = reason
        super().__init__(f"{reason}: {detail}" if detail else reason)


@dataclass
class RobotState:
    """One measurement of the robot, canonical joint order FR, FL, RR, RL x (abd, hip, knee)."""

    q: np.ndarray                      # rad (12)
    dq: np.ndarray                     # rad/s (12)
    tau: np.ndarray                    # N·m (12), measured or estimated joint torque
    quat: np.ndarray                   # base orientation, unit quaternion (x, y, z, w)
    gyro: np.ndarray                   # rad/s (3), body frame
    accel: np.ndarray                  # m/s² (3), body frame, specific force (reads +9.81 z at rest)
    contacts: np.ndarray               # (4) feet FR, FL, RR, RL: 1.0 contact, 0.0 none, NaN unknown
    timestamp: float                   # s, the backend's clock (sim time in simulation)
    base_pos: np.ndarray | None = None  # m (3), world frame: simulation only, None on hardware
    base_vel: np.ndarray | None = None  # m/s (3), world frame: simulation only

    @classmethod
    def zeros(cls, q: np.ndarray | None = None, timestamp: float = 0.0) -> "RobotState":
        """A level, motionless state at joint positions ``q`` (rad; zeros if None)."""
        return cls(
            q=np.zeros(NUM_JOINTS) if q is None else np.array(q, dtype=np.float64),
            dq=np.zeros(NUM_JOINTS), tau=np.zeros(NUM_JOINTS),
            quat=np.array([0.0, 0.0, 0.0, 1.0]), gyro=np.zeros(3),
            accel=np.array([0.0, 0.0, 9.81]), contacts=np.ones(NUM_FEET), timestamp=timestamp,
        )

    @classmethod
    def standing(cls, spec, q: np.ndarray | None = None,
                 quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> "RobotState":
        """A motionless state at ``q`` (rad; the spec's default pose if None) with orientation ``quat`` (xyzw)."""
        st = cls.zeros(spec.default_pose if q is None else q)
        st.quat = np.array(quat, dtype=np.float64)
        return st


@dataclass
class JointCommand:
    """Per-joint PD command: tau = kp (q_target - q) + kd (0 - dq) + tau_ff, canonical order."""

    q_target: np.ndarray               # rad (12)
    kp: np.ndarray                     # N·m/rad (12)
    kd: np.ndarray                     # N·m·s/rad (12)
    tau_ff: np.ndarray                 # N·m (12)
    ref_seq: int = 0                   # seq of the STATE it was computed from (0: unknown)

    @classmethod
    def hold(cls, spec, q: np.ndarray | None = None) -> "JointCommand":
        """Hold ``q`` (rad; the default pose if None) with the spec's gains and no feed-forward."""
        return cls(np.array(spec.default_pose if q is None else q, dtype=np.float64),
                   np.array(spec.kp, dtype=np.float64), np.array(spec.kd, dtype=np.float64), np.zeros(NUM_JOINTS))


@dataclass
class Message:
    """A decoded message: header fields and the typed body."""

    type: MsgType
    seq: int
    stamp_ns: int
    body: Union[RobotState, JointCommand, dict[str, Any]] = field(repr=False)


# ----------------------------------------------------------------------------- key expressions

def check_robot_id(robot_id: str) -> str:
    """Return ``robot_id`` if it is one non-empty key chunk; raise ValueError otherwise."""
    if not isinstance(robot_id, str) or not robot_id or _FORBIDDEN_ID_CHARS & set(robot_id):
        raise ValueError(f"invalid robot_id {robot_id!r}: non-empty, no '/', '*', '$', '?', '#', '@' or spaces")
    return robot_id


def key(robot_id: str, topic: str) -> str:
    """Key expression ``virl/<robot_id>/<topic>`` for one of :data:`TOPICS`."""
    if topic not in TOPICS:
        raise ValueError(f"unknown topic {topic!r}; choose one of: {', '.join(TOPICS)}")
    return f"virl/{check_robot_id(robot_id)}/{topic}"


def liveliness_key(robot_id: str, role: str) -> str:
    """Liveliness token key ``virl/<robot_id>/alive/<role>`` for role 'hal' or 'policy'."""
    if role not in LIVELINESS_ROLES:
        raise ValueError(f"unknown role {role!r}; choose one of: {', '.join(LIVELINESS_ROLES)}")
    return f"virl/{check_robot_id(robot_id)}/alive/{role}"


# ----------------------------------------------------------------------------- framing

class SeqCounter:
    """Sequence numbers for one sender: start at the wall clock in ns, then +1 per message.

    Starting from the clock keeps a restarted sender's numbers above its previous run's.
    """

    def __init__(self, start: int | None = None) -> None:
        self._next = time.time_ns() if start is None else int(start)

    def __call__(self) -> int:
        """Return the next sequence number."""
        n = self._next
        self._next += 1
        return n


def _frame(mtype: MsgType, seq: int, payload: bytes, stamp_ns: int | None) -> bytes:
    stamp = time.time_ns() if stamp_ns is None else stamp_ns
    if not 0 <= seq < 2**64 or not 0 <= stamp < 2**64:
        raise ValueError(f"seq and stamp_ns must fit in u64, got {seq}, {stamp}")
    head = HEADER.pack(MAGIC, PROTOCOL_VERSION, int(mtype), seq, stamp, len(payload), 0)[:_HEADER_NO_CRC]
    crc = zlib.crc32(payload, zlib.crc32(head))
    return head + struct.pack("<I", crc) + payload


def _vec(a: Any, n: int, name: str) -> np.ndarray:
    v = np.asarray(a, dtype=np.float64).reshape(-1)
    if v.shape != (n,):
        raise ValueError(f"{name} must have {n} values, got {v.size}")
    return v


def encode_state(state: RobotState, seq: int, stamp_ns: int | None = None, active: bool = False) -> bytes:
    """Encode a STATE message. NaN/inf are carried as they are (the receiver judges them).
    ``active``: set the ACTIVE flag (the HAL will apply a command that answers this state)."""
    has_base = state.base_pos is not None and state.base_vel is not None
    contacts = _vec(state.contacts, NUM_FEET, "contacts")
    wire_contacts = [CONTACT_UNKNOWN if not np.isfinite(c) else int(c > 0.5) for c in contacts]
    nan3 = np.full(3, np.nan)
    floats = np.concatenate([
        _vec(state.q, NUM_JOINTS, "q"), _vec(state.dq, NUM_JOINTS, "dq"), _vec(state.tau, NUM_JOINTS, "tau"),
        _vec(state.quat, 4, "quat"), _vec(state.gyro, 3, "gyro"), _vec(state.accel, 3, "accel"),
        [float(state.timestamp)],
        _vec(state.base_pos, 3, "base_pos") if has_base else nan3,
        _vec(state.base_vel, 3, "base_vel") if has_base else nan3,
    ])
    flags = (STATE_FLAG_BASE if has_base else 0) | (STATE_FLAG_ACTIVE if active else 0)
    payload = _STATE_HEAD.pack(flags, *wire_contacts) + floats.astype("<f8").tobytes()
    return _frame(MsgType.STATE, seq, payload, stamp_ns)


def encode_command(cmd: JointCommand, seq: int, stamp_ns: int | None = None) -> bytes:
    """Encode a COMMAND message. NaN/inf are carried as they are (the HAL rejects them)."""
    floats = np.concatenate([
        _vec(cmd.q_target, NUM_JOINTS, "q_target"), _vec(cmd.kp, NUM_JOINTS, "kp"),
        _vec(cmd.kd, NUM_JOINTS, "kd"), _vec(cmd.tau_ff, NUM_JOINTS, "tau_ff"),
    ])
    ref = int(cmd.ref_seq)
    if not 0 <= ref < 2**64:
        raise ValueError(f"ref_seq must fit in u64, got {ref}")
    payload = _CMD_HEAD.pack(ref) + floats.astype("<f8").tobytes()
    return _frame(MsgType.COMMAND, seq, payload, stamp_ns)


class CommandEncoder:
    """COMMAND messages with fixed gains and feed-forward, for a sender in a control loop.

    Byte-identical to :func:`encode_command` (tested), with the constant part of the
    payload (kp, kd, tau_ff) packed once: a policy server calls it once per state."""

    def __init__(self, kp: Any, kd: Any, tau_ff: Any) -> None:
        tail = np.concatenate([_vec(kp, NUM_JOINTS, "kp"), _vec(kd, NUM_JOINTS, "kd"),
                               _vec(tau_ff, NUM_JOINTS, "tau_ff")]).astype("<f8").tobytes()
        self._tail = tail

    def __call__(self, q_target: np.ndarray, ref_seq: int, seq: int, stamp_ns: int | None = None) -> bytes:
        """Encode one COMMAND with ``q_target`` (rad, 12) answering the state ``ref_seq``."""
        q = _vec(q_target, NUM_JOINTS, "q_target")
        if not 0 <= ref_seq < 2**64:
            raise ValueError(f"ref_seq must fit in u64, got {ref_seq}")
        payload = _CMD_HEAD.pack(ref_seq) + q.astype("<f8").tobytes() + self._tail
        return _frame(MsgType.COMMAND, seq, payload, stamp_ns)


def encode_json(mtype: MsgType, body: dict[str, Any], seq: int, stamp_ns: int | None = None) -> bytes:
    """Encode an ANNOUNCE, STATUS, ESTOP or ARM message with a JSON object payload."""
    if mtype not in _JSON_TYPES:
        raise ValueError(f"{MsgType(mtype).name} is not a JSON message type")
    payload = json.dumps(body, allow_nan=False, separators=(",", ":")).encode()
    if len(payload) > MAX_JSON_PAYLOAD:
        raise ValueError(f"JSON payload of {len(payload)} bytes exceeds {MAX_JSON_PAYLOAD}")
    return _frame(mtype, seq, payload, stamp_ns)


def announce_body(spec: Any, robot_id: str, role: str = "hal", limits: dict[str, Any] | None = None) -> dict[str, Any]:
    """ANNOUNCE payload for a RobotSpec: robot name, id, joint order, control period (s),
    ``active_flag`` (this HAL sets ``STATE_FLAG_ACTIVE`` on the states whose answers it applies)
    and, when given, the ``limits`` its safety layer enforces (``SafetyController.limits``)."""
    body = {
        "robot": spec.name, "robot_id": check_robot_id(robot_id), "role": role,
        "protocol_version": PROTOCOL_VERSION, "joint_order": list(spec.joint_names),
        "control_dt": float(spec.control_dt), "active_flag": True,
    }
    if limits is not None:
        body["limits"] = limits
    return body


# ----------------------------------------------------------------------------- decoding

def _as_bytes(data: Any) -> bytes:
    """bytes from bytes-like objects and from zenoh.ZBytes (anything with to_bytes() but int)."""
    if isinstance(data, bytes):
        return data
    if isinstance(data, (bytearray, memoryview)):
        return bytes(data)
    if not isinstance(data, int) and callable(getattr(data, "to_bytes", None)):
        try:
            out = data.to_bytes()
            if isinstance(out, (bytes, bytearray)):
                return bytes(out)
        except Exception:   # a foreign object's to_bytes may raise anything
            pass
    raise ProtocolError("bad_payload", f"not a bytes-like object: {type(data).__name__}")


def decode(data: Any, expect: MsgType | None = None) -> Message:
    """Decode one message; raise ProtocolError(reason) if it is malformed or not ``expect``.

    ``data``: bytes, bytearray, memoryview or a zenoh.ZBytes (``sample.payload``).

    Checks, in the order of ``deploy/PROTOCOL.md`` section 7: the framing (bad_size: at least a
    header, payload_len == bytes received, the fixed size of a known binary type, the JSON
    limit), magic (bad_magic), version (bad_version), type known (bad_type), CRC (bad_crc),
    then ``expect`` (wrong_type) and the JSON payload (bad_payload).
    """
    buf, mt, seq, stamp_ns = _checked_frame(data, expect)
    payload = buf[HEADER_SIZE:]
    if mt == MsgType.STATE:
        body: Any = _decode_state(payload)
    elif mt == MsgType.COMMAND:
        body = _decode_command(payload)
    else:
        body = _decode_json(payload)
    return Message(mt, seq, stamp_ns, body)


def decode_state_values(data: Any) -> tuple[int, int, np.ndarray]:
    """A STATE's seq, its flags (``STATE_FLAG_*``) and its float64 values (read-only, indexed by
    ``STATE_Q``, ``STATE_DQ``, ``STATE_QUAT``, ``STATE_GYRO``), after every check of
    ``decode(data, MsgType.STATE)``.

    For a loop that runs once per state and needs only the measurements: no objects built."""
    buf, _, seq, _ = _checked_frame(data, MsgType.STATE)
    (flags,) = _STATE_FLAGS.unpack_from(buf, HEADER_SIZE)
    return seq, flags, np.frombuffer(buf, dtype="<f8", count=_STATE_NF, offset=HEADER_SIZE + _STATE_HEAD.size)


def _checked_frame(data: Any, expect: MsgType | None) -> tuple[bytes, MsgType, int, int]:
    """(bytes, type, seq, stamp_ns) of a message whose header, size and CRC are valid (see :func:`decode`)."""
    buf = _as_bytes(data)
    if len(buf) < HEADER_SIZE:
        raise ProtocolError("bad_size", f"{len(buf)} bytes, header needs {HEADER_SIZE}")
    magic, version, mtype, seq, stamp_ns, plen, crc = HEADER.unpack_from(buf)
    # framing first: every length check (they need only the length and type fields)
    if plen != len(buf) - HEADER_SIZE:
        raise ProtocolError("bad_size", f"payload_len {plen}, received {len(buf) - HEADER_SIZE}")
    mt = _TYPE_OF_CODE.get(mtype)
    want = _FIXED_SIZE.get(mt) if mt is not None else None
    if (want is not None and plen != want) or (mt in _JSON_TYPES and plen > MAX_JSON_PAYLOAD):
        raise ProtocolError("bad_size", f"{mt.name} payload of {plen} bytes")
    if magic != MAGIC:
        raise ProtocolError("bad_magic", repr(magic))
    if version != PROTOCOL_VERSION:
        raise ProtocolError("bad_version", f"{version} != {PROTOCOL_VERSION}")
    if mt is None:
        raise ProtocolError("bad_type", str(mtype))
    view = memoryview(buf)   # CRC over the buffer without copying it
    if zlib.crc32(view[HEADER_SIZE:], zlib.crc32(view[:_HEADER_NO_CRC])) != crc:
        raise ProtocolError("bad_crc")
    if expect is not None and mt != expect:
        raise ProtocolError("wrong_type", f"{mt.name}, expected {MsgType(expect).name}")
    return buf, mt, seq, stamp_ns


def _decode_state(p: bytes) -> RobotState:
    (flags,) = _STATE_FLAGS.unpack_from(p)
    f = np.frombuffer(p, dtype="<f8", count=_STATE_NF, offset=_STATE_HEAD.size).astype(np.float64)
    contacts = _CONTACT_OF_WIRE[np.frombuffer(p, dtype=np.uint8, count=NUM_FEET, offset=_STATE_FLAGS.size)]
    n = NUM_JOINTS
    has_base = bool(flags & STATE_FLAG_BASE)
    return RobotState(
        q=f[STATE_Q], dq=f[STATE_DQ], tau=f[2 * n:3 * n], quat=f[STATE_QUAT], gyro=f[STATE_GYRO], accel=f[43:46],
        contacts=contacts, timestamp=float(f[46]),
        base_pos=f[47:50] if has_base else None, base_vel=f[50:53] if has_base else None,
    )


def _decode_command(p: bytes) -> JointCommand:
    (ref_seq,) = _CMD_HEAD.unpack_from(p)
    f = np.frombuffer(p, dtype="<f8", count=_CMD_NF, offset=_CMD_HEAD.size).astype(np.float64)
    n = NUM_JOINTS
    return JointCommand(q_target=f[0:n], kp=f[n:2 * n], kd=f[2 * n:3 * n], tau_ff=f[3 * n:4 * n], ref_seq=ref_seq)


def _decode_json(p: bytes) -> dict[str, Any]:
    try:
        body = loads_strict(p.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise ProtocolError("bad_payload", f"JSON: {e}") from None
    if not isinstance(body, dict):
        raise ProtocolError("bad_payload", "JSON payload is not an object")
    return body
