"""Kinematics of the project's quadrupeds with Pinocchio: model loading, joint mapping, FK, IK.

>>> from virl_quad import robots
>>> from virl_quad.kinematics import Kinematics
>>> kin = Kinematics(robots.get("pupper"))
>>> feet = kin.foot_positions([0, 0, 0.17], [0, 0, 0, 1], robots.get("pupper").default_pose)
>>> q, residual = kin.leg_ik(feet, [0, 0, 0.17], [0, 0, 0, 1])

Units: m, rad; quaternions xyzw; joint arrays in the canonical order
FR, FL, RR, RL x (abduction, hip, knee). See :mod:`virl_quad.kinematics.model`
for the frame conventions.
"""

from virl_quad.kinematics.frames import (
    laikago_clip_root_to_zup,
    quat_to_matrix,
    to_body,
    to_world,
)
from virl_quad.kinematics.ik import ik_trajectory, leg_ik
from virl_quad.kinematics.model import Kinematics, joint_limit_violation

__all__ = [
    "Kinematics",
    "leg_ik",
    "ik_trajectory",
    "joint_limit_violation",
    "laikago_clip_root_to_zup",
    "quat_to_matrix",
    "to_body",
    "to_world",
]
