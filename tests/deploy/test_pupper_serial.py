"""Pupper serial backend against a board emulator on a pseudo-terminal (no mocks)."""

from __future__ import annotations

import os
import select
import struct
import threading
import time
import tty
import zlib

import msgpack
import numpy as np
import pytest

from virl_quad import robots
from virl_quad.deploy.backends import BackendError, BackendTimeout, get_backend
from virl_quad.deploy.backends.pupper_serial import (
    SYNC,
    TORQUE_CONSTANT,
    FrameDecoder,
    MotorMap,
    PupperSerialBackend,
    encode_frame,
)
from virl_quad.deploy.protocol import JointCommand
from virl_quad.deploy.safety import SafetyController


SPEC = robots.get("pupper")
# a deliberately non-trivial mapping: reversed motor order, mixed signs, offsets
MAP = MotorMap(order=tuple(reversed(range(12))), sign=(1, -1, 1) * 4, offset=tuple(0.01 * i for i in range(12)))


def hand_frame(obj) -> bytes:
    """The documented framing, written out without the module's helper."""
    body = msgpack.packb(obj, use_bin_type=True)
    return b"\xa5\x5a" + struct.pack("<H", len(body)) + body + struct.pack("<I", zlib.crc32(body))


class Board:
    """Plays the Teensy: streams state frames, records the host's frames."""

    def __init__(self, rate_hz: float = 400.0) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)                        # no echo, no line discipline before pyserial opens it
        self.slave_fd, self.path = slave, os.ttyname(slave)
        self.period = 1.0 / rate_hz
        self.received: list[dict] = []
        self.pos = np.linspace(-0.5, 0.5, 12)    # board order, rad
        self.vel = np.linspace(1.0, 2.2, 12)
        self.cur = np.linspace(-3.0, 3.0, 12)    # A
        self.quat_wxyz = [0.9, 0.1, -0.2, 0.3]
        self.streaming = True
        self.extra: list[bytes] = []             # raw bytes to inject before the next state frame
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.decoder = FrameDecoder()
        self._t0 = time.monotonic()

    def __enter__(self) -> "Board":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave_fd)

    def state_msg(self) -> dict:
        return {"t": "state", "ts": int((time.monotonic() - self._t0) * 1e6), "pos": self.pos.tolist(),
                "vel": self.vel.tolist(), "cur": self.cur.tolist(), "quat": self.quat_wxyz,
                "gyro": [0.1, 0.2, 0.3], "acc": [0.0, 0.0, 9.81]}

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.001)
            if r:
                try:
                    self.received += self.decoder.feed(os.read(self.master, 4096))
                except OSError:
                    return
            if self.streaming and time.monotonic() >= next_t:
                next_t += self.period
                data = b"".join(self.extra) + hand_frame(self.state_msg())
                self.extra.clear()
                try:
                    os.write(self.master, data)
                except OSError:
                    return

    def wait_for(self, n: int, timeout: float = 2.0) -> list[dict]:
        deadline = time.monotonic() + timeout
        while len(self.received) < n and time.monotonic() < deadline:
            time.sleep(0.002)
        return self.received


def test_frame_decoder_reads_the_documented_framing_and_resyncs():
    dec = FrameDecoder()
    good = hand_frame({"t": "state", "x": 1})
    assert encode_frame({"t": "state", "x": 1}) == good
    corrupt = bytearray(good)
    corrupt[6] ^= 0xFF                                          # body byte: CRC mismatch
    stream = b"\x00\xa5noise" + bytes(corrupt) + SYNC + b"\xff\xff" + good + hand_frame([1, 2]) + good[:5]
    out = []
    for i in range(0, len(stream), 7):                          # arrives in small pieces
        out += dec.feed(stream[i:i + 7])
    out += dec.feed(good[5:])
    assert out == [{"t": "state", "x": 1}, {"t": "state", "x": 1}]
    assert dec.errors["bad_crc"] == 1 and dec.errors["bad_length"] == 1 and dec.errors["not_a_map"] == 1


def test_motor_map_round_trip_and_validation():
    q = np.linspace(-1, 1, 12)
    np.testing.assert_allclose(MAP.from_board(MAP.to_board(q, offset=True), offset=True), q)
    assert MAP.to_board(q)[11] == pytest.approx(q[0])          # joint 0 is motor 11
    with pytest.raises(ValueError):
        MotorMap(order=(0,) * 12)
    with pytest.raises(ValueError):
        MotorMap(sign=(1, 0) * 6)


