"""The reference state at one instant and the part of a motion the environment uses (light:
numpy only, so the environment can import it without the motion tools)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass
class MotionState:
    """The reference robot state at one instant (SI units, canonical joint order)."""

    root_pos: np.ndarray      # m, world (3)
    root_quat: np.ndarray     # xyzw, world (4)
    q: np.ndarray             # rad (12)
    root_lin_vel: np.ndarray  # m/s, world (3)
    root_ang_vel: np.ndarray  # rad/s, world (3)
    dq: np.ndarray            # rad/s (12)


class MotionLike(Protocol):
    """The part of a reference motion the environment uses."""

    duration: float
    loop: bool

    def state_at(self, t: float) -> MotionState:
        """Reference state at time ``t`` (s)."""
        ...
