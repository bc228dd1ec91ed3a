"""E-stop and ARM races and bursts against a REAL ``python -m virl_quad.deploy.hal`` process
(sim Pupper, real Zenoh on loopback, multicast scouting off), written from ``deploy/PROTOCOL.md``
sections 6-8 alone:

- an E-stop sent a few milliseconds after an ARM wins, also when it overtakes the ARM (it has
  the higher priority): the HAL never ends in RAMP or ACTIVE, for ARM -> ESTOP gaps of 0 to
  25 ms, in real time and in lock-step (§7, §8);
- every sample on ``arm`` and ``estop`` is counted, also in a burst, and a valid ARM or E-stop
  is never lost behind a burst of garbage (§7);
- a Zenoh DELETE on ``estop`` is an E-stop, on ``arm`` it is counted and ignored (§7);
- the ANNOUNCE publishes the limits the safety layer enforces (§6).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.deploy import protocol as P
from hil_harness import Monitor, start_hal
from virl_quad.deploy.operator import wait_until
from virl_quad.deploy.protocol import MsgType
from virl_quad.deploy.safety import SafetyController
from virl_quad.deploy.zenoh_config import free_port, publisher_options

ROBOT_ID = "pupper-race"
SPEC = robots.get("pupper")
TIMEOUT = 60.0                           # s, generous waits for a loaded 2-core machine (never asserted)
GAPS_MS = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0)
TRIES = 20                               # per gap


class Rig:
    """A sim HAL process (STATUS at 50 Hz) and an operator session on it."""

    def __init__(self, *hal_args: str) -> None:
        ep = f"tcp/127.0.0.1:{free_port()}"
        self.hal = start_hal(ep, ROBOT_ID, "--status-hz", "50", *hal_args)
        try:
            self.op = Monitor.peer(ep, ROBOT_ID)
        except BaseException:
            self.hal.close()
            raise
        # the operator's own publisher options: the E-stop at a higher priority than the ARM
        self.pubs = {t: self.op.session.declare_publisher(P.key(ROBOT_ID, t), **publisher_options(t))
                     for t in ("arm", "estop")}
        assert wait_until(lambda: all(p.matching_status.matching for p in self.pubs.values()), TIMEOUT), \
            f"the HAL's arm/estop subscribers never matched\n{self.hal.output()}"
        self._seq = P.SeqCounter()

    def wait(self, pred: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        """The first STATUS satisfying ``pred``; fails with the HAL's output if none comes."""
        st = self.op.wait_status(pred, TIMEOUT)
        assert st and pred(st), f"STATUS never showed {what}; last {st}\n{self.hal.output()}"
        return st

    def arm_msg(self, robot_id: str = ROBOT_ID) -> bytes:
        return P.encode_json(MsgType.ARM, {"robot_id": robot_id}, self._seq())

    def estop_msg(self, reason: str) -> bytes:
        return P.encode_json(MsgType.ESTOP, {"reason": reason}, self._seq())

    def put(self, topic: str, data: bytes) -> None:
        self.pubs[topic].put(data)

    def close(self) -> None:
        for p in self.pubs.values():
            try:
                p.undeclare()
            except Exception:
                pass
        self.op.close()
        self.hal.close()


@pytest.fixture
def rig_factory():
    rigs: list[Rig] = []

    def make(*args: str) -> Rig:
        rigs.append(Rig(*args))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def _events(st: dict[str, Any], name: str) -> int:
    return int(st.get("events", {}).get(name, 0))


@pytest.mark.slow
@pytest.mark.parametrize("lockstep", [False, True], ids=["real_time", "lockstep"])
def test_estop_after_arm_always_wins(rig_factory, lockstep):
    """ARM, then ESTOP ``gap`` ms later from the same session, while the HAL is in DAMPING: once
    both are counted and a few periods have passed, the HAL is in DAMPING with the E-stop's
    fault. An ARM that took effect before the E-stop arrived (gaps longer than a period) may
    start a RAMP; the E-stop must end it."""
    rig = rig_factory(*(("--lockstep",) if lockstep else ()))
    rig.wait(lambda s: s["ticks"] > 3, "a running loop")
    rig.put("estop", rig.estop_msg("start"))                # an E-stop in IDLE damps (§8)
    rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING after the first E-stop")
    rearmed: list[tuple[float, dict[str, Any]]] = []
    for gap in GAPS_MS:
        for _ in range(TRIES):
            before = rig.op.latest()
            n_estop = _events(before, "estop")               # E-stops taken by a tick
            rig.put("arm", rig.arm_msg())
            if gap:
                time.sleep(gap / 1000.0)
            rig.put("estop", rig.estop_msg("stop!"))
            st = rig.wait(lambda s: _events(s, "estop") > n_estop, "the E-stop taken")
            settled = st["ticks"] + 4                        # an ARM taken later would show by then
            st = rig.wait(lambda s: s["ticks"] >= settled, "four more periods")
            if st["mode"] != "DAMPING" or not st["fault"].startswith("estop"):
                rearmed.append((gap, st))
    assert not rearmed, (f"{len(rearmed)} of {len(GAPS_MS) * TRIES} tries ended re-armed after the E-stop; "
                         f"first at gap {rearmed[0][0]} ms: {rearmed[0][1]}")
    st = rig.op.latest()
    assert _events(st, "arm_received") == len(GAPS_MS) * TRIES, st   # every ARM sample was counted
    assert _events(st, "estop_received") == len(GAPS_MS) * TRIES + 1, st
    assert _events(st, "arm_received") == sum(_events(st, e) for e in ("arm", "arm_cancelled", "arm_ignored")), st
    print(f"ARMs taken {_events(st, 'arm')}, cancelled {_events(st, 'arm_cancelled')} "
          f"(sent before an E-stop that overtook them: {_events(st, 'arm_before_estop')})")


