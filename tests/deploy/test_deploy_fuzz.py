"""Fuzz: 10,000 malformed and valid commands through decode + safety, seeded.

No exception may escape, every applied command must pass is_safe_command (and the
per-period step limit while ACTIVE), and every message must be either accepted or
counted under exactly one rejection reason -- the expected one where it is known.
"""

from __future__ import annotations

import struct
import time
import zlib
from collections import Counter

import numpy as np
import pytest

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, ProtocolError, RobotState
from virl_quad.deploy.safety import Mode, SafetyConfig, SafetyController, is_safe_command


N_MESSAGES = 10_000
SEED = 20240606

# category -> expected rejection reason (None: accepted; "*": any protocol reason)
CATEGORIES: dict[str, str | None] = {
    "valid": None, "huge": None, "non_finite": "non_finite", "negative_gain": "negative_gain",
    "replay": "stale_seq", "old_seq": "stale_seq", "random_bytes": "*", "truncated": "bad_size",
    "extended": "bad_size", "bad_len_field": "bad_size", "bad_version": "bad_version",
    "bad_magic": "bad_magic", "bad_type": "bad_type", "payload_bit_flip": "bad_crc",
    "any_bit_flip": "*", "wrong_type": "wrong_type",
}
WEIGHTS = np.array([30, 5, 8, 4, 5, 4, 8, 4, 3, 3, 3, 3, 3, 6, 6, 5], dtype=float)


def _reframe(data: bytes, version: int | None = None, mtype: int | None = None,
             magic: bytes | None = None, plen: int | None = None) -> bytes:
    m, v, t, seq, stamp, n, _ = P.HEADER.unpack_from(data)
    head = struct.pack("<4sHHQQI", magic or m, v if version is None else version,
                       t if mtype is None else mtype, seq, stamp, n if plen is None else plen)
    payload = data[32:]
    return head + struct.pack("<I", zlib.crc32(head + payload)) + payload