def test_read_state_maps_board_units_order_and_signs():
    with Board() as board, PupperSerialBackend(board.path, motor_map=MAP) as robot:
        st = robot.read_state()
        sign, off = np.array(MAP.sign, float), np.array(MAP.offset)
        order = list(MAP.order)
        np.testing.assert_allclose(st.q, board.pos[order] * sign + off)
        np.testing.assert_allclose(st.dq, board.vel[order] * sign)
        np.testing.assert_allclose(st.tau, board.cur[order] * sign * TORQUE_CONSTANT)
        np.testing.assert_allclose(st.quat, [0.1, -0.2, 0.3, 0.9])   # wxyz on the board -> xyzw
        np.testing.assert_allclose(st.accel, [0, 0, 9.81])
        assert np.isnan(st.contacts).all() and st.timestamp >= 0
        t1 = robot.read_state().timestamp
        assert t1 > st.timestamp                                      # a fresh frame every call


def test_write_command_converts_to_board_units():
    with Board() as board:
        robot = get_backend("pupper_serial", port=board.path, motor_map=MAP, max_current=5.0)
        with robot:
            cmd = JointCommand(np.linspace(-0.3, 0.3, 12), np.full(12, 3.6), np.full(12, 0.36),
                               np.array([2.0, -2.0] + [0.18] * 10))
            robot.write_command(cmd)
            msgs = board.wait_for(2)
        assert msgs[0] == {"t": "cfg", "max_cur": 5.0}
        m = msgs[1]
        assert m["t"] == "cmd" and m["max_cur"] == 5.0
        motor = list(MAP.order)
        pos = np.empty(12)
        pos[motor] = (cmd.q_target - np.array(MAP.offset)) * np.array(MAP.sign, float)
        np.testing.assert_allclose(m["pos"], pos)
        np.testing.assert_allclose(m["kp"], 20.0)                   # 3.6 N·m/rad / 0.18 N·m/A
        np.testing.assert_allclose(m["kd"], 2.0)
        ff = np.empty(12)
        ff[motor] = np.clip(cmd.tau_ff / TORQUE_CONSTANT, -5, 5) * np.array(MAP.sign, float)
        np.testing.assert_allclose(m["ff"], ff)
        assert max(abs(np.array(m["ff"]))) == 5.0                    # 11.1 A capped at max_current
        # close() left the motors damped: kp 0, spec kd, no feed-forward
        last = board.wait_for(3)[2]
        assert last["t"] == "cmd" and not any(last["kp"]) and not any(last["ff"])
        np.testing.assert_allclose(last["kd"], SPEC.kd / TORQUE_CONSTANT)


def test_non_finite_command_is_refused_and_nothing_is_sent():
    with Board() as board, PupperSerialBackend(board.path) as robot:
        bad = JointCommand.hold(SPEC)
        bad.q_target[3] = np.nan
        with pytest.raises(ValueError):
            robot.write_command(bad)
        time.sleep(0.05)
        assert [m["t"] for m in board.received] == ["cfg"]


def test_silent_board_times_out_and_garbage_is_counted():
    with Board() as board, PupperSerialBackend(board.path, state_timeout=0.05) as robot:
        robot.read_state()
        board.extra.append(hand_frame({"t": "state", "pos": [1, 2]}))     # malformed state map
        board.extra.append(b"\xa5\x5a\x03\x00abc\x00\x00\x00\x00")        # bad CRC
        time.sleep(0.02)
        robot.read_state()
        assert robot.bad_frames.get("bad_state_msg") == 1 and robot.bad_frames.get("bad_crc") == 1
        board.streaming = False
        time.sleep(0.05)
        try:
            robot.read_state()      # drains frames sent before the board fell silent, if any
        except BackendTimeout:
            pass
        t0 = time.monotonic()
        with pytest.raises(BackendTimeout):
            robot.read_state()
        assert 0.04 < time.monotonic() - t0 < 0.5


def test_open_failure_is_a_backend_error(tmp_path):
    with pytest.raises(BackendError):
        PupperSerialBackend(str(tmp_path / "no-such-tty"))


def test_safety_loop_over_the_serial_link():
    """HAL-style loop for a few periods: every frame the board receives is finite."""
    with Board() as board, PupperSerialBackend(board.path) as robot:
        ctl = SafetyController(SPEC)
        ctl.arm()
        for _ in range(10):
            robot.write_command(ctl.tick(robot.read_state()))
        msgs = board.wait_for(11)
    cmds = [m for m in msgs if m["t"] == "cmd"]
    assert len(cmds) >= 10
    assert all(np.isfinite(np.array(m["pos"] + m["kp"] + m["kd"] + m["ff"])).all() for m in cmds)
