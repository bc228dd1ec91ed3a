"""Silence native libraries that write to the stderr file descriptor (not Python's sys.stderr).

PyBullet prints its build time on import and FFmpeg (inside OpenCV) prints decoder errors for
broken videos; the command line promises one-line errors, so these go to /dev/null.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Redirect file descriptor 2 to /dev/null inside the block (no-op when it cannot)."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def import_pybullet_quietly() -> None:
    """Import pybullet without its build-time banner on stderr."""
    if "pybullet" in sys.modules:
        return
    with quiet_stderr():
        import pybullet  # noqa: F401
