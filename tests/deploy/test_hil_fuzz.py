"""Fuzz a running HAL over Zenoh: 10,000 messages from the :class:`fuzzing.Fuzzer` (random
bytes, wrong sizes, versions, magics and types, bad CRC, NaN/inf, negative gains, huge values,
replayed and old sequence numbers, valid commands mixed in) at ``virl/<id>/cmd`` of a REAL
``python -m virl_quad.deploy.hal`` process (sim Pupper) on a free loopback port (peer config:
multicast scouting off), while this test, as the operator, arms, E-stops and re-arms it.

Real time, not lock-step: the HAL's loop ticks at 50 Hz by the wall clock while the messages
arrive at any moment, as they would from a network. (In lock-step the first accepted command
whose random ``ref_seq`` exceeds the state's sequence number would count as the answer to every
later state, and the loop would run as fast as the CPU allows.)

Delivery is made lossless, so that every message can be counted: one publisher, reliable, with
congestion control BLOCK, that starts only once the HAL's subscriber matches it (a put before
the subscriber's declaration has reached this session has no route and is dropped silently).

Every expected rejection reason is known exactly: the HAL's sequence baseline changes only on
an accepted ARM, so before each ARM the test waits until STATUS has counted every message sent
so far, and after it until STATUS shows the ARM taken; only then does the Fuzzer forget its
baseline. The test checks afterwards that the HAL is alive and still publishing, that
``accepted + sum(rejected) == 10,000`` with every reason's count as expected (the random-bytes
and any-bit-flip categories: some protocol reason each), and, in the HAL's ``--record`` of every
tick, that every command the simulated motors were given is safe (``is_safe_command``, the
per-period step limit between powered ticks, DAMPING: no kp, no feed-forward; IDLE: no torque).
"""

from __future__ import annotations

import signal
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from virl_quad import robots
from virl_quad.deploy import protocol as P
from hil_harness import Monitor, start_hal
from virl_quad.deploy.operator import wait_until
from virl_quad.deploy.protocol import JointCommand
from virl_quad.deploy.safety import SafetyConfig, is_safe_command
from virl_quad.deploy.zenoh_config import free_port, publisher_options


ROBOT_ID = "pupper-fuzz"
SPEC = robots.get("pupper")
CFG = SafetyConfig()                 # the HAL's (no command-line option changes it)
N_MESSAGES = 10_000
SEED = 20240607
RATE = 600.0                         # messages/s at most: the HAL keeps up and still ticks on time
BATCH = 40                           # messages between two looks at STATUS (re-arm, E-stop)
TIMEOUT = 60.0                       # s, generous waits for a loaded 2-core machine (never asserted)
#: rejection reasons of the safety layer (after a message decoded): content, then sequence
SAFETY_REASONS: tuple[str, ...] = ("bad_shape", "non_finite", "negative_gain", "bad_seq", "stale_seq")


def _counted(status: dict[str, Any]) -> int:
    """Commands the HAL has judged so far: accepted + every rejection."""
    return int(status.get("accepted", 0)) + sum(status.get("rejected", {}).values())


