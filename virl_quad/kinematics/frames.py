"""Rotation helpers (numpy only) and the Laikago clip root convention.

Quaternions are ``(x, y, z, w)`` everywhere, as in PyBullet and in Pinocchio's
free-flyer configuration. Rotation matrices map body coordinates to world
coordinates: ``p_world = R @ p_body + base_pos``.
"""

from __future__ import annotations

import numpy as np

IDENTITY_QUAT = np.array([0.0, 0.0, 0.0, 1.0])


def normalize_quat(quat) -> np.ndarray:
    """Unit quaternion(s) ``(..., 4)`` xyzw; raises on a zero or non-finite quaternion."""
    q = np.asarray(quat, dtype=np.float64)
    if q.shape[-1] != 4:
        raise ValueError(f"quaternion must have 4 components (x, y, z, w), got shape {q.shape}")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)) or np.any(n < 1e-12):
        raise ValueError("quaternion must be finite and non-zero")
    return q / n


def quat_to_matrix(quat) -> np.ndarray:
    """Rotation matrix (..., 3, 3), body -> world, of quaternion(s) xyzw (normalised first)."""
    x, y, z, w = np.moveaxis(normalize_quat(quat), -1, 0)
    r = np.empty(x.shape + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - z * w)
    r[..., 0, 2] = 2 * (x * z + y * w)
    r[..., 1, 0] = 2 * (x * y + z * w)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - x * w)
    r[..., 2, 0] = 2 * (x * z - y * w)
    r[..., 2, 1] = 2 * (y * z + x * w)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` of xyzw quaternions (rotation b first, then a)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def quat_conjugate(q) -> np.ndarray:
    """Inverse of unit quaternion(s) xyzw."""
    q = np.asarray(q, dtype=np.float64)
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """xyzw quaternion of R = Rz(yaw) Ry(pitch) Rx(roll) (PyBullet's getQuaternionFromEuler)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


def random_quat(rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Uniformly distributed random unit quaternion(s) xyzw."""
    q = rng.normal(size=(4,) if n is None else (n, 4))
    return normalize_quat(q)


def to_body(points_world, base_pos, base_quat) -> np.ndarray:
    """World points (..., 3) -> base frame: ``R^T (p - base_pos)`` (leading dimensions broadcast)."""
    r = quat_to_matrix(base_quat)
    d = np.asarray(points_world, dtype=np.float64) - np.asarray(base_pos, dtype=np.float64)
    return np.einsum("...ji,...j->...i", r, d)


def to_world(points_body, base_pos, base_quat) -> np.ndarray:
    """Base-frame points (..., 3) -> world: ``R p + base_pos`` (leading dimensions broadcast)."""
    r = quat_to_matrix(base_quat)
    p = np.einsum("...ij,...j->...i", r, np.asarray(points_body, dtype=np.float64))
    return p + np.asarray(base_pos, dtype=np.float64)


# -- Laikago: motion_imitation clips -> the z-up URDF ------------------------------------------
#: Orientation of ``laikago_toes_limits.urdf``'s chassis frame in the z-up chassis frame:
#: motion_imitation spawns that URDF with Euler(pi/2, 0, pi/2) to stand it upright.
LIMITS_URDF_BASE_IN_ZUP = quat_from_euler(np.pi / 2, 0.0, np.pi / 2)


def laikago_clip_root_to_zup(root_pos, root_quat) -> tuple[np.ndarray, np.ndarray]:
    """Convert a motion_imitation Laikago root pose to the base pose of the z-up URDF.

    Clip roots are PyBullet base poses of ``laikago_toes_limits.urdf``, i.e. the
    pose of that chassis' inertial frame (origin (0, 0.03, 0.043794) m in its
    link frame, no rotation). That point is the z-up chassis link origin, so the
    position is unchanged; the orientation loses the Euler(pi/2, 0, pi/2) spawn
    rotation. Joint angles need no change (same joint frames; the check
    ``python -m virl_quad.check --robot laikago`` verifies both claims on toe
    positions in PyBullet). Works on (3,)/(4,) or batched (T, 3)/(T, 4) arrays.
    """
    pos = np.asarray(root_pos, dtype=np.float64).copy()
    quat = quat_multiply(normalize_quat(root_quat), quat_conjugate(LIMITS_URDF_BASE_IN_ZUP))
    return pos, quat
