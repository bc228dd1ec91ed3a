"""Domain randomisation: every range in one config, sampling as a pure function of (ranges, rng).

``sample(ranges, rng, spec)`` draws one episode's :class:`Randomization`; it
touches no simulator. ``DRConfig.off()`` gives the nominal robot, and any
range can be overridden by name: ``DRConfig.from_overrides({"latency": (0, 0.02)})``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from virl_quad.robots.spec import RobotSpec
from virl_quad.sim.camera import CameraParams
from virl_quad.sim.params import PhysicsParams

Range = tuple[float, float]


@dataclass(frozen=True)
class DRConfig:
    """Ranges (lo, hi) sampled uniformly at every reset. Defaults follow motion_imitation / legged_gym."""

    mass_scale: Range = (0.8, 1.2)             # x every link mass
    payload: Range = (0.0, 0.1)                # fraction of the robot's total mass, added to the base
    inertia_scale: Range = (0.5, 1.5)          # x every link inertia
    motor_strength: Range = (0.8, 1.2)         # x torque limit, per motor
    kp_scale: Range = (0.9, 1.1)               # x PD position gain
    kd_scale: Range = (0.9, 1.1)               # x PD velocity gain
    joint_friction: Range = (0.0, 0.05)        # N·m, Coulomb friction per joint
    joint_damping: Range = (0.0, 0.01)         # N·m·s/rad, viscous damping per joint
    ground_friction: Range = (0.5, 1.25)       # lateral friction coefficient
    ground_restitution: Range = (0.0, 0.1)
    latency: Range = (0.0, 0.04)               # s, observation delay
    obs_noise: Range = (0.0, 1.0)              # x nominal per-component noise std (see env)
    push_velocity: Range = (0.0, 0.25)         # m/s, horizontal kick to the base
    push_interval: Range = (3.0, 5.0)          # s between kicks
    camera_distance: Range = (-0.05, 0.05)     # fraction of the nominal distance
    camera_height: Range = (-0.05, 0.05)       # fraction of the nominal distance
    camera_yaw: Range = (-5.0, 5.0)            # deg

    @staticmethod
    def for_robot(spec: RobotSpec) -> "DRConfig":
        """The default ranges with the robot's own (``spec.randomization``) in place."""
        return DRConfig.from_overrides(spec.randomization or None)

    @staticmethod
    def off() -> "DRConfig":
        """The nominal robot: every range collapsed to its nominal value, no noise, no pushes."""
        return DRConfig(**NOMINAL)

    @staticmethod
    def from_overrides(overrides: dict | None, base: "DRConfig | None" = None) -> "DRConfig":
        """A config with some ranges replaced; ValueError on an unknown name or a bad range."""
        base = base or DRConfig()
        overrides = dict(overrides or {})
        names = [f.name for f in dataclasses.fields(DRConfig)]
        for key, value in overrides.items():
            if key not in names:
                raise ValueError(f"unknown randomisation parameter {key!r}; choose from: {', '.join(names)}")
            try:
                lo, hi = (float(v) for v in value)
            except (TypeError, ValueError):
                raise ValueError(f"randomisation range {key} must be (lo, hi), got {value!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise ValueError(f"randomisation range {key} must be finite with lo <= hi, got {value!r}")
            overrides[key] = (lo, hi)
        return dataclasses.replace(base, **overrides)


#: The nominal value of every range (what "off" means).
NOMINAL: dict[str, Range] = {
    "mass_scale": (1.0, 1.0), "payload": (0.0, 0.0), "inertia_scale": (1.0, 1.0),
    "motor_strength": (1.0, 1.0), "kp_scale": (1.0, 1.0), "kd_scale": (1.0, 1.0),
    "joint_friction": (-1.0, -1.0), "joint_damping": (-1.0, -1.0),  # -1 = the spec's value
    "ground_friction": (0.8, 0.8), "ground_restitution": (0.0, 0.0), "latency": (0.0, 0.0),
    "obs_noise": (0.0, 0.0), "push_velocity": (0.0, 0.0), "push_interval": (1e9, 1e9),
    "camera_distance": (0.0, 0.0), "camera_height": (0.0, 0.0), "camera_yaw": (0.0, 0.0),
}


@dataclass
class Randomization:
    """One episode's draw."""

    physics: PhysicsParams
    latency: float          # s
    obs_noise: float        # x nominal noise std
    push_velocity: float    # m/s
    push_interval: float    # s
    camera: CameraParams


def _u(rng: np.random.Generator, r: Range, size: int | None = None):
    lo, hi = r
    return rng.uniform(lo, hi, size) if hi > lo else (np.full(size, lo) if size else lo)


def sample(ranges: DRConfig, rng: np.random.Generator, spec: RobotSpec) -> Randomization:
    """Draw one episode's randomisation. Pure: the same (ranges, rng state, spec) give the same draw."""
    friction = float(_u(rng, ranges.joint_friction))
    damping = float(_u(rng, ranges.joint_damping))
    physics = PhysicsParams(
        mass_scale=float(_u(rng, ranges.mass_scale)),
        payload=float(_u(rng, ranges.payload)) * spec.total_mass,
        inertia_scale=float(_u(rng, ranges.inertia_scale)),
        motor_strength=np.asarray(_u(rng, ranges.motor_strength, 12), dtype=np.float64),
        kp_scale=float(_u(rng, ranges.kp_scale)),
        kd_scale=float(_u(rng, ranges.kd_scale)),
        joint_friction=None if friction < 0 else friction,
        joint_damping=None if damping < 0 else damping,
        ground_friction=float(_u(rng, ranges.ground_friction)),
        ground_restitution=float(_u(rng, ranges.ground_restitution)),
    )
    nominal = CameraParams.from_spec(spec)
    camera = nominal.jittered(float(_u(rng, ranges.camera_distance)) * nominal.distance,
                              float(_u(rng, ranges.camera_height)) * nominal.distance,
                              float(_u(rng, ranges.camera_yaw)))
    return Randomization(
        physics=physics,
        latency=float(_u(rng, ranges.latency)),
        obs_noise=float(_u(rng, ranges.obs_noise)),
        push_velocity=float(_u(rng, ranges.push_velocity)),
        push_interval=float(_u(rng, ranges.push_interval)),
        camera=camera,
    )
