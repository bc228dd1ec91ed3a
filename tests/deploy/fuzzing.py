"""Malformed and valid COMMAND messages for the fuzz tests (``test_fuzz.py`` in process,
``test_hil_fuzz.py`` against a real HAL over Zenoh).

Not a test module: the tests load it by path (pytest runs with ``--import-mode=importlib``,
which puts no test folder on ``sys.path``), see ``load_fuzzing`` in each of them.

- :data:`CATEGORIES`: message category -> the rejection reason it must get (None: accepted,
  ``"*"``: some :data:`virl_quad.deploy.protocol.REASONS` code)
- :data:`WEIGHTS`: how often each category is drawn (same order as CATEGORIES)
- :class:`Fuzzer`: one message of a category, with its expected outcome
"""

from __future__ import annotations

import struct
import zlib
from typing import Any

import numpy as np

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, RobotState

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
    """``data`` (a framed message) with header fields replaced and a CRC that matches again."""
    m, v, t, seq, stamp, n, _ = P.HEADER.unpack_from(data)
    head = struct.pack("<4sHHQQI", magic or m, v if version is None else version,
                       t if mtype is None else mtype, seq, stamp, n if plen is None else plen)
    payload = data[32:]
    return head + struct.pack("<I", zlib.crc32(head + payload)) + payload


class Fuzzer:
    """Generates one message of a given category; tracks what the controller should know."""

    def __init__(self, spec: Any, rng: np.random.Generator) -> None:
        self.spec, self.rng = spec, rng
        self.seq = 10**6
        self.accepted_since_arm: list[bytes] = []   # candidates for replay
        self.baseline: int | None = None            # newest accepted seq since the last arm

    def note_accepted(self, data: bytes) -> None:
        """The receiver accepted ``data``: its seq is the new baseline, it may be replayed."""
        self.baseline = P.HEADER.unpack_from(data)[3]
        self.accepted_since_arm.append(data)

    def note_arm(self) -> None:
        """The receiver was (re-)armed: its sequence baseline is gone."""
        self.accepted_since_arm.clear()
        self.baseline = None

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
        """A sequence number above every one used so far."""
        self.seq += int(self.rng.integers(1, 4))
        return self.seq

    def make(self, cat: str) -> tuple[bytes, str | None]:
        """One message of category ``cat`` and its expected rejection reason (see CATEGORIES)."""
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
