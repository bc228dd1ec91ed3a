"""Joint-space PD with torque limits and Coulomb friction, two ways of stepping it.

The gains mean what they mean on the real motor drivers (N·m/rad, N·m·s/rad), torque
saturation is exact, and motor strength, gain scaling and control latency can be randomised
the way they happen on hardware. Two integrations of the same law:

- **implicit** (default, :func:`pd_motor`): each physics step, PyBullet's joint velocity motor
  is asked for the velocity at which the PD torque and the friction balance, with at most the
  PD torque (plus the friction) as its force. A light, unloaded link reaches that velocity
  within the step, as a real damper makes it do when its time constant ``I / kd`` (0.8 ms for
  Pupper's lower leg) is shorter than the step; a loaded one gets the full PD torque, as the
  explicit law gives it. The solver treats it implicitly, so the step may be longer than
  ``I / kd``: 2 ms on Pupper.
- **explicit** (:func:`pd_torque`): the torque from the state at the start of each physics
  step, with Coulomb friction as a separate velocity motor. Stable only for steps shorter
  than about ``2 I / kd`` (1.7 ms for Pupper's lower leg with its reflected rotor inertia):
  Pupper then needs a 1 kHz physics step.
"""

from __future__ import annotations

import numpy as np

PD_MODES = ("implicit", "explicit")
_MAX_TARGET_VELOCITY = 1e4   # rad/s: the motor target for kd = 0 (a pure spring: always saturated)


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


def pd_motor(
    q_target: np.ndarray,       # rad
    q: np.ndarray,              # rad
    dq: np.ndarray,             # rad/s
    kp: np.ndarray,             # N·m/rad
    kd: np.ndarray,             # N·m·s/rad
    torque_limit: np.ndarray,   # N·m
    friction: float,            # N·m, Coulomb joint friction
    tau_ff: np.ndarray | float = 0.0,  # N·m, feed-forward
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The velocity-motor command that steps the PD law implicitly (see the module doc):
    (target velocity rad/s, largest motor force N·m, the PD torque N·m clipped to the limit).

    The target is where ``kp (q_target - q) + tau_ff - kd v`` equals the friction (zero
    inside the friction band: the joint sticks); the force bound is the PD torque's
    magnitude plus the friction, so a joint held against a load or at rest can use both."""
    drive = kp * (q_target - q) + tau_ff                     # N·m, the PD torque at rest
    tau = np.minimum(np.maximum(drive - kd * dq, -torque_limit), torque_limit)
    kd_safe = np.maximum(kd, 1e-9)
    v_star = np.minimum(np.maximum(drive / kd_safe, -_MAX_TARGET_VELOCITY), _MAX_TARGET_VELOCITY)
    target = np.copysign(np.maximum(np.abs(v_star) - friction / kd_safe, 0.0), v_star)
    return target, np.abs(tau) + friction, tau