class Fuzzer:
    """Generates one message of a given category; tracks what the controller should know."""

    def __init__(self, spec, rng: np.random.Generator) -> None:
        self.spec, self.rng = spec, rng
        self.seq = 10**6
        self.accepted_since_arm: list[bytes] = []   # candidates for replay
        self.baseline: int | None = None            # newest accepted seq since the last arm

    def _random_command(self, huge: bool = False) -> JointCommand:
        s, r = self.spec, self.rng
        span = s.joint_upper - s.joint_lower
        q = s.joint_lower - 0.2 * span + r.random(12) * 1.4 * span
        kp, kd = r.random(12) * 3 * s.kp, r.random(12) * 3 * s.kd
        tau = r.normal(0, 1, 12) * s.torque_limit
        if huge:
            for a in (q, kp, kd, tau):
                idx = r.random(12) < 0.5
                a[idx] = r.choice([1e308, 1e300, 1e30, 1e6]) * (1 if a is kp or a is kd else r.choice([-1, 1]))
        return JointCommand(q, kp, kd, tau, ref_seq=int(r.integers(0, 2**63)))

    def next_seq(self) -> int:
        self.seq += int(self.rng.integers(1, 4))
        return self.seq

    def make(self, cat: str) -> tuple[bytes, str | None]:
        r = self.rng
        if cat in ("replay", "old_seq") and self.baseline is None:
            cat = "valid"        # nothing accepted since the last arm: no baseline to be older than
        if cat == "replay" and not self.accepted_since_arm:
            cat = "valid"
        expect = CATEGORIES[cat]
        if cat in ("valid", "huge"):
            data = P.encode_command(self._random_command(cat == "huge"), self.next_seq())
        elif cat == "non_finite":
            c = self._random_command()
            getattr(c, r.choice(["q_target", "kp", "kd", "tau_ff"]))[r.integers(12)] = r.choice([np.nan, np.inf, -np.inf])
            data = P.encode_command(c, self.next_seq())
        elif cat == "negative_gain":
            c = self._random_command()
            getattr(c, r.choice(["kp", "kd"]))[r.integers(12)] = -r.random() - 1e-6
            data = P.encode_command(c, self.next_seq())
        elif cat == "replay":
            data = self.accepted_since_arm[r.integers(len(self.accepted_since_arm))]
        elif cat == "old_seq":
            data = P.encode_command(self._random_command(), self.baseline - int(r.integers(0, 1000)))
        elif cat == "random_bytes":
            n = int(r.choice([r.integers(0, 40), r.integers(0, 600), P.HEADER_SIZE + P.COMMAND_PAYLOAD_SIZE]))
            data = r.bytes(n)
            if r.random() < 0.3 and n >= 4:
                data = b"VIRL" + data[4:]
        else:
            base = P.encode_command(self._random_command(), self.next_seq())
            if cat == "truncated":
                data = base[: int(r.integers(0, len(base)))]
            elif cat == "extended":
                data = base + r.bytes(int(r.integers(1, 64)))
            elif cat == "bad_len_field":
                data = _reframe(base, plen=int(r.choice([0, 391, 393, 2**32 - 1])))
            elif cat == "bad_version":
                data = _reframe(base, version=int(r.choice([0, 2, 3, 65535])))
            elif cat == "bad_magic":
                data = _reframe(base, magic=bytes(r.integers(0, 256, 4, dtype=np.uint8)) if r.random() < 0.5 else b"VIRM")
                if data[:4] == P.MAGIC:
                    data, expect = base, None
            elif cat == "bad_type":
                data = _reframe(base, mtype=int(r.choice([0, 7, 8, 255, 65535])))
            elif cat == "payload_bit_flip":
                b = bytearray(base)
                bit = int(r.integers(32 * 8, len(b) * 8))
                b[bit // 8] ^= 1 << (bit % 8)
                data = bytes(b)
            elif cat == "any_bit_flip":
                b = bytearray(base)
                for _ in range(int(r.integers(1, 4))):
                    bit = int(r.integers(0, len(b) * 8))
                    b[bit // 8] ^= 1 << (bit % 8)
                data = bytes(b)
            else:  # wrong_type
                kind = r.integers(3)
                if kind == 0:
                    data = P.encode_state(RobotState.standing(self.spec), self.next_seq())
                else:
                    data = P.encode_json(MsgType.STATUS if kind == 1 else MsgType.ARM, {"x": 1}, self.next_seq())
        return data, expect


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_fuzz_commands_through_decode_and_safety(robot):
    from virl_quad import robots

    spec = robots.get(robot)
    cfg = SafetyConfig(ramp_time=0.3)        # short ramps: more of the run is spent ACTIVE
    rng = np.random.default_rng(SEED)
    ctl, fz = SafetyController(spec, cfg), Fuzzer(spec, rng)
    cats = list(CATEGORIES)
    probs = WEIGHTS / WEIGHTS.sum()
    offered, by_category, reasons_seen = 0, Counter(), Counter()
    outputs, step_checks, modes = 0, 0, Counter()
    prev_out, prev_mode = None, ctl.mode
    t0 = time.perf_counter()

    def tick() -> None:
        nonlocal prev_out, prev_mode, outputs, step_checks
        st = RobotState.standing(spec, prev_out.q_target if prev_out is not None else None)
        st.q = st.q + rng.normal(0, 0.01, 12)
        u = rng.random()
        if u < 0.002:
            st.quat = np.array([0.5, 0.0, 0.0, 0.866])          # ~60 deg roll
        elif u < 0.003:
            st.q[int(rng.integers(12))] = np.nan
        elif u < 0.004:
            ctl.estop("fuzz")
        out = ctl.tick(None if rng.random() < 0.001 else st)
        assert is_safe_command(out, spec, cfg), out
        if prev_mode == Mode.ACTIVE and ctl.mode == Mode.ACTIVE:
            assert is_safe_command(out, spec, cfg, prev=prev_out)
            step_checks += 1
        if ctl.mode == Mode.DAMPING:
            assert not out.kp.any() and not out.tau_ff.any()
        outputs += 1
        modes[ctl.mode.value] += 1
        prev_out, prev_mode = out, ctl.mode
        if ctl.mode in (Mode.IDLE, Mode.DAMPING) and rng.random() < 0.2:
            ctl.arm()                                     # operator re-arms
            fz.accepted_since_arm.clear()
            fz.baseline = None
            tick()

    tick()
    for _ in range(N_MESSAGES):
        cat = cats[int(rng.choice(len(cats), p=probs))]
        data, expect = fz.make(cat)
        before = Counter(ctl.rejected)
        ok = ctl.receive(data)                            # must never raise
        offered += 1
        by_category[cat] += 1
        diff = Counter(ctl.rejected)
        diff.subtract(before)
        diff = +diff
        if ok:
            assert expect is None, (cat, data[:40])
            assert not diff
            seq = P.HEADER.unpack_from(data)[3]
            fz.baseline = seq
            fz.accepted_since_arm.append(data)
        else:
            assert sum(diff.values()) == 1, diff        # counted exactly once
            (reason,) = diff
            reasons_seen[reason] += 1
            if expect == "*":
                assert reason in P.REASONS, (cat, reason)
            else:
                assert reason == expect, (cat, reason, expect)
        if rng.random() < 0.4:
            tick()
    elapsed = time.perf_counter() - t0

    st = ctl.status()
    print(f"\n[fuzz {robot}] messages={offered} accepted={st['accepted']} rejected={dict(st['rejected'])} "
          f"clamped={dict(st['clamped'])} events={dict(st['events'])} ticks={outputs} modes={dict(modes)} "
          f"step_checks={step_checks} time={elapsed:.2f}s")
    assert offered == N_MESSAGES
    assert st["accepted"] + sum(st["rejected"].values()) == N_MESSAGES
    assert set(by_category) == set(CATEGORIES)                  # every category exercised
    assert modes["ACTIVE"] > 0.3 * outputs and step_checks > 1000
    assert elapsed < 30, elapsed


def test_fuzz_decode_of_every_message_type_raises_only_protocol_error():
    rng = np.random.default_rng(SEED + 1)
    from virl_quad import robots

    spec = robots.get("pupper")
    seeds = [P.encode_state(RobotState.standing(spec), 1), P.encode_command(JointCommand.hold(spec), 2),
             P.encode_json(MsgType.ANNOUNCE, P.announce_body(spec, "p1"), 3),
             P.encode_json(MsgType.STATUS, {"mode": "IDLE"}, 4), P.encode_json(MsgType.ESTOP, {}, 5),
             P.encode_json(MsgType.ARM, {"robot_id": "p1"}, 6)]
    outcomes = Counter()
    for i in range(3000):
        b = bytearray(seeds[i % len(seeds)])
        for _ in range(int(rng.integers(1, 5))):
            op = rng.integers(3)
            if op == 0 and b:
                b[int(rng.integers(len(b)))] = int(rng.integers(256))
            elif op == 1:
                b = b[: int(rng.integers(len(b) + 1))]
            else:
                b += rng.bytes(int(rng.integers(1, 8)))
        try:
            P.decode(bytes(b))
            outcomes["ok"] += 1
        except ProtocolError as e:
            outcomes[e.reason] += 1
    assert sum(outcomes.values()) == 3000 and outcomes["ok"] < 30