class Rig:
    """The HAL process, an operator session and a reliable, blocking publisher on its cmd key."""

    def __init__(self, record: Path) -> None:
        self.ep = f"tcp/127.0.0.1:{free_port()}"
        self.hal = start_hal(self.ep, ROBOT_ID, "--reset-on-arm", "--status-hz", "20", "--record", str(record))
        try:
            self.op = Monitor.peer(self.ep, ROBOT_ID)
        except BaseException:
            self.hal.close()
            raise
        opts = dict(publisher_options("cmd"), congestion_control=zenoh.CongestionControl.BLOCK,
                    reliability=zenoh.Reliability.RELIABLE)
        self.pub = self.op.session.declare_publisher(P.key(ROBOT_ID, "cmd"), **opts)
        self.sent = 0                  # messages published on the cmd key

    def wait(self, pred: Any, what: str) -> dict[str, Any]:
        """The first STATUS satisfying ``pred``; fails with the HAL's output if none comes."""
        st = self.op.wait_status(pred, TIMEOUT)
        assert st and pred(st), f"STATUS never showed {what}; last {st}\n{self.hal.output()}"
        return st

    def put(self, data: bytes) -> None:
        """Publish one message on the cmd key (blocks rather than drops under congestion)."""
        self.pub.put(data)
        self.sent += 1

    def flush(self) -> dict[str, Any]:
        """Wait until the HAL has counted every message sent so far; that STATUS."""
        st = self.wait(lambda s: _counted(s) >= self.sent, f"{self.sent} commands counted")
        assert _counted(st) == self.sent, f"the HAL counted more commands than were sent: {st}"
        return st

    def arm(self) -> bool:
        """Flush, ARM, wait until the HAL took it (True) or ignored it (False)."""
        ev = self.flush()["events"]
        arms, ignored = ev.get("arm", 0), ev.get("arm_ignored", 0)
        self.op.arm()
        st = self.wait(lambda s: s["events"].get("arm", 0) > arms or s["events"].get("arm_ignored", 0) > ignored,
                       "the ARM taken or ignored")
        return st["events"].get("arm", 0) > arms

    def close(self) -> None:
        """Undeclare the publisher, close the session, kill the HAL if it still runs."""
        try:
            self.pub.undeclare()
        except Exception:
            pass
        self.op.close()
        self.hal.close()


