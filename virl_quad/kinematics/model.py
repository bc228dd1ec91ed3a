"""Pinocchio model of one robot, with the canonical <-> Pinocchio joint mapping and foot FK.

``Kinematics`` keeps the model (the description: ``self.model``) apart from its
buffers (``self.data``). A placement is named by its frame: ``data.oMf[f]`` is
frame ``f`` in the world (or in the base frame for a fixed-base model).

Conventions
-----------
- Lengths in m, angles in rad. Quaternions xyzw (PyBullet's and Pinocchio's order).
- ``q12``: the 12 joint angles in the project's canonical order FR, FL, RR, RL x
  (abduction, hip, knee), the angles of the URDF joints (as PyBullet reads them).
- ``base_pos`` / ``base_quat``: the pose of the URDF base link frame in the world.
  It equals PyBullet's base pose (``World.state().base_pos/base_quat``) when the base
  link's inertial origin is at the link origin, true for both project robots (the
  check ``python -m virl_quad.check`` verifies it).
- Base ("body") frame: the URDF base link frame, x forward, y left, z up.
- Feet: the origins of the foot link frames (the foot sphere centres), not the
  contact points (those are ``foot_radius`` lower on flat ground).
- Pinocchio orders joints by its own tree traversal (Laikago: FL, FR, RL, RR) and
  represents ``continuous`` joints with two numbers (cos, sin); joints are mapped
  by URDF name, never by index.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from virl_quad.kinematics.frames import IDENTITY_QUAT, normalize_quat, quat_to_matrix, to_world
from virl_quad.robots.spec import NUM_JOINTS, RobotSpec

_TWO_PI = 2.0 * np.pi


class Kinematics:
    """Forward kinematics, foot Jacobians, joint limits and leg IK of one robot.

    ``floating_base=True`` builds the model with a free-flyer root joint
    (configuration: position xyz, quaternion xyzw, then the joints), so world
    poses go through Pinocchio itself; ``False`` builds a fixed-base model
    (configuration: the joints only, world = base frame).
    """

    def __init__(self, spec: RobotSpec, floating_base: bool = True, urdf_path: str | None = None) -> None:
        self.spec = spec
        self.urdf_path = urdf_path or spec.urdf_path
        self.floating_base = floating_base
        if floating_base:
            self.model = pin.buildModelFromUrdf(self.urdf_path, pin.JointModelFreeFlyer())
        else:
            self.model = pin.buildModelFromUrdf(self.urdf_path)
        self.data = self.model.createData()
        m = self.model
        missing = [n for n in spec.joint_names if not m.existJointName(n)]
        if missing:
            raise ValueError(f"{self.urdf_path}: Pinocchio model lacks joints {missing}")
        #: Pinocchio joint id, first configuration index, nq (1 revolute, 2 continuous), velocity index.
        ids = [int(m.getJointId(n)) for n in spec.joint_names]
        self.joint_ids = np.array(ids)
        self.idx_q = np.array([m.idx_qs[j] for j in ids])
        self.nq = np.array([m.nqs[j] for j in ids])
        self.idx_v = np.array([m.idx_vs[j] for j in ids])
        bad = [spec.joint_names[i] for i, j in enumerate(ids)
               if m.nvs[j] != 1 or m.nqs[j] not in (1, 2)]
        if bad:
            raise ValueError(f"{self.urdf_path}: joints {bad} are not revolute/continuous (1 DOF)")
        self.continuous = self.nq == 2
        self._iq1 = self.idx_q[~self.continuous]
        self._iq2 = self.idx_q[self.continuous]
        missing = [n for n in spec.foot_links if not m.existFrame(n, pin.BODY)]
        if missing:
            raise ValueError(f"{self.urdf_path}: Pinocchio model lacks foot links {missing}")
        self.foot_frame_ids = [m.getFrameId(n, pin.BODY) for n in spec.foot_links]
        self.lower = np.asarray(spec.joint_lower, dtype=np.float64)
        self.upper = np.asarray(spec.joint_upper, dtype=np.float64)
        self._neutral = pin.neutral(m)
        self._base_nq = 7 if floating_base else 0

    # -- configuration mapping -----------------------------------------------------------------
    def q_pin(self, base_pos=None, base_quat=None, q12=None) -> np.ndarray:
        """Pinocchio configuration (``model.nq``) from a base pose and canonical angles (rad).

        ``base_pos``/``base_quat`` default to the origin/identity; a fixed-base model
        accepts no base pose. ``q12`` defaults to zeros.
        """
        q = self._neutral.copy()
        if self.floating_base:
            q[:3] = 0.0 if base_pos is None else np.asarray(base_pos, dtype=np.float64)
            q[3:7] = IDENTITY_QUAT if base_quat is None else normalize_quat(base_quat)
        elif base_pos is not None or base_quat is not None:
            raise ValueError("a fixed-base model takes no base pose")
        if q12 is not None:
            a = np.asarray(q12, dtype=np.float64)
            if a.shape != (NUM_JOINTS,):
                raise ValueError(f"q12 must have shape (12,), got {a.shape}")
            q[self._iq1] = a[~self.continuous]
            q[self._iq2] = np.cos(a[self.continuous])
            q[self._iq2 + 1] = np.sin(a[self.continuous])
        return q

    def q12(self, q_pin: np.ndarray) -> np.ndarray:
        """Canonical angles (rad) from a Pinocchio configuration.

        A continuous joint's (cos, sin) gives an angle only modulo 2 pi: it is taken in
        ``[lower, lower + 2 pi)``, the one representative that can lie within the limits.
        """
        q_pin = np.asarray(q_pin, dtype=np.float64)
        out = np.empty(NUM_JOINTS)
        out[~self.continuous] = q_pin[self._iq1]
        ang = np.arctan2(q_pin[self._iq2 + 1], q_pin[self._iq2])
        lo = self.lower[self.continuous]
        out[self.continuous] = lo + np.mod(ang - lo, _TWO_PI)
        return out

    def base_pose(self, q_pin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Base position (m) and quaternion xyzw of a floating-base configuration."""
        if not self.floating_base:
            return np.zeros(3), IDENTITY_QUAT.copy()
        return np.array(q_pin[:3]), np.array(q_pin[3:7])

    # -- forward kinematics ------------------------------------------------------------------------
    def foot_positions(self, base_pos, base_quat, q12) -> np.ndarray:
        """World positions (m) of the 4 foot frames, (4, 3), FR FL RR RL.

        ``base_pos=None, base_quat=None`` gives base-frame positions.
        """
        if self.floating_base:
            q = self.q_pin(base_pos, base_quat, q12)
            pin.framesForwardKinematics(self.model, self.data, q)
            return np.array([self.data.oMf[f].translation for f in self.foot_frame_ids])
        body = self.foot_positions_body(q12)
        if base_pos is None and base_quat is None:
            return body
        return to_world(body, np.zeros(3) if base_pos is None else base_pos,
                        IDENTITY_QUAT if base_quat is None else base_quat)

    def foot_positions_body(self, q12) -> np.ndarray:
        """Base-frame positions (m) of the 4 foot frames, (4, 3)."""
        pin.framesForwardKinematics(self.model, self.data, self.q_pin(q12=q12))
        return np.array([self.data.oMf[f].translation for f in self.foot_frame_ids])

    def foot_positions_batch(self, q12, base_pos=None, base_quat=None) -> np.ndarray:
        """Foot positions (m) for a trajectory: q12 (T, 12), base (T, 3)/(T, 4) or None -> (T, 4, 3)."""
        q12 = np.asarray(q12, dtype=np.float64).reshape(-1, NUM_JOINTS)
        body = np.stack([self.foot_positions_body(q) for q in q12])
        if base_pos is None and base_quat is None:
            return body
        n = len(q12)
        pos = np.zeros((n, 3)) if base_pos is None else np.broadcast_to(base_pos, (n, 3))
        quat = np.tile(IDENTITY_QUAT, (n, 1)) if base_quat is None else np.broadcast_to(base_quat, (n, 4))
        return np.einsum("tij,tkj->tki", quat_to_matrix(quat), body) + pos[:, None, :]

    def foot_jacobians(self, q12) -> tuple[np.ndarray, np.ndarray]:
        """Base-frame foot positions (4, 3) and per-leg Jacobians (4, 3, 3) = d p_foot / d q_leg (m/rad).

        ``J[leg][:, j]`` is the derivative with respect to joint ``j`` (abduction, hip, knee)
        of that leg; a leg's foot does not depend on the other legs' joints.
        """
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d, self.q_pin(q12=q12))
        pin.updateFramePlacements(m, d)
        pos = np.empty((4, 3))
        jac = np.empty((4, 3, 3))
        for leg, f in enumerate(self.foot_frame_ids):
            pos[leg] = d.oMf[f].translation
            full = pin.getFrameJacobian(m, d, f, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            jac[leg] = full[:3, self.idx_v[3 * leg:3 * leg + 3]]
        return pos, jac

    def hip_positions(self) -> np.ndarray:
        """Base-frame positions (m) of the 4 abduction joint origins, (4, 3) (they do not move)."""
        pin.forwardKinematics(self.model, self.data, self.q_pin())
        return np.array([self.data.oMi[int(j)].translation for j in self.joint_ids[0::3]])

    def joint_axes(self, q12=None) -> np.ndarray:
        """Joint axes (12, 3), unit vectors in the base frame at ``q12`` (default zeros)."""
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d, self.q_pin(q12=q12))
        axes = np.empty((NUM_JOINTS, 3))
        for i, (jid, iv) in enumerate(zip(self.joint_ids, self.idx_v)):
            axes[i] = pin.getJointJacobian(m, d, int(jid), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[3:, iv]
        return axes

    # -- joint limits ----------------------------------------------------------------------------
    def limit_violation(self, q12) -> np.ndarray:
        """How far (rad, >= 0) each angle lies outside the spec's limits; shape of ``q12`` (..., 12)."""
        q = np.asarray(q12, dtype=np.float64)
        return np.maximum(self.lower - q, 0.0) + np.maximum(q - self.upper, 0.0)

    def within_limits(self, q12, tol: float = 1e-9) -> bool:
        """True when every angle of ``q12`` (..., 12) lies within the limits (+- ``tol`` rad)."""
        return bool(np.all(self.limit_violation(q12) <= tol))

    def clip(self, q12) -> np.ndarray:
        """Clamp angles (rad) to the limits."""
        return np.clip(np.asarray(q12, dtype=np.float64), self.lower, self.upper)

    # -- inverse kinematics (see virl_quad.kinematics.ik) ----------------------------------------
    def leg_ik(self, foot_targets, base_pos=None, base_quat=None, q_init=None, **kwargs):
        """Joint angles placing the feet on targets; see :func:`virl_quad.kinematics.ik.leg_ik`."""
        from virl_quad.kinematics.ik import leg_ik

        return leg_ik(self, foot_targets, base_pos, base_quat, q_init, **kwargs)

    def ik_trajectory(self, foot_targets, base_pos=None, base_quat=None, q_init=None, **kwargs):
        """IK over a trajectory; see :func:`virl_quad.kinematics.ik.ik_trajectory`."""
        from virl_quad.kinematics.ik import ik_trajectory

        return ik_trajectory(self, foot_targets, base_pos, base_quat, q_init, **kwargs)


def joint_limit_violation(spec: RobotSpec, q12) -> np.ndarray:
    """How far (rad, >= 0) angles ``q12`` (..., 12) lie outside ``spec``'s joint limits."""
    q = np.asarray(q12, dtype=np.float64)
    return np.maximum(np.asarray(spec.joint_lower) - q, 0.0) + np.maximum(q - np.asarray(spec.joint_upper), 0.0)
