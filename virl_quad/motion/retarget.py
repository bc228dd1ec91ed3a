"""Retargeting: play one robot's motion (e.g. a Laikago dog clip) on another robot by its feet.

For every keyframe the source feet are expressed in the source base frame, relative to
their hips' default-pose foot spot, and scaled by ``k`` = target leg length / source leg
length (hip pitch joint -> knee -> foot, from the URDFs). Heights are scaled about the
ground: a foot ``h`` m above the ground (sphere bottom) becomes ``k h`` above it, and the
target base is put so that its hips stand ``k`` times as high above the ground (foot
sphere centre level) as the source hips. The root's horizontal path is scaled by ``k``
(so strides keep their proportion to the legs), its orientation and the timing are kept.
The target joint angles then come from Pinocchio leg IK (joint limits kept), each frame
starting from the previous solution.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from virl_quad import robots
from virl_quad.motion.gaits import world_to_base
from virl_quad.motion.motion import Motion
from virl_quad.policy.legs import leg_length


def retarget_with_residual(motion: Motion, target: str, source: str | None = None) -> tuple[Motion, np.ndarray]:
    """Retarget ``motion`` (of robot ``source``, default ``motion.robot``) to robot ``target``.

    Returns the new motion and the IK residual per keyframe and foot, (N, 4) m.
    """
    from virl_quad.kinematics import Kinematics

    source = source or motion.robot
    if not source:
        raise ValueError("retargeting needs the source robot (motion.robot is empty)")
    src_spec, tgt_spec = robots.get(source), robots.get(target)
    src, tgt = Kinematics(src_spec), Kinematics(tgt_spec)
    k = leg_length(tgt_spec) / leg_length(src_spec)                               # stride scale
    hips_s, hips_t = src.hip_positions(), tgt.hip_positions()                      # (4, 3) base frame
    spot_s = src.foot_positions(None, None, src_spec.default_pose) - hips_s        # default foot - hip
    spot_t = tgt.foot_positions(None, None, tgt_spec.default_pose) - hips_t
    rot = Rotation.from_quat(motion.root_quat)
    mats = rot.as_matrix()                                                          # (N, 3, 3)
    feet_s_body = src.foot_positions_batch(motion.q)                               # (N, 4, 3)
    feet_s = np.einsum("nij,nkj->nki", mats, feet_s_body) + motion.root_pos[:, None, :]
    # Horizontal: foot offset from its default spot, in the base frame, scaled by k.
    feet_t_body = hips_t + spot_t + k * (feet_s_body - hips_s - spot_s)
    # Vertical: heights above the ground scaled by k.
    hip_z_s = motion.root_pos[:, 2] + np.einsum("nj,kj->nk", mats[:, 2, :], hips_s).mean(axis=1)
    hip_z_t = tgt_spec.foot_radius + k * (hip_z_s - src_spec.foot_radius)
    root_z = hip_z_t - np.einsum("nj,kj->nk", mats[:, 2, :], hips_t).mean(axis=1)
    root = np.column_stack([k * motion.root_pos[:, :2], root_z])
    feet_t = np.einsum("nij,nkj->nki", mats, feet_t_body) + root[:, None, :]
    feet_t[..., 2] = tgt_spec.foot_radius + k * (feet_s[..., 2] - src_spec.foot_radius)
    body = world_to_base(feet_t, root, motion.root_quat)
    q0, _ = tgt.leg_ik(body[0], q_init=tgt_spec.default_pose, frame="body", max_iters=200)
    q, residual = tgt.ik_trajectory(body, q_init=q0, frame="body", max_iters=100)
    out = Motion(frame_duration=motion.frame_duration, root_pos=root, root_quat=motion.root_quat, q=q,
                 loop=motion.loop, cycle_offset_position=motion.cycle_offset_position,
                 cycle_offset_rotation=motion.cycle_offset_rotation, robot=target,
                 name=f"{motion.name} ({source}->{target})")
    return out, residual


def retarget(motion: Motion, target: str, source: str | None = None) -> Motion:
    """Retarget ``motion`` to robot ``target`` (see module doc); identity when the robots match."""
    if (source or motion.robot) == target:
        return motion
    return retarget_with_residual(motion, target, source)[0]
