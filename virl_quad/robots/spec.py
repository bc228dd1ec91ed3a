"""The robot description shared by simulation, kinematics checks, training and deployment.

A :class:`RobotSpec` is plain, immutable data: no simulator handle, no buffers.
Every array is given in the project's canonical joint order

    FR, FL, RR, RL  x  (abduction, hip, knee)

so index ``3 * leg + j`` is joint ``j`` of leg ``leg``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

LEGS: tuple[str, ...] = ("FR", "FL", "RR", "RL")
#: rad per control period: the largest change of a PD target. The env applies it in training
#: and the deploy safety layer on the robot, so a policy meets the same limit in both.
MAX_TARGET_STEP = 0.2
#: s: the deploy safety layer ramps to the default pose and holds it this long before a policy
#: drives; the env's standing start holds it as long, so a policy meets the same handover.
RAMP_TIME = 2.0
JOINT_KINDS: tuple[str, ...] = ("abduction", "hip", "knee")
NUM_JOINTS: int = 12

#: Top-level folder that holds the project's own URDF files.
ROBOTS_DIR: Path = Path(__file__).resolve().parents[2] / "robots"


def _arr(values: tuple[float, ...] | list[float]) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    a.setflags(write=False)
    return a


def per_leg(abduction: float, hip: float, knee: float) -> np.ndarray:
    """Repeat one leg's (abduction, hip, knee) values for the four legs, canonical order."""
    return _arr([abduction, hip, knee] * 4)


@dataclass(frozen=True)
class LegGeometry:
    """The kinematic chain of the four legs at zero joint angles, in the base frame (m).

    Each leg: an abduction joint whose axis is the body x axis (``abduction_sign`` +1) or
    its opposite (-1), then a hip and a knee joint whose axes are both the body +y axis,
    i.e. an abduction joint carrying a planar two-link leg. Positions are the joint
    origins and the foot frame origin (the foot sphere centre) with every joint at 0 rad;
    arrays are (4, 3) in the canonical leg order FR, FL, RR, RL. Enough for closed-form
    leg forward and inverse kinematics (:mod:`virl_quad.policy.legs`), checked against
    the URDF with Pinocchio in the tests.
    """

    abduction_origin: np.ndarray    # m (4, 3): abduction joint origin in the base frame
    abduction_sign: np.ndarray      # (4,) +1: abduction axis along +x, -1: along -x
    hip_from_abduction: np.ndarray  # m (4, 3): hip joint origin - abduction origin, all joints at 0
    knee_from_hip: np.ndarray       # m (4, 3): knee joint origin - hip joint origin, all joints at 0
    foot_from_knee: np.ndarray      # m (4, 3): foot frame origin - knee joint origin, all joints at 0

    def __post_init__(self) -> None:
        for name in ("abduction_origin", "hip_from_abduction", "knee_from_hip", "foot_from_knee"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (4, 3) or not np.all(np.isfinite(a)):
                raise ValueError(f"LegGeometry.{name} must be finite (4, 3), got shape {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        sign = np.asarray(self.abduction_sign, dtype=np.float64)
        if sign.shape != (4,) or not np.all(np.abs(sign) == 1.0):
            raise ValueError(f"LegGeometry.abduction_sign must be 4 values of +-1, got {sign.tolist()}")
        sign.setflags(write=False)
        object.__setattr__(self, "abduction_sign", sign)

    @property
    def upper_leg_length(self) -> np.ndarray:
        """m (4,): hip joint to knee joint, in the leg plane."""
        return np.hypot(self.knee_from_hip[:, 0], self.knee_from_hip[:, 2])

    @property
    def lower_leg_length(self) -> np.ndarray:
        """m (4,): knee joint to foot, in the leg plane."""
        return np.hypot(self.foot_from_knee[:, 0], self.foot_from_knee[:, 2])


@dataclass(frozen=True)
class RobotSpec:
    """Everything the project needs to know about one quadruped.

    Units: lengths in m, angles in rad, torques in N·m, gains in N·m/rad and
    N·m·s/rad, masses in kg, times in s.
    """

    name: str
    urdf: str                       # absolute path, or a pybullet_data-relative path
    urdf_in_pybullet_data: bool     # True when ``urdf`` is relative to pybullet_data
    joint_names: tuple[str, ...]    # URDF joint names, canonical order (12)
    foot_links: tuple[str, ...]     # URDF link names of the feet, FR, FL, RR, RL
    foot_radius: float              # m, radius of the foot collision sphere
    contact_fall_links: tuple[str, ...]  # links whose ground contact ends an episode
    default_pose: np.ndarray        # rad (12)
    joint_lower: np.ndarray         # rad (12)
    joint_upper: np.ndarray         # rad (12)
    torque_limit: np.ndarray        # N·m (12)
    velocity_limit: np.ndarray      # rad/s (12)
    kp: np.ndarray                  # N·m/rad (12)
    kd: np.ndarray                  # N·m·s/rad (12)
    joint_damping: float            # N·m·s/rad, viscous joint damping
    joint_friction: float           # N·m, Coulomb joint friction
    total_mass: float               # kg, the spec's figure (checked against the URDF)
    spawn_height: float             # m, base height where the default pose's feet touch ground
    sim_dt: float                   # s, physics step
    substeps: int                   # physics steps per control step
    action_scale: float             # rad per unit of action
    max_roll: float                 # rad, termination
    max_pitch: float                # rad, termination
    min_base_height: float          # m, termination
    camera_distance: float          # m, third-person camera distance from the base
    camera_height: float            # m, camera target height above the base
    camera_yaw: float               # deg, 0 = side view from the robot's right, +x to the right of the image
    camera_pitch: float             # deg, negative looks down
    episode_seconds: float = 10.0   # s, time limit of one training episode
    tracker_gain: float = 2.0       # the warm start's tracker of the gait prior (virl_quad.training.warm_start):
                                    # feedback gain on the joint error (a weak PD needs it to follow a gait; a
                                    # stiff one follows open-loop and is destabilised by it under latency),
    tracker_lead: float = 0.08      # s its feed-forward runs ahead of the clock,
    tracker_noise: float = 0.1      # action units, std of the noise on its executed actions while gathering
    leg: LegGeometry | None = None  # leg chain for closed-form leg kinematics (m); None: not described
    notes: str = ""
    randomization: dict = field(default_factory=dict)  # this robot's domain-randomisation ranges where they
                                    # differ from DRConfig's defaults: {name: (lo, hi)}, units as DRConfig
    extra: dict = field(default_factory=dict)

    @property
    def control_dt(self) -> float:
        """Control period in s (policy and PD target update)."""
        return self.sim_dt * self.substeps

    @property
    def control_hz(self) -> float:
        """Control rate in Hz."""
        return 1.0 / self.control_dt

    @property
    def urdf_path(self) -> str:
        """Absolute path of the URDF file."""
        if self.urdf_in_pybullet_data:
            import pybullet_data

            return str(Path(pybullet_data.getDataPath()) / self.urdf)
        return self.urdf

    def clip_to_limits(self, q: np.ndarray) -> np.ndarray:
        """Clamp joint positions (rad, canonical order, any leading shape) to the joint limits."""
        return np.minimum(np.maximum(q, self.joint_lower), self.joint_upper)   # np.clip, 3x faster here
