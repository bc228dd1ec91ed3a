"""Unitree Laikago constants (URDF from pybullet_data, figures from ROBOTS.md).

URDF variant: ``laikago/laikago_toes_zup_lores.urdf``. z-up base frame (no spawn
rotation to carry around), and low-resolution visual meshes: a 48x48 render
costs about 0.6 ms against 5 ms for the full meshes, and every control step
renders. Its joints are ``continuous`` (no limits), so the limits below come
from ``laikago_toes_limits.urdf``, whose joint frames are the same; the
environment enforces them. Joint angles follow the URDF, which is offset from
motion_imitation's motor angles by (0, -0.6, +0.66) rad per leg: the
"(0, 0.67, -1.25)" standing pose there is (0, 0.07, -0.59) here.
"""

from __future__ import annotations

from virl_quad.robots.spec import LEGS, LegGeometry, RobotSpec, per_leg

_FRONT_X, _REAR_X, _HIP_Y, _HIP_Z = 0.199095, -0.238195, 0.0817145, -0.03   # m, abduction joint origins (URDF)
#: Leg chain at zero joint angles, from the URDF's joint origins expressed in the base frame
#: (each abduction joint frame is rotated by rpy (pi/2, 0, pi/2): its x is the body y, its y the
#: body z, its z the body x). The right legs' abduction axis is -x (URDF axis 0 0 -1), the left
#: legs' +x; hip and knee axes are +y. The right and left legs are not mirror images: the upper
#: leg sits 0.053565 m out on the right, 0.055855 m on the left, and the knee 0.02069 m back in.
LEG = LegGeometry(
    abduction_origin=[[_FRONT_X, -_HIP_Y, _HIP_Z], [_FRONT_X, _HIP_Y, _HIP_Z],
                      [_REAR_X, -_HIP_Y, _HIP_Z], [_REAR_X, _HIP_Y, _HIP_Z]],                         # m
    abduction_sign=[-1.0, 1.0, -1.0, 1.0],
    hip_from_abduction=[[0.0, -0.053565, 0.0], [0.0, 0.055855, 0.0]] * 2,                          # m
    knee_from_hip=[[-0.1422, 0.02069, -0.20833], [-0.1422, -0.02069, -0.20833]] * 2,               # m
    foot_from_knee=[[-0.022, 0.0, -0.25]] * 4,                                                       # m (toe)
)

SPEC = RobotSpec(
    name="laikago",
    urdf="laikago/laikago_toes_zup_lores.urdf",
    urdf_in_pybullet_data=True,
    joint_names=tuple(
        f"{leg}_{j}" for leg in LEGS
        for j in ("hip_motor_2_chassis_joint", "upper_leg_2_hip_motor_joint", "lower_leg_2_upper_leg_joint")
    ),
    foot_links=tuple(f"toe{leg}" for leg in LEGS),
    foot_radius=0.03,                                   # m, toe sphere
    contact_fall_links=("chassis",) + tuple(f"{leg}_upper_leg" for leg in LEGS),
    default_pose=per_leg(0.0, 0.07, -0.59),             # rad (URDF angles)
    joint_lower=per_leg(-0.873, -1.3, -2.164),          # rad (limits URDF)
    joint_upper=per_leg(1.0472, 3.4, 0.0),              # rad
    torque_limit=per_leg(35.0, 35.0, 35.0),             # N·m
    velocity_limit=per_leg(20.0, 20.0, 20.0),           # rad/s
    kp=per_leg(220.0, 220.0, 220.0),                    # N·m/rad (motion_imitation)
    kd=per_leg(0.3, 2.0, 2.0),                          # N·m·s/rad
    joint_damping=0.0,                                  # N·m·s/rad
    joint_friction=0.0,                                 # N·m
    total_mass=25.567,                                  # kg: 13.715 + 4 x (1.095 + 1.527 + 0.241 + 0.1)
    spawn_height=0.486,                                 # m, toes touch the ground in the default pose
    sim_dt=0.002,                                       # s
    substeps=15,                                        # -> 33.3 Hz policy (motion_imitation: ~30 Hz)
    tracker_gain=0.0,                                   # its 220 N·m/rad PD follows the gait prior open-loop;
                                                        # feedback on top of it topples the robot under latency,
    tracker_lead=0.04,                                  # s
    tracker_noise=0.0,                                  # and so does 0.1 action units (6.6 N·m) of noise
    action_scale=0.3,                                   # rad per unit action
    max_roll=0.6,                                       # rad
    max_pitch=0.6,                                      # rad
    min_base_height=0.2,                                # m
    camera_distance=1.6,                                # m
    camera_height=0.0,                                  # m
    camera_yaw=0.0,                                     # deg: side view
    camera_pitch=-15.0,                                 # deg
    episode_seconds=10.0,
    leg=LEG,
    notes="pybullet_data laikago_toes_zup_lores.urdf; limits from laikago_toes_limits.urdf.",
)
