"""Silence native libraries that write straight to a file descriptor (not Python's sys.stdout/err).

PyBullet prints its build time on import and some status lines from C; FFmpeg (inside
OpenCV) prints decoder errors for broken videos. The command lines promise one-line
errors, so these go to /dev/null.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
from collections.abc import Iterator


@contextlib.contextmanager
def quiet_fd(fd: int = 2) -> Iterator[None]:
    """Redirect file descriptor ``fd`` (1 stdout, 2 stderr) to /dev/null inside the block."""
    try:
        (sys.stdout if fd == 1 else sys.stderr).flush()
        saved = os.dup(fd)
    except (OSError, ValueError, AttributeError):  # no such descriptor: nothing to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


def import_pybullet_quietly() -> None:
    """Import pybullet without its build-time banner."""
    if "pybullet" in sys.modules:
        return
    with quiet_fd(1), quiet_fd(2):
        importlib.import_module("pybullet")
