"""Ground-truth imitation score (evaluation only, never a training reward).

motion_imitation's imitation terms (Peng et al. 2020), each ``exp(-scale * error)`` per step:

============  ======  =====  ================================================================
term          weight  scale  error
============  ======  =====  ================================================================
pose          0.5     5      sum over the 12 joints of (q - q_ref)^2, rad^2
velocity      0.05    0.1    sum over the 12 joints of (dq - dq_ref)^2, (rad/s)^2
end_effector  0.2     40     sum over the 4 feet of |p - p_ref|^2, m^2, where p is the foot frame
                             minus the root, in the root's heading frame (yaw only)
root_pose     0.15    20     (z - z_ref)^2 + 0.5 * angle(R_ref^T R)^2: base height (m) and the
                             full 3D orientation difference (rad)
root_velocity 0.1     2      |v - v_ref|^2 + 0.1 * |w - w_ref|^2, base linear (m/s) and angular
                             (rad/s) velocity, each in its own heading frame
============  ======  =====  ================================================================

``total`` is the weighted sum (1.0 for a perfect match). The rollout's time index is
the demonstration clock (``env.demo_step / demo.fps``); ``total_best_offset`` is the
total at the best constant time shift of the reference (a grid over one cycle), i.e.
the score of doing the right motion out of phase.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from virl_quad import robots

TERMS: dict[str, tuple[float, float]] = {  # name: (weight, scale)
    "pose": (0.5, 5.0),
    "velocity": (0.05, 0.1),
    "end_effector": (0.2, 40.0),
    "root_pose": (0.15, 20.0),
    "root_velocity": (0.1, 2.0),
}
NUM_OFFSETS = 24  # grid size of the phase-offset search over one cycle


@dataclass
class Trajectory:
    """A recorded rollout, one row per step (SI units, world frame, canonical joint order)."""

    root_pos: np.ndarray      # (T, 3) m
    root_quat: np.ndarray     # (T, 4) xyzw
    q: np.ndarray             # (T, 12) rad
    dq: np.ndarray            # (T, 12) rad/s
    root_lin_vel: np.ndarray  # (T, 3) m/s
    root_ang_vel: np.ndarray  # (T, 3) rad/s
    feet: np.ndarray | None = None  # (T, 4, 3) m, foot frames; None: forward kinematics of the poses

    def __len__(self) -> int:
        return len(self.root_pos)


def _headings(quat: np.ndarray) -> np.ndarray:
    """Headings (rad): the yaw of each base x axis on the ground, for quaternions (T, 4) xyzw."""
    x, y, z, w = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    return np.arctan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def _unturn(v: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Vectors (T, ..., 3) in the frame turned by ``heading`` (T,) rad about z (the heading undone)."""
    c, s = np.cos(heading), np.sin(heading)
    c, s = c.reshape(c.shape + (1,) * (v.ndim - 2)), s.reshape(s.shape + (1,) * (v.ndim - 2))
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1)


