"""Stanford Pupper v2 constants (figures from ROBOTS.md; URDF in ``robots/pupper/``)."""

from __future__ import annotations

from virl_quad.robots.spec import LEGS, ROBOTS_DIR, LegGeometry, RobotSpec, per_leg

#: Leg chain at zero joint angles (ROBOTS.md; robots/pupper/pupper.urdf): abduction joints at
#: x +-0.10 m, y +-0.04 m; the upper leg 0.02 m further out; upper leg 0.08 m and lower leg
#: 0.11 m straight down; all three axes positive (abduction +x, hip and knee +y).
LEG = LegGeometry(
    abduction_origin=[[0.10, -0.04, 0.0], [0.10, 0.04, 0.0], [-0.10, -0.04, 0.0], [-0.10, 0.04, 0.0]],  # m
    abduction_sign=[1.0, 1.0, 1.0, 1.0],
    hip_from_abduction=[[0.0, -0.02, 0.0], [0.0, 0.02, 0.0], [0.0, -0.02, 0.0], [0.0, 0.02, 0.0]],     # m
    knee_from_hip=[[0.0, 0.0, -0.08]] * 4,                                                              # m
    foot_from_knee=[[0.0, 0.0, -0.11]] * 4,                                                             # m
)

SPEC = RobotSpec(
    name="pupper",
    urdf=str(ROBOTS_DIR / "pupper" / "pupper.urdf"),
    urdf_in_pybullet_data=False,
    joint_names=tuple(f"{leg}_{j}_joint" for leg in LEGS for j in ("abduction", "hip", "knee")),
    foot_links=tuple(f"{leg}_foot" for leg in LEGS),
    foot_radius=0.013,                                  # m
    contact_fall_links=("base_link",) + tuple(f"{leg}_upper_leg" for leg in LEGS),
    default_pose=per_leg(0.0, 0.6, -1.2),               # rad, puppersim's initial pose
    joint_lower=per_leg(-0.6, -0.6, -2.6),              # rad
    joint_upper=per_leg(0.6, 1.8, -0.2),                # rad
    torque_limit=per_leg(1.7, 1.7, 1.7),                # N·m
    velocity_limit=per_leg(25.0, 25.0, 25.0),           # rad/s
    kp=per_leg(4.0, 4.0, 4.0),                          # N·m/rad
    kd=per_leg(0.4, 0.4, 0.4),                          # N·m·s/rad
    joint_damping=0.0045,                               # N·m·s/rad
    joint_friction=0.021,                               # N·m
    total_mass=2.135,                                   # kg: 0.991 + 4 x (0.106 + 0.142 + 0.038)
    spawn_height=0.17,                                  # m, feet touch the ground in the default pose
    sim_dt=0.002,                                       # s (the implicit PD, virl_quad/sim/pd.py; the explicit
                                                        # one on a 38 g shank needs 0.001)
    substeps=10,                                        # -> 50 Hz policy
    action_scale=0.5,                                   # rad per unit action: +-1.0 rad at the env's clip of 2,
                                                        # to reach the built-in gaits' joint range (knee down to
                                                        # -0.73 rad from the default pose) and to overshoot the weak PD
    max_roll=0.4,                                       # rad (puppersim)
    max_pitch=0.4,                                      # rad
    min_base_height=0.05,                               # m
    camera_distance=0.6,                                # m
    camera_height=0.0,                                  # m
    camera_yaw=0.0,                                     # deg: side view from the right, robot walks left to right
    camera_pitch=-15.0,                                 # deg
    leg=LEG,
    randomization={
        # s, observation delay: the HAL applies the command computed from a period's state in that
        # period (it waits up to half a period for it) or in the next one, and damps after three
        # without (deploy/PROTOCOL.md section 8): at most one control period, 20 ms. DRConfig's
        # 0-40 ms is motion_imitation's Laikago figure at 30 Hz.
        "latency": (0.0, 0.02),
    },
    notes="Own URDF generated from public figures; implicit PD at 500 Hz, policy at 50 Hz.",
)
