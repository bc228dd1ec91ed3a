"""Wire protocol: round trips, the documented byte layout, every ProtocolError reason."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, ProtocolError, RobotState, decode


def _state(with_base: bool) -> RobotState:
    rng = np.random.default_rng(1)
    st = RobotState(q=rng.normal(size=12), dq=rng.normal(size=12), tau=rng.normal(size=12),
                    quat=np.array([0.1, -0.2, 0.3, 0.9]), gyro=rng.normal(size=3), accel=rng.normal(size=3),
                    contacts=np.array([1.0, 0.0, np.nan, 1.0]), timestamp=12.345)
    if with_base:
        st.base_pos, st.base_vel = np.array([0.1, 0.2, 0.17]), np.array([0.5, 0.0, -0.1])
    return st


def _cmd() -> JointCommand:
    rng = np.random.default_rng(2)
    return JointCommand(rng.normal(size=12), rng.uniform(0, 5, 12), rng.uniform(0, 1, 12), rng.normal(size=12), ref_seq=41)


@pytest.mark.parametrize("with_base", [False, True])
def test_state_round_trip(with_base):
    st = _state(with_base)
    data = P.encode_state(st, seq=7, stamp_ns=123456789)
    assert len(data) == P.HEADER_SIZE + P.STATE_PAYLOAD_SIZE == 464
    m = decode(data, expect=MsgType.STATE)
    assert (m.type, m.seq, m.stamp_ns) == (MsgType.STATE, 7, 123456789)
    for f in ("q", "dq", "tau", "quat", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(m.body, f), getattr(st, f))
    np.testing.assert_array_equal(m.body.contacts, st.contacts)      # NaN = unknown survives
    assert m.body.timestamp == st.timestamp
    if with_base:
        np.testing.assert_array_equal(m.body.base_pos, st.base_pos)
        np.testing.assert_array_equal(m.body.base_vel, st.base_vel)
    else:
        assert m.body.base_pos is None and m.body.base_vel is None


def test_command_round_trip():
    c = _cmd()
    m = decode(P.encode_command(c, seq=2**64 - 1), expect=MsgType.COMMAND)
    assert m.seq == 2**64 - 1 and m.body.ref_seq == 41
    for f in ("q_target", "kp", "kd", "tau_ff"):
        np.testing.assert_array_equal(getattr(m.body, f), getattr(c, f))


@pytest.mark.parametrize("mtype", [MsgType.ANNOUNCE, MsgType.STATUS, MsgType.ESTOP, MsgType.ARM])
def test_json_round_trip(mtype):
    body = {"robot_id": "pupper-01", "n": [1, 2.5], "nested": {"a": "b"}}
    m = decode(P.encode_json(mtype, body, seq=3))
    assert m.type == mtype and m.body == body


def test_announce_body():
    from virl_quad import robots

    spec = robots.get("pupper")
    body = P.announce_body(spec, "pupper-01")
    m = decode(P.encode_json(MsgType.ANNOUNCE, body, seq=1))
    assert m.body["joint_order"] == list(spec.joint_names) and m.body["control_dt"] == pytest.approx(0.02)
    assert m.body["robot"] == "pupper" and m.body["protocol_version"] == P.PROTOCOL_VERSION
    assert m.body["active_flag"] is True


def test_documented_command_layout_by_hand():
    """Build a COMMAND with struct from PROTOCOL.md's table alone; the decoder must agree."""
    q, kp, kd, ff = (np.arange(12) * k for k in (0.01, 1.0, 0.1, -0.05))
    payload = struct.pack("<Q", 9) + struct.pack("<48d", *q, *kp, *kd, *ff)
    head = struct.pack("<4sHHQQI", b"VIRL", 1, 2, 1000, 5, len(payload))
    data = head + struct.pack("<I", zlib.crc32(head + payload)) + payload
    m = decode(data)
    assert m.type == MsgType.COMMAND and m.seq == 1000 and m.stamp_ns == 5 and m.body.ref_seq == 9
    np.testing.assert_array_equal(m.body.kd, kd)
    assert P.encode_command(m.body, seq=1000, stamp_ns=5) == data


def test_documented_state_offsets():
    st = _state(True)
    data = P.encode_state(st, seq=1, stamp_ns=0)
    p = data[32:]
    assert struct.unpack_from("<I4B", p, 0) == (P.STATE_FLAG_BASE, 1, 0, 255, 1)
    assert struct.unpack_from("<12d", p, 8) == tuple(st.q)
    assert struct.unpack_from("<4d", p, 296) == tuple(st.quat)
    assert struct.unpack_from("<d", p, 376) == (st.timestamp,)
    assert struct.unpack_from("<3d", p, 408) == tuple(st.base_vel)
    assert struct.unpack_from("<I", data, 24) == (432,)


