"""Fixtures shared by the test folders (pytest runs with --import-mode=importlib, so test modules
cannot import each other: helpers live in fixtures here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

#: ../shared/motions next to the repository root (absent in a user's fresh checkout).
SHARED_MOTIONS = Path(__file__).resolve().parents[1].parent / "shared" / "motions"


@pytest.fixture(scope="session")
def motions_dir() -> Path:
    """The shared motion clips folder; skips the test when it is absent."""
    if not SHARED_MOTIONS.is_dir() or not any(SHARED_MOTIONS.glob("*.txt")):
        pytest.skip(f"shared motions folder not found: {SHARED_MOTIONS}")
    return SHARED_MOTIONS


@pytest.fixture
def private_cache(tmp_path_factory, monkeypatch):
    """Keep built-in gait renders out of the user's cache: one cache folder per test session
    (used by every test of tests/demo, tests/motion and tests/evaluation, through their conftest)."""
    monkeypatch.setenv("VIRL_QUAD_CACHE", str(tmp_path_factory.getbasetemp() / "virl_quad_cache"))


@pytest.fixture(scope="session")
def gait_motions():
    """Built-in gait motions of both robots, {(robot, gait): Motion}, generated once."""
    from virl_quad.motion.gaits import GAIT_NAMES, gait_motion

    return {(r, g): gait_motion(r, g) for r in ("pupper", "laikago") for g in GAIT_NAMES}


@pytest.fixture(scope="session")
def mae():
    """Mean absolute difference of two uint8 image stacks, in gray levels."""
    return lambda a, b: float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


@pytest.fixture(scope="session")
def wait_for_checkpoint():
    """``wait(proc, run_dir, iteration, seconds=240)``: poll until the training subprocess ``proc``
    has a checkpoint at ``iteration`` or more in ``run_dir``, or has ended, or time is up."""
    import time

    from virl_quad.training import checkpoint

    def wait(proc, run_dir: Path, iteration: int, seconds: float = 240.0) -> None:
        deadline = time.time() + seconds
        while time.time() < deadline and proc.poll() is None:
            if (run_dir / checkpoint.LATEST).exists() and checkpoint.load(run_dir)["iteration"] >= iteration:
                return
            time.sleep(0.5)
    return wait
