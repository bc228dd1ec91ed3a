"""Bad command lines of every entry point: one ``error:`` line on stderr, exit code 2, no usage block
and no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BAD = [
    ("virl_quad.train", ["--reward", "foo"], "invalid choice: 'foo'"),
    ("virl_quad.train", ["--num-envs", "many"], "invalid int value"),
    ("virl_quad.train", ["--robot", "dog"], "unknown robot"),
    ("virl_quad.train", ["--demo", "missing.mp4"], "not found"),
    ("virl_quad.train", ["--resume", "no/such/run"], "does not exist"),
    ("virl_quad.train", ["--workers", "ray", "--ray-address", "127.0.0.1:1"], "cannot reach a Ray cluster"),
    ("virl_quad.train", ["--workers", "ray", "--ray-address", "headnode"], "HOST:PORT"),
    ("virl_quad.check", ["--robot", "dog"], "unknown robot 'dog'"),
    ("virl_quad.check", ["--samples", "0"], "--samples"),
    ("virl_quad.evaluate", [], "--policy"),
    ("virl_quad.evaluate", ["--policy", "missing.pt"], "missing.pt"),
    ("virl_quad.export", ["no/such/run", "--out", "x.pt"], "no/such/run"),
    ("virl_quad.export", ["run"], "--out"),
    ("virl_quad.demo", ["dance"], "invalid choice"),
    ("virl_quad.demo", ["render", "--robot", "dog", "--out", "x.npz"], "dog"),
    ("virl_quad.demo", ["show", "missing.npz", "--out", "x.png"], "missing.npz"),
    ("virl_quad.demo", ["render", "--robot", "pupper", "--gait", "trot", "--motion", "x.txt", "--out", "y.npz"],
     "not allowed with"),
    ("virl_quad.compare", ["--rewards", "virl,foo"], "unknown reward 'foo'"),
    ("virl_quad.compare", ["--minutes", "0"], "--minutes"),
    ("virl_quad.compare", ["--confusion", "trot"], "two or more"),
    ("virl_quad.deploy.hal", ["--cmd-wait", "soon"], "invalid float value"),
    ("virl_quad.deploy.serve", ["--wait", "forever"], "invalid float value"),
    ("virl_quad.deploy.serve", ["--policy", "missing.pt"], "missing.pt"),
    ("virl_quad.deploy.operator", ["dance"], "invalid choice"),
]


@pytest.mark.parametrize("module, args, message", BAD, ids=[f"{m.split('.')[-1]} {' '.join(a)}" for m, a, _ in BAD])
def test_bad_input_is_one_error_line_and_exit_2(module: str, args: list[str], message: str, tmp_path: Path) -> None:
    p = subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path)
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2, (p.returncode, p.stderr[-1500:])
    assert len(lines) == 1 and lines[0].startswith("error: "), p.stderr[-1500:]
    assert message in lines[0], lines[0]
    assert not any(tmp_path.iterdir()), list(tmp_path.iterdir())   # nothing made on the way to the error


@pytest.mark.parametrize("module, args", [("virl_quad.train", ["--init-std", "5"]),
                                          ("virl_quad.compare", ["--confusion", "trot,trot"]),
                                          ("virl_quad.evaluate", ["--policy", "p.pt", "--episodes", "0"]),
                                          ("virl_quad.export", ["no/such/run", "--out", "x.pt"]),
                                          ("virl_quad.export", ["run", "--out", "x.onnx"]),
                                          ("virl_quad.deploy.serve", ["--policy", "missing.pt"]),
                                          ("virl_quad.distill", ["--robot", "spot"]),
                                          ("virl_quad.distill", ["--rounds", "0"])])
def test_bad_options_are_refused_before_torch_and_the_simulator_load(module: str, args: list[str],
                                                                    tmp_path: Path) -> None:
    """A mistyped option is answered at once: nothing heavy is imported on the way to the error."""
    p = subprocess.run([sys.executable, "-X", "importtime", "-m", module, *args], capture_output=True, text=True,
                       timeout=120, cwd=tmp_path)
    assert p.returncode == 2, p.stderr[-1500:]
    imported = {line.rsplit("|", 1)[-1].strip() for line in p.stderr.splitlines() if line.startswith("import time:")}
    assert "virl_quad" in imported                      # the probe sees the imports
    heavy = {"torch", "pybullet", "pinocchio", "rsl_rl"} & imported
    assert not heavy, sorted(heavy)