@pytest.mark.slow
def test_every_arm_and_estop_sample_is_counted_in_a_burst(rig_factory):
    rig = rig_factory()
    rig.wait(lambda s: s["ticks"] > 3 and s["mode"] == "IDLE", "a running loop in IDLE")
    bad = bytearray(rig.arm_msg())
    bad[-1] ^= 1                                             # payload changed, CRC not: bad_crc
    for _ in range(100):                                     # one burst, no pause
        rig.put("arm", bytes(bad))
    st = rig.wait(lambda s: sum(s["rejected_other"].values()) >= 100, "100 bad ARMs counted")
    time.sleep(0.2)
    st = rig.op.latest()
    assert st["rejected_other"] == {"arm:bad_crc": 100} and st["mode"] == "IDLE", st
    # a valid ARM followed at once by 40 bad ones: counted and taken, not pushed out of a buffer
    rig.put("arm", rig.arm_msg())
    for _ in range(40):
        rig.put("arm", bytes(bad))
    st = rig.wait(lambda s: s["rejected_other"].get("arm:bad_crc") == 140 and _events(s, "arm") == 1,
                  "the valid ARM taken and every bad one counted")
    assert _events(st, "arm_received") == 1 and st["mode"] == "RAMP", st
    # garbage on both keys, then one valid E-stop: every sample counted, the robot damped
    for i in range(300):
        rig.put("arm", bytes(bad) if i % 2 else b"x" * (i % 50))
        rig.put("estop", b"junk" * (i % 7))
    rig.put("estop", rig.estop_msg("the real one"))
    st = rig.wait(lambda s: _events(s, "estop_received") == 301, "301 E-stop samples counted")
    assert st["mode"] == "DAMPING" or st["estop_pending"], st    # counted: applied, or at the next tick
    st = rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING at the tick after the E-stop")
    other = st["rejected_other"]
    assert sum(v for k, v in other.items() if k.startswith("estop:")) == 300, st
    assert sum(v for k, v in other.items() if k.startswith("arm:")) == 140 + 300, st
    assert st["mode"] == "DAMPING" and st["fault"].startswith("estop"), st


def test_delete_on_estop_is_an_estop_and_announce_has_the_limits(rig_factory):
    rig = rig_factory("--arm")
    rig.wait(lambda s: s["mode"] == "RAMP", "RAMP after --arm")
    rig.op.session.delete(P.key(ROBOT_ID, "arm"))
    st = rig.wait(lambda s: s["rejected_other"].get("arm:delete") == 1, "the DELETE on arm counted")
    assert st["mode"] == "RAMP", st
    rig.op.session.delete(P.key(ROBOT_ID, "estop"))
    st = rig.wait(lambda s: s["mode"] == "DAMPING", "DAMPING after a DELETE on estop")
    assert st["fault"] == "estop" and st["rejected_other"].get("estop:delete") == 1, st
    replies = [r.ok for r in rig.op.session.get(P.key(ROBOT_ID, "announce"), timeout=5.0) if r.ok]
    assert replies, rig.hal.output()
    body = P.decode(replies[0].payload.to_bytes(), expect=MsgType.ANNOUNCE).body
    want = SafetyController(SPEC).limits()
    assert body["limits"] == want
    np.testing.assert_array_equal(body["limits"]["q_lower"], SPEC.joint_lower)
    np.testing.assert_array_equal(body["limits"]["kp_max"], 2.0 * SPEC.kp)
    assert body["limits"]["max_step"] == 0.2 and body["limits"]["watchdog_periods"] == 3
