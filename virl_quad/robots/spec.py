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
    strip_full_speed: float = 0.5   # m/s drawn as a half-width bar by the speed strip (sim.strip.stamp_speed)
    notes: str = ""
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
