"""Fuzz: 10,000 malformed and valid commands through decode + safety, seeded.

No exception may escape, every applied command must pass is_safe_command (and the
per-period step limit while ACTIVE), and every message must be either accepted or
counted under exactly one rejection reason -- the expected one where it is known.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
import pytest

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import JointCommand, MsgType, ProtocolError, RobotState
from virl_quad.deploy.safety import Mode, SafetyConfig, SafetyController, is_safe_command


N_MESSAGES = 10_000
SEED = 20240606


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_fuzz_commands_through_decode_and_safety(robot, fuzzing):
    CATEGORIES, WEIGHTS, Fuzzer = fuzzing.CATEGORIES, fuzzing.WEIGHTS, fuzzing.Fuzzer
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