def test_crc_is_zlib_crc32():
    assert zlib.crc32(b"123456789") == 0xCBF43926     # the check value quoted in PROTOCOL.md


def test_every_single_bit_flip_is_detected():
    data = P.encode_command(_cmd(), seq=5)
    for bit in range(len(data) * 8):
        bad = bytearray(data)
        bad[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(ProtocolError):
            decode(bytes(bad))
    # a flip in the payload or in seq/stamp is caught by the CRC itself
    for byte in (8, 16, 40, len(data) - 1):
        bad = bytearray(data)
        bad[byte] ^= 0x10
        with pytest.raises(ProtocolError) as e:
            decode(bytes(bad))
        assert e.value.reason == "bad_crc"


def _reframe(data: bytes, **fields) -> bytes:
    """Rewrite header fields and recompute the CRC (so only the named field is wrong)."""
    magic, version, mtype, seq, stamp, plen, _ = P.HEADER.unpack_from(data)
    vals = dict(magic=magic, version=version, mtype=mtype, seq=seq, stamp=stamp, plen=plen)
    vals.update(fields)
    payload = fields.get("payload", data[32:])
    head = struct.pack("<4sHHQQI", vals["magic"], vals["version"], vals["mtype"], vals["seq"], vals["stamp"], vals["plen"])
    return head + struct.pack("<I", zlib.crc32(head + payload)) + payload


def _json_frame(mtype: MsgType, payload: bytes) -> bytes:
    return _reframe(P.encode_json(mtype, {}, seq=1), plen=len(payload), payload=payload)


@pytest.mark.parametrize("make, reason", [
    (lambda d: b"", "bad_size"),
    (lambda d: d[:31], "bad_size"),
    (lambda d: d[:-1], "bad_size"),                                   # truncated payload
    (lambda d: d + b"\0", "bad_size"),                                # trailing byte
    (lambda d: _reframe(d, plen=391, payload=d[32:-1]), "bad_size"),  # consistent but wrong size
    (lambda d: _reframe(d, magic=b"VIRX"), "bad_magic"),
    (lambda d: _reframe(d, version=2), "bad_version"),
    (lambda d: _reframe(d, version=0), "bad_version"),
    (lambda d: _reframe(d, mtype=99), "bad_type"),
    (lambda d: _reframe(d, mtype=0), "bad_type"),
    (lambda d: d[:28] + struct.pack("<I", (struct.unpack_from("<I", d, 28)[0] ^ 1)) + d[32:], "bad_crc"),
    (lambda d: P.encode_state(RobotState.zeros(), seq=1), "wrong_type"),
    (lambda d: _json_frame(MsgType.STATUS, b"{bad}"), "bad_payload"),
    (lambda d: _json_frame(MsgType.STATUS, b"[1,2,3]"), "bad_payload"),
    (lambda d: _json_frame(MsgType.ARM, b'{"x":NaN}'), "bad_payload"),
    (lambda d: _json_frame(MsgType.ESTOP, b"\xff\xfe"), "bad_payload"),
    (lambda d: _json_frame(MsgType.ESTOP, b"[" * 100000), "bad_size"),
    (lambda d: _json_frame(MsgType.ARM, b'{"robot_id":"a","robot_id":"b"}'), "bad_payload"),   # duplicated key
    (lambda d: _json_frame(MsgType.ARM, b'{"robot_id":"a","t":1e400}'), "bad_payload"),       # parses to inf
    (lambda d: _json_frame(MsgType.ARM, b'{"robot_id":"a","t":{"u":1,"u":2}}'), "bad_payload"),
])
def test_each_protocol_error_reason(make, reason):
    data = make(P.encode_command(_cmd(), seq=5))
    with pytest.raises(ProtocolError) as e:
        decode(data, expect=MsgType.COMMAND if reason == "wrong_type" else None)
    assert e.value.reason == reason and reason in P.REASONS


def test_framing_is_checked_before_magic_version_and_type():
    """PROTOCOL.md section 7: every bad_size condition comes first. A COMMAND whose length field
    lies (500 for 392 bytes) with a correct CRC is bad_size, whatever its magic, version or type."""
    good = P.encode_command(_cmd(), seq=5)
    for fields in (dict(magic=b"XIRL"), dict(version=7), dict(mtype=99), dict(magic=b"XIRL", version=0, mtype=0), {}):
        data = _reframe(good, plen=500, **fields)
        with pytest.raises(ProtocolError) as e:
            decode(data)
        assert e.value.reason == "bad_size", fields
    # a known binary type with a consistent length field but the wrong size: bad_size before bad_magic
    short = _reframe(good, magic=b"XIRL", plen=391, payload=good[32:-1])
    with pytest.raises(ProtocolError) as e:
        decode(short)
    assert e.value.reason == "bad_size"


def test_decode_rejects_non_bytes_and_oversized_json():
    for junk in (None, 10**12, "VIRL", 3.5, [1, 2]):
        with pytest.raises(ProtocolError) as e:
            decode(junk)  # type: ignore[arg-type]
        assert e.value.reason == "bad_payload"
    big = json.dumps({"x": "a" * (P.MAX_JSON_PAYLOAD + 1)}).encode()
    data = _reframe(P.encode_json(MsgType.STATUS, {}, seq=1), plen=len(big), payload=big)
    with pytest.raises(ProtocolError) as e:
        decode(data)
    assert e.value.reason == "bad_size"


def test_encoders_refuse_wrong_shapes_and_non_json_values():
    c = _cmd()
    c.kp = np.ones(11)
    with pytest.raises(ValueError):
        P.encode_command(c, seq=1)
    with pytest.raises(ValueError):
        P.encode_json(MsgType.STATUS, {"x": float("nan")}, seq=1)
    with pytest.raises(ValueError):
        P.encode_json(MsgType.COMMAND, {}, seq=1)
    with pytest.raises(ValueError):
        P.encode_command(_cmd(), seq=-1)


def test_key_expressions():
    assert P.key("pupper-01", "cmd") == "virl/pupper-01/cmd"
    assert P.liveliness_key("pupper-01", "hal") == "virl/pupper-01/alive/hal"
    for bad in ("", "a/b", "a*", "$x", "a b", None):
        with pytest.raises(ValueError):
            P.key(bad, "cmd")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        P.key("p", "cmds")
    with pytest.raises(ValueError):
        P.liveliness_key("p", "robot")


def test_seq_counter_starts_from_clock_and_increases():
    a = P.SeqCounter()
    first = a()
    assert a() == first + 1 and first > 1_600_000_000 * 10**9
    assert P.SeqCounter(start=5)() == 5


def test_command_encoder_matches_encode_command() -> None:
    rng = np.random.default_rng(4)
    kp, kd, ff = rng.uniform(0, 5, 12), rng.uniform(0, 1, 12), rng.normal(size=12)
    enc = P.CommandEncoder(kp, kd, ff)
    for seq in (1, 2**40, 2**64 - 1):
        q = rng.normal(size=12)
        want = P.encode_command(P.JointCommand(q, kp, kd, ff, ref_seq=seq // 2), seq, stamp_ns=123)
        assert enc(q, seq // 2, seq, stamp_ns=123) == want
    with pytest.raises(ValueError):
        enc(np.zeros(11), 1, 1)
    with pytest.raises(ValueError):
        enc(np.zeros(12), -1, 1)


@pytest.mark.parametrize("with_base", [False, True])
def test_state_values_agree_with_decode(with_base):
    st = _state(with_base)
    st.dq[3] = np.inf                                    # carried as it is: the receiver judges it
    data = P.encode_state(st, seq=9, active=with_base)
    seq, flags, f = P.decode_state_values(data)
    body = decode(data, expect=MsgType.STATE).body
    assert seq == 9 and bool(flags & P.STATE_FLAG_ACTIVE) == with_base
    assert bool(flags & P.STATE_FLAG_BASE) == with_base == (body.base_pos is not None)
    for name, sl in (("q", P.STATE_Q), ("dq", P.STATE_DQ), ("quat", P.STATE_QUAT), ("gyro", P.STATE_GYRO)):
        np.testing.assert_array_equal(f[sl], getattr(body, name))


def test_state_values_reject_what_decode_rejects():
    data = P.encode_state(_state(False), seq=3)
    bad = [b"", data[:31], data[:-1], data + b"\0", _reframe(data, magic=b"VIRX"), _reframe(data, version=2),
           _reframe(data, mtype=99), data[:40] + bytes([data[40] ^ 4]) + data[41:], P.encode_command(_cmd(), seq=1)]
    for b in bad:
        with pytest.raises(ProtocolError) as want:
            decode(b, expect=MsgType.STATE)
        with pytest.raises(ProtocolError) as got:
            P.decode_state_values(b)
        assert got.value.reason == want.value.reason
