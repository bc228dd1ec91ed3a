"""Process harness for hardware-in-the-loop tests and benches (real processes, real Zenoh).

- :func:`start_hal`, :func:`start_server`: ``python -m virl_quad.deploy.hal|serve`` as
  subprocesses, output captured to a file (no pipe can fill up and block them)
- :class:`Monitor`: an operator's Zenoh session: latest STATUS / STATE, ARM, E-stop
- :func:`policy_for_tests`: the trained ``policies/pupper_trot.pt`` if present, else an
  untrained export (same format and metadata) in a given folder
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable

import zenoh

from virl_quad.deploy import protocol as P
from virl_quad.deploy.protocol import MsgType, ProtocolError
from virl_quad.deploy.zenoh_config import load_config, publisher_options

ROOT: Path = Path(__file__).resolve().parents[2]
TRAINED_POLICY: Path = ROOT / "policies" / "pupper_trot.pt"


def wait_until(pred: Callable[[], Any], timeout: float, interval: float = 0.02) -> Any:
    """Poll ``pred`` until it returns something truthy or ``timeout`` s pass; returns its last value."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(interval)


def port_open(port: int, host: str = "127.0.0.1") -> bool:
    """True if something accepts TCP connections on ``host:port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex((host, port)) == 0


class Proc:
    """A ``python -m module`` subprocess in the repository root, output in a temp file."""

    def __init__(self, module: str, args: list[str], name: str) -> None:
        self.name = name
        self._out = tempfile.NamedTemporaryFile(prefix=f"virl_{name}_", suffix=".log", delete=False)
        env = dict(os.environ, PYTHONUNBUFFERED="1", OMP_NUM_THREADS="1")
        self.popen = subprocess.Popen([sys.executable, "-m", module, *args], cwd=ROOT, env=env,
                                      stdout=self._out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    @property
    def pid(self) -> int:
        """Process id."""
        return self.popen.pid

    def output(self) -> str:
        """Everything the process printed so far."""
        self._out.flush()
        return Path(self._out.name).read_text(errors="replace")

    def alive(self) -> bool:
        """True while the process runs."""
        return self.popen.poll() is None

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        """Send ``sig`` (if running) and wait for the exit code; SIGKILL after ``timeout`` s."""
        if self.alive():
            self.popen.send_signal(sig)
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait(10)
            raise AssertionError(f"{self.name} did not exit within {timeout} s of signal {sig}:\n{self.output()}")

    def wait(self, timeout: float = 60.0) -> int:
        """Wait for the process to exit by itself; its exit code."""
        return self.popen.wait(timeout)

    def close(self) -> None:
        """Kill the process if it still runs and delete its log."""
        if self.alive():
            self.popen.kill()
            self.popen.wait(10)
        self._out.close()
        Path(self._out.name).unlink(missing_ok=True)


def start_hal(endpoint: str, robot_id: str, *extra: str, robot: str = "pupper", wait: float = 60.0) -> Proc:
    """Start a sim HAL listening on ``endpoint`` (``tcp/127.0.0.1:PORT`` or ``tls/...``) and wait
    until its port accepts connections."""
    args = ["--robot", robot, "--backend", "sim", "--robot-id", robot_id, "--listen", endpoint, *extra]
    proc = Proc("virl_quad.deploy.hal", args, "hal")
    port = int(endpoint.rsplit(":", 1)[1])
    if not wait_until(lambda: port_open(port) or not proc.alive(), wait, 0.05) or not proc.alive():
        out = proc.output()
        proc.close()
        raise RuntimeError(f"the HAL did not start:\n{out}")
    return proc


def start_server(policy: Path | str, endpoint: str, robot_id: str, *extra: str) -> Proc:
    """Start a policy server connecting to ``endpoint``."""
    args = ["--policy", str(policy), "--robot-id", robot_id, "--connect", endpoint, *extra]
    return Proc("virl_quad.deploy.serve", args, "serve")


def policy_for_tests(folder: Path | str) -> tuple[Path, bool]:
    """(policy path, trained?): ``policies/pupper_trot.pt`` if it exists, else an untrained
    Pupper policy exported into ``folder`` (demonstration of 40 frames)."""
    if TRAINED_POLICY.is_file():
        return TRAINED_POLICY, True
    return export_untrained(folder, "pupper"), False


def export_untrained(folder: Path | str, robot: str, seed: int = 0) -> Path:
    """Export an untrained policy for ``robot`` to ``folder/untrained_<robot>.pt``."""
    from virl_quad.export import export_actor, fresh_actor

    out = Path(folder) / f"untrained_{robot}.pt"
    if not out.is_file():
        export_actor(fresh_actor(seed=seed), robot, out, demo={"source": "trot", "num_frames": 40})
    return out


class Monitor:
    """An operator / monitor Zenoh session on one robot: newest STATUS and STATE, ARM, E-stop."""

    def __init__(self, conf: zenoh.Config, robot_id: str) -> None:
        self.robot_id = robot_id
        self.session = zenoh.open(conf)
        self.status: dict[str, Any] = {}
        self.state: P.RobotState | None = None
        self.statuses = 0
        self._lock = threading.Lock()
        self._seq = P.SeqCounter()
        self._subs = [self.session.declare_subscriber(P.key(robot_id, "status"), self._on_status),
                      self.session.declare_subscriber(P.key(robot_id, "state"), self._on_state)]

    @classmethod
    def peer(cls, endpoint: str, robot_id: str) -> "Monitor":
        """A monitor on the plain peer config connecting to ``endpoint``."""
        return cls(load_config("peer", listen=[], connect=[endpoint]), robot_id)

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            body = P.decode(sample.payload.to_bytes(), expect=MsgType.STATUS).body
        except ProtocolError:
            return
        with self._lock:
            self.status = body  # type: ignore[assignment]
            self.statuses += 1

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            st = P.decode(sample.payload.to_bytes(), expect=MsgType.STATE).body
        except ProtocolError:
            return
        with self._lock:
            self.state = st  # type: ignore[assignment]

    def latest(self) -> dict[str, Any]:
        """A copy of the newest STATUS body ({} before the first)."""
        with self._lock:
            return dict(self.status)

    def wait_status(self, pred: Callable[[dict[str, Any]], bool], timeout: float = 60.0) -> dict[str, Any]:
        """Wait for a STATUS satisfying ``pred``; returns it, or the last one seen (pred false)."""
        got = wait_until(lambda: (lambda s: s if s and pred(s) else None)(self.latest()), timeout)
        return got or self.latest()

    def fresh_status(self, timeout: float = 30.0) -> dict[str, Any]:
        """A STATUS published after this call (waits for the next one)."""
        n = self.statuses
        wait_until(lambda: self.statuses > n + 1, timeout)
        return self.latest()

    def alive(self, role: str, timeout: float = 2.0) -> bool:
        """True if the ``alive/<role>`` liveliness token of this robot is present."""
        replies = self.session.liveliness().get(P.liveliness_key(self.robot_id, role), timeout=timeout)
        return any(r.ok is not None for r in replies)

    def arm(self, robot_id: str | None = None) -> None:
        """Publish an ARM for ``robot_id`` (default this monitor's robot)."""
        body = {"robot_id": robot_id or self.robot_id}
        self.session.put(P.key(self.robot_id, "arm"), P.encode_json(MsgType.ARM, body, self._seq()),
                         **publisher_options("arm"))

    def estop(self, reason: str = "test") -> None:
        """Publish an E-stop."""
        self.session.put(P.key(self.robot_id, "estop"),
                         P.encode_json(MsgType.ESTOP, {"reason": reason, "source": "monitor"}, self._seq()),
                         **publisher_options("estop"))

    def close(self) -> None:
        """Undeclare and close the session."""
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:
                pass
        self.session.close()
