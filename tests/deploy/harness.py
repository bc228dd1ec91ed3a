"""Process harness for hardware-in-the-loop tests and ``bench/serve_latency.py`` (real processes,
real Zenoh); loaded by path (``tests/deploy/conftest.py``), not part of the package.

- :func:`start_hal`, :func:`start_server`: ``python -m virl_quad.deploy.hal|serve`` as
  subprocesses, output captured to a file (no pipe can fill up and block them)
- :class:`Monitor` (= :class:`virl_quad.deploy.operator.Operator`): newest STATUS, ARM, E-stop
- :func:`policy_for_tests`: the shipped Pupper policy (the policy server's default,
  :func:`virl_quad.deploy.serve.default_policy`) if present, else an untrained export (same
  format and metadata) in a given folder
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

from virl_quad.deploy.operator import Operator, wait_until

#: An operator / monitor session (kept under this name for the tests).
Monitor = Operator

ROOT: Path = Path(__file__).resolve().parents[2]


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
    """(policy path, shipped?): the policy server's default Pupper policy if one is shipped,
    else an untrained Pupper policy exported into ``folder`` (demonstration of 40 frames)."""
    from virl_quad.deploy.serve import default_policy

    shipped = default_policy()
    if shipped.is_file():
        return shipped, True
    return export_untrained(folder, "pupper"), False


def export_untrained(folder: Path | str, robot: str, seed: int = 0) -> Path:
    """Export an untrained policy for ``robot`` to ``folder/untrained_<robot>.pt``."""
    from virl_quad.export import default_contract, export_actor, fresh_actor

    out = Path(folder) / f"untrained_{robot}.pt"
    if not out.is_file():
        contract = default_contract(robot, demo_frames=40)
        export_actor(fresh_actor(contract, seed=seed), robot, out, contract, demo={"source": "trot", "num_frames": 40})
    return out
