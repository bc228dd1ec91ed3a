"""What may reach a motor: the safety layer's tunables and its pure checks (no state, no clock).

:class:`SafetyConfig` holds the limits; :func:`is_safe_command` judges an outgoing command,
:func:`command_error` an incoming one and :func:`state_fault` a measured state;
:func:`limits` lists the limits for the ANNOUNCE. :mod:`virl_quad.deploy.safety` applies them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from virl_quad.deploy.protocol import NUM_JOINTS, JointCommand, RobotState
from virl_quad.robots.spec import MAX_TARGET_STEP, RAMP_TIME

_EPS = 1e-9


@dataclass(frozen=True)
class SafetyConfig:
    """Tunables of the safety layer (the watchdog and the step limit count control periods)."""

    ramp_time: float = RAMP_TIME       # s, from the current pose to the default pose
    watchdog_periods: int = 3          # ACTIVE: more periods than this without a valid command -> DAMPING
    max_step: float = MAX_TARGET_STEP  # rad per control period, change of an applied target (as in training)
    gain_factor: float = 2.0           # kp, kd at most gain_factor x the spec gains
    damping_kd_factor: float = 1.0     # DAMPING kd = damping_kd_factor x spec kd (<= gain_factor)
    tilt_factor: float = 1.0           # fault beyond tilt_factor x spec max_roll / max_pitch
    arm_stamp_window: float = 1.0      # s: an ARM stamped before an E-stop received this recently is cancelled

    def __post_init__(self) -> None:
        if self.ramp_time <= 0 or self.watchdog_periods < 1 or self.max_step <= 0:
            raise ValueError("ramp_time, watchdog_periods and max_step must be positive")
        if not 0 <= self.damping_kd_factor <= self.gain_factor:
            raise ValueError("damping_kd_factor must lie in [0, gain_factor]")
        if self.tilt_factor <= 0:
            raise ValueError("tilt_factor must be positive")
        if self.arm_stamp_window < 0:
            raise ValueError("arm_stamp_window must be >= 0")


def roll_pitch(quat_xyzw: np.ndarray) -> tuple[float, float]:
    """Roll and pitch (rad, ZYX Euler) of a quaternion (x, y, z, w); normalises it first."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=np.float64) / np.linalg.norm(quat_xyzw)
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    return roll, pitch


def is_safe_command(cmd: JointCommand, spec: Any, config: SafetyConfig = SafetyConfig(),
                    prev: JointCommand | None = None) -> bool:
    """True if ``cmd`` may reach a motor: finite, 12 values each, targets within the joint
    limits, 0 <= kp, kd <= gain_factor x spec gains, |tau_ff| <= torque limit, and (if
    ``prev`` is given) no target moved more than ``config.max_step`` rad since ``prev``."""
    try:
        arrays = [np.asarray(a, dtype=np.float64) for a in (cmd.q_target, cmd.kp, cmd.kd, cmd.tau_ff)]
    except (TypeError, ValueError):
        return False
    if any(a.shape != (NUM_JOINTS,) or not np.all(np.isfinite(a)) for a in arrays):
        return False
    q, kp, kd, tau = arrays
    ok = (np.all(q >= spec.joint_lower - _EPS) and np.all(q <= spec.joint_upper + _EPS)
          and np.all(kp >= 0) and np.all(kp <= config.gain_factor * spec.kp + _EPS)
          and np.all(kd >= 0) and np.all(kd <= config.gain_factor * spec.kd + _EPS)
          and np.all(np.abs(tau) <= spec.torque_limit + _EPS))
    if ok and prev is not None:
        ok = bool(np.all(np.abs(q - np.asarray(prev.q_target)) <= config.max_step + _EPS))
    return bool(ok)


#: What each ``clamped`` counter of STATUS means: an accepted command the safety layer changed
#: before applying it, by kind (one count per command, however many joints it touched).
CLAMPS: dict[str, str] = {
    "q_limit": "a joint target outside the joint limits, clipped to them",
    "q_step": "a joint target too far from the last applied one, moved at most max_step (rad) per period",
    "gain": "kp or kd above the allowed maximum, lowered to it",
    "tau_ff": "a feed-forward torque above the motor's limit (N·m), clipped",
}



def command_error(cmd: JointCommand) -> str | None:
    """Why a decoded command must be rejected (``bad_shape``, ``non_finite``, ``negative_gain``), or None."""
    try:
        arrays = [np.asarray(a, dtype=np.float64) for a in (cmd.q_target, cmd.kp, cmd.kd, cmd.tau_ff)]
    except (TypeError, ValueError, AttributeError):
        return "bad_shape"
    if any(a.shape != (NUM_JOINTS,) for a in arrays):
        return "bad_shape"
    if not all(np.all(np.isfinite(a)) for a in arrays):
        return "non_finite"
    if np.any(arrays[1] < 0) or np.any(arrays[2] < 0):
        return "negative_gain"
    return None


def state_fault(state: RobotState | None, spec: Any, config: SafetyConfig) -> str:
    """Why a measured state is a fault in RAMP or ACTIVE (``no_state``, ``bad_state``, ``tilt``), or ""."""
    if state is None:
        return "no_state"
    try:
        q = np.asarray(state.q, dtype=np.float64)
        quat = np.asarray(state.quat, dtype=np.float64)
        if q.shape != (NUM_JOINTS,) or quat.shape != (4,):
            return "bad_state"
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(state.dq)) and np.all(np.isfinite(quat))):
            return "bad_state"
        if not 0.5 < float(np.linalg.norm(quat)) < 1.5:
            return "bad_state"
        roll, pitch = roll_pitch(quat)
    except (TypeError, ValueError, AttributeError):
        return "bad_state"
    tf = config.tilt_factor
    if abs(roll) > tf * spec.max_roll or abs(pitch) > tf * spec.max_pitch:
        return "tilt"
    return ""


def limits(spec: Any, config: SafetyConfig) -> dict[str, Any]:
    """The limits a safety layer with ``config`` enforces on ``spec``'s robot, JSON-ready (the
    ANNOUNCE's ``limits`` member): joint limits (rad), maximum gains (N·m/rad, N·m·s/rad),
    torque limit (N·m), maximum target step (rad per control period), watchdog (control
    periods), tilt limits (rad), the DAMPING gain (N·m·s/rad) and the RAMP time (s)."""
    s, c = spec, config
    as_list = lambda a: np.asarray(a, dtype=np.float64).tolist()  # noqa: E731
    return {
        "q_lower": as_list(s.joint_lower), "q_upper": as_list(s.joint_upper),
        "kp_max": as_list(c.gain_factor * np.asarray(s.kp)), "kd_max": as_list(c.gain_factor * np.asarray(s.kd)),
        "tau_max": as_list(s.torque_limit), "max_step": float(c.max_step),
        "watchdog_periods": int(c.watchdog_periods),
        "max_roll": float(c.tilt_factor * s.max_roll), "max_pitch": float(c.tilt_factor * s.max_pitch),
        "damping_kd": as_list(c.damping_kd_factor * np.asarray(s.kd)), "ramp_time": float(c.ramp_time),
    }
