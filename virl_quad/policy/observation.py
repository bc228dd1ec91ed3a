"""The one policy-observation builder, used by training AND deployment.

Everything here must be measurable on the real robot: IMU orientation and gyro, joint
encoders, the previous action, the heading relative to the episode's start and (with a
trajectory generator or a demonstration) the phase of the policy's clock. Mismatched
observations between simulation and robot are the classic sim-to-real bug, so the
policy server calls :func:`policy_observation` too, and the exported metadata records
:func:`policy_layout`.

Heading: the base's yaw minus the yaw at the episode's start, as (sin, cos). The env
takes the start yaw at reset; the policy server at the first state the HAL flags ACTIVE.
"""

from __future__ import annotations

import math

import numpy as np

from virl_quad.robots.spec import RobotSpec

ANG_VEL_SCALE = 0.25   # observation = 0.25 * gyro (rad/s)
JOINT_VEL_SCALE = 0.05  # observation = 0.05 * dq (rad/s)
LIN_VEL_SCALE = 2.0    # privileged observation = 2.0 * base velocity (m/s)
ACTION_SIZES = (12, 14)  # joint offsets; with a trajectory generator + 2 modulation entries


def projected_gravity(quat_xyzw: np.ndarray) -> np.ndarray:
    """Unit gravity direction in the body frame, from the IMU orientation (xyzw, unit norm).

    ``R^T (0, 0, -1)``: minus the third row of the rotation matrix, written out (this runs
    in every control step; tested against scipy)."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=np.float64).tolist()
    return np.array([2.0 * (w * y - x * z), -2.0 * (y * z + w * x), 2.0 * (x * x + y * y) - 1.0])


def yaw(quat_xyzw: np.ndarray) -> float:
    """Yaw (rad, (-pi, pi]) of an orientation xyzw: the z angle of its z-y-x Euler angles."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=np.float64).tolist()
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def policy_layout(with_phase: bool, action_size: int = 12) -> list[tuple[str, int, float]]:
    """(name, size, scale) of each block of the policy observation, in order.

    ``action_size``: 12, or 14 with a trajectory generator (its last action includes the
    two modulation entries)."""
    if action_size not in ACTION_SIZES:
        raise ValueError(f"action size must be one of {ACTION_SIZES}, got {action_size}")
    layout = [
        ("projected_gravity", 3, 1.0),
        ("heading_sin_cos", 2, 1.0),               # yaw - start yaw, rad
        ("base_ang_vel_body", 3, ANG_VEL_SCALE),   # rad/s
        ("joint_pos_minus_default", 12, 1.0),      # rad
        ("joint_vel", 12, JOINT_VEL_SCALE),        # rad/s
        ("last_action", action_size, 1.0),
    ]
    if with_phase:
        layout.append(("phase_sin_cos", 2, 1.0))   # the policy clock's phase, cycles
    return layout


def policy_block(name: str, with_phase: bool = True, action_size: int = 12) -> slice:
    """Where the block ``name`` of :func:`policy_layout` lies in the policy observation."""
    start = 0
    for block, size, _ in policy_layout(with_phase, action_size):
        if block == name:
            return slice(start, start + size)
        start += size
    raise KeyError(f"no block {name!r} in the policy observation")


def policy_size(with_phase: bool, action_size: int = 12) -> int:
    """Length of the policy observation."""
    return sum(n for _, n, _ in policy_layout(with_phase, action_size))


def policy_observation(spec: RobotSpec, quat_xyzw: np.ndarray, gyro_body: np.ndarray, q: np.ndarray,
                       dq: np.ndarray, last_action: np.ndarray, phase: float | None = None,
                       start_yaw: float = 0.0) -> np.ndarray:
    """Build the float32 policy observation from robot measurements.

    quat_xyzw: base orientation (IMU); gyro_body: rad/s in the body frame;
    q: rad, dq: rad/s (canonical order); last_action: the policy's previous
    output, clipped, unscaled (12 or 14 entries); phase: the policy clock's phase
    in [0, 1) or None; start_yaw: rad, the yaw at the episode's start.
    Raises ValueError on NaN/inf input or wrong sizes.
    """
    quat, gyro = np.asarray(quat_xyzw, dtype=np.float64), np.asarray(gyro_body, dtype=np.float64)
    q, dq, act = (np.asarray(x, dtype=np.float64) for x in (q, dq, last_action))
    sizes = [quat.size, gyro.size, q.size, dq.size]
    if sizes != [4, 3, 12, 12] or act.size not in ACTION_SIZES:
        raise ValueError(f"observation inputs (quat, gyro, q, dq, last_action) have sizes {sizes + [act.size]}, "
                         f"expected [4, 3, 12, 12, 12 or 14]")
    heading = yaw(quat) - start_yaw
    if not math.isfinite(heading):                     # math.sin(inf) would raise another error
        raise ValueError("observation contains NaN or inf")
    parts = [projected_gravity(quat), (math.sin(heading), math.cos(heading)), gyro * ANG_VEL_SCALE,
             q - spec.default_pose, dq * JOINT_VEL_SCALE, act]
    if phase is not None:
        angle = 2.0 * math.pi * phase
        parts.append((math.sin(angle), math.cos(angle)))
    obs = np.concatenate(parts, dtype=np.float32)
    if not math.isfinite(obs.sum(dtype=np.float64)):   # a float64 sum of float32 values is finite iff all are
        raise ValueError("observation contains NaN or inf")
    return obs
