"""Explicit joint-space PD with torque limits.

Why explicit torque PD rather than PyBullet's POSITION_CONTROL motors: the
gains then mean what they mean on the real motor drivers (N·m/rad,
N·m·s/rad), torque saturation is exact, and motor strength, gain scaling and
control latency can be randomised the way they happen on hardware. The price
is numerical stiffness on very light links, paid for by a small physics step
and the reflected rotor inertia in the Pupper URDF.
"""

from __future__ import annotations

import numpy as np


def pd_torque(
    q_target: np.ndarray,       # rad
    q: np.ndarray,              # rad
    dq: np.ndarray,             # rad/s
    kp: np.ndarray,             # N·m/rad
    kd: np.ndarray,             # N·m·s/rad
    torque_limit: np.ndarray,   # N·m
    tau_ff: np.ndarray | float = 0.0,  # N·m, feed-forward
    dq_target: np.ndarray | float = 0.0,  # rad/s
) -> np.ndarray:
    """Return the PD torque (N·m), clipped to +-torque_limit."""
    tau = kp * (q_target - q) + kd * (dq_target - dq) + tau_ff
    return np.clip(tau, -torque_limit, torque_limit)