def _angles(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Angles (rad) of the rotations between unit quaternions (T, 4): 2 atan2(|sin|, |cos|) of half."""
    d = np.abs(np.sum(q1 * q2, axis=1) / (np.linalg.norm(q1, axis=1) * np.linalg.norm(q2, axis=1)))
    return 2.0 * np.arctan2(np.sqrt(np.maximum(0.0, 1.0 - d * d)), d)


def _feet(traj: Trajectory, kin) -> np.ndarray:
    if traj.feet is not None:
        return np.asarray(traj.feet, dtype=np.float64)
    return kin.foot_positions_batch(traj.q, traj.root_pos, traj.root_quat)


def reference_trajectory(motion, times: np.ndarray, kin) -> Trajectory:
    """The motion's states at ``times`` (s) as a :class:`Trajectory` (feet by forward kinematics)."""
    s = motion.sample(times) if hasattr(motion, "sample") else _sample(motion, times)
    traj = Trajectory(root_pos=s["root_pos"], root_quat=s["root_quat"], q=s["q"], dq=s["dq"],
                      root_lin_vel=s["root_lin_vel"], root_ang_vel=s["root_ang_vel"])
    traj.feet = kin.foot_positions_batch(traj.q, traj.root_pos, traj.root_quat)
    return traj


def _sample(motion, times: np.ndarray) -> dict[str, np.ndarray]:
    states = [motion.state_at(float(t)) for t in times]
    keys = ("root_pos", "root_quat", "q", "root_lin_vel", "root_ang_vel", "dq")
    return {k: np.array([getattr(s, k) for s in states]) for k in keys}


def term_errors(traj: Trajectory, ref: Trajectory, kin) -> dict[str, np.ndarray]:
    """Per-step errors (see module doc) of ``traj`` against ``ref`` (same length)."""
    h, h_ref = _headings(np.asarray(traj.root_quat, float)), _headings(np.asarray(ref.root_quat, float))
    local = _unturn(_feet(traj, kin) - traj.root_pos[:, None, :], h)
    local_ref = _unturn(_feet(ref, kin) - ref.root_pos[:, None, :], h_ref)
    angle = _angles(np.asarray(ref.root_quat, float), np.asarray(traj.root_quat, float))
    dv = _unturn(traj.root_lin_vel, h) - _unturn(ref.root_lin_vel, h_ref)
    dw = _unturn(traj.root_ang_vel, h) - _unturn(ref.root_ang_vel, h_ref)
    return {
        "pose": np.sum((traj.q - ref.q) ** 2, axis=1),
        "velocity": np.sum((traj.dq - ref.dq) ** 2, axis=1),
        "end_effector": np.sum((local - local_ref) ** 2, axis=(1, 2)),
        "root_pose": (traj.root_pos[:, 2] - ref.root_pos[:, 2]) ** 2 + 0.5 * angle ** 2,
        "root_velocity": np.sum(dv ** 2, axis=1) + 0.1 * np.sum(dw ** 2, axis=1),
    }


def term_rewards(errors: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-step term rewards exp(-scale * error) and their weighted ``total``."""
    out = {k: np.exp(-TERMS[k][1] * errors[k]) for k in TERMS}
    out["total"] = sum(TERMS[k][0] * out[k] for k in TERMS)
    return out


def offset_grid(motion, num: int = NUM_OFFSETS) -> np.ndarray:
    """Reference time shifts (s) searched for the best phase: one cycle for a loop, +-25 % of a clip."""
    d = float(motion.duration)
    if getattr(motion, "loop", True):
        return np.arange(num) * d / num
    return np.linspace(-0.25 * d, 0.25 * d, num + 1)


def score_trajectory(traj: Trajectory, motion, ref_times: np.ndarray, robot: str,
                     offsets: np.ndarray | None = None, kin=None) -> dict:
    """Score a recorded trajectory against ``motion`` sampled at ``ref_times`` (s, one per row).

    Returns per-step mean term rewards and ``total``, plus ``total_best_offset`` and
    ``best_offset`` (s) over :func:`offset_grid` (or ``offsets``), and the per-step arrays.
    """
    from virl_quad.kinematics import Kinematics

    kin = kin or Kinematics(robots.get(robot))
    ref_times = np.asarray(ref_times, dtype=np.float64)
    if len(ref_times) != len(traj):
        raise ValueError(f"{len(ref_times)} reference times for a trajectory of {len(traj)} steps")
    aligned = term_rewards(term_errors(traj, reference_trajectory(motion, ref_times, kin), kin))
    out = {k: float(np.mean(v)) for k, v in aligned.items()}
    offsets = offset_grid(motion) if offsets is None else np.asarray(offsets, dtype=np.float64)
    totals = [float(np.mean(term_rewards(term_errors(traj, reference_trajectory(motion, ref_times + o, kin),
                                                     kin))["total"])) for o in offsets]
    best = int(np.argmax(totals))
    out["total_best_offset"] = max(totals[best], out["total"])
    out["best_offset"] = float(offsets[best]) if totals[best] > out["total"] else 0.0
    out["per_step"] = aligned
    return out