def test_fuzz_10000_messages_at_a_running_hal(tmp_path, fuzzing):
    CATEGORIES, WEIGHTS, Fuzzer = fuzzing.CATEGORIES, fuzzing.WEIGHTS, fuzzing.Fuzzer
    record = tmp_path / "fuzz.npz"
    rng = np.random.default_rng(SEED)
    fz = Fuzzer(SPEC, rng)
    cats = list(CATEGORIES)
    probs = WEIGHTS / WEIGHTS.sum()
    by_category: Counter[str] = Counter()
    expect: Counter[str] = Counter()        # certain rejection reasons, "*" (some protocol reason), None (accepted)
    arms = estops = 0
    t_start = time.perf_counter()
    rig = Rig(record)
    try:
        st = rig.wait(lambda s: s["ticks"] > 5, "a running loop")
        assert st["mode"] == "IDLE" and st["lockstep"] is False, st
        assert wait_until(lambda: rig.pub.matching_status.matching, TIMEOUT), "the HAL's cmd subscriber never matched"
        active_batches, estop_after = 0, 0
        t_fuzz = time.perf_counter()
        while rig.sent < N_MESSAGES:
            seen = rig.op.latest().get("mode")       # DAMPING and IDLE are latched: still true
            if seen in ("IDLE", "DAMPING") and (arms == 0 or rng.random() < 0.3):
                if rig.arm():                 # every message before it counted: the baseline reset is exact
                    fz.note_arm()
                    arms += 1
                    active_batches, estop_after = 0, int(rng.integers(2, 12))
            elif seen == "ACTIVE":
                active_batches += 1
                if active_batches == estop_after:
                    rig.op.estop("fuzz")          # unless the flailing robot tilted first
                    estops += 1
            t_batch = time.perf_counter()
            for _ in range(min(BATCH, N_MESSAGES - rig.sent)):
                cat = cats[int(rng.choice(len(cats), p=probs))]
                data, reason = fz.make(cat)
                rig.put(data)
                by_category[cat] += 1
                expect[reason] += 1
                if reason is None:
                    fz.note_accepted(data)
            time.sleep(max(0.0, BATCH / RATE - (time.perf_counter() - t_batch)))
        t_sent = time.perf_counter() - t_fuzz
        st = rig.flush()
        # alive afterwards, its loop still ticking and publishing STATUS, its token held
        n_status, ticks = rig.op.statuses, st["ticks"]
        rig.wait(lambda s: s["ticks"] > ticks + 10 and rig.op.statuses > n_status + 2, "the loop still running")
        assert rig.hal.alive() and rig.op.alive("hal"), rig.hal.output()
        assert rig.hal.stop(signal.SIGINT) == 0, rig.hal.output()    # SIGINT: the record is written
        out = rig.hal.output()
    finally:
        rig.close()
    elapsed = time.perf_counter() - t_start

    # ------------------------------------------------------------------ every message counted once
    rejected = Counter(st["rejected"])
    assert rig.sent == N_MESSAGES and sum(expect.values()) == N_MESSAGES
    assert st["accepted"] + sum(rejected.values()) == N_MESSAGES, st
    assert st["errors"] == {}, st                                   # no callback failed (nothing uncounted)
    assert set(rejected) <= set(P.REASONS) | set(SAFETY_REASONS), rejected
    assert st["accepted"] == expect[None], (st, expect)
    for reason in SAFETY_REASONS:                                   # decided after decoding: exact
        assert rejected[reason] == expect[reason], (reason, rejected, expect)
    for reason in P.REASONS:                                        # plus some of the "*" messages
        assert rejected[reason] >= expect[reason], (reason, rejected, expect)
    assert sum(rejected[r] for r in P.REASONS) == sum(expect[r] for r in P.REASONS) + expect["*"], (rejected, expect)
    assert set(by_category) == set(CATEGORIES)                      # every category exercised
    for reason in ("bad_crc", "bad_size", "bad_version", "bad_magic", "bad_type", "wrong_type",
                   "non_finite", "negative_gain", "stale_seq"):
        assert rejected[reason] > 0, (reason, rejected)
    # out-of-range commands were applied, limited (the fuzz reached the motors' side of the loop)
    assert all(st["clamped"].get(k, 0) > 0 for k in ("q_limit", "gain", "tau_ff")), st
    assert "Traceback" not in out, out

    # ------------------------------------------------------------------ every applied command safe
    data = np.load(record)
    names = [str(m) for m in data["modes"]]
    mode = np.array([names[i] for i in data["mode"]])
    n = len(mode)
    np.testing.assert_array_equal(data["tick"], np.arange(1, n + 1))   # every tick since the start
    powered = np.isin(mode, ["RAMP", "ACTIVE"])
    prev: JointCommand | None = None
    step_checks = 0
    for i in range(n):
        cmd = JointCommand(*(data[k][i] for k in ("q_target", "kp", "kd", "tau_ff")))
        assert is_safe_command(cmd, SPEC, CFG), f"unsafe command at tick {data['tick'][i]} ({mode[i]}): {cmd}"
        if i > 0 and powered[i] and powered[i - 1]:
            assert is_safe_command(cmd, SPEC, CFG, prev=prev), f"target jump at tick {data['tick'][i]} ({mode[i]})"
            step_checks += 1
        prev = cmd
    damping, idle = mode == "DAMPING", mode == "IDLE"
    assert not data["kp"][damping].any() and not data["tau_ff"][damping].any()
    assert np.all(data["kd"][damping] == CFG.damping_kd_factor * np.asarray(SPEC.kd, dtype=np.float64))
    assert not data["kp"][idle].any() and not data["kd"][idle].any() and not data["tau_ff"][idle].any()
    modes = Counter(mode.tolist())
    assert modes["ACTIVE"] > 0 and modes["DAMPING"] > 0 and modes["RAMP"] > 0, modes
    print(f"\n[hil fuzz] messages={rig.sent} accepted={st['accepted']} rejected={dict(sorted(rejected.items()))} "
          f"ticks={n} modes={dict(modes)} step_checks={step_checks} arms={arms} estops={estops} "
          f"events={st['events']} clamped={st['clamped']} overruns={st['overruns']} "
          f"send={t_sent:.1f}s total={elapsed:.1f}s")
