"""Built-in gaits: foot trajectories and a root trajectory, turned into joint angles by IK.

A gait is periodic with frequency ``f`` (Hz). Leg ``l`` has the phase
``phi_l = (t f + offset_l) mod 1``; it is in stance while ``phi_l < duty`` and swings
otherwise. In the world frame a stance foot stands still on the ground (foot sphere
touching: foot frame z = ``spec.foot_radius``); a swing foot travels one stride
``speed / f`` (m) forward along a cycloid (zero velocity at lift-off and touch-down)
and rises ``swing_height`` (m) at mid-swing. Each foot is centred, at mid-stance,
under its default-pose position relative to the base, so the step length (foot travel
relative to the body during stance) is ``speed * duty / f``.

The base moves forward at ``speed`` (m/s) at height ``height`` (m), level, except
for a vertical bob and a pitch oscillation driven by the legs' stance phases: both
cancel for gaits whose legs pair up half a cycle apart (trot, pace), the bob is
full for a pronk and the pitch rocks a bound. The joint angles come from Pinocchio
leg IK (:mod:`virl_quad.kinematics`), which keeps them within the joint limits; the
generator refuses a gait whose feet the IK cannot place (residual > 1 mm).

The period is rounded to a whole number of control steps (``spec.control_hz``) so a
rendered demonstration loops seamlessly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from virl_quad import robots
from virl_quad.motion.motion import Motion
from virl_quad.robots.spec import RobotSpec

#: Phase offsets (fraction of a cycle) of the legs FR, FL, RR, RL.
PHASE_OFFSETS: dict[str, tuple[float, float, float, float]] = {
    "trot": (0.0, 0.5, 0.5, 0.0),     # diagonal pairs
    "pace": (0.0, 0.5, 0.0, 0.5),     # lateral pairs
    "bound": (0.0, 0.0, 0.5, 0.5),    # front pair, then hind pair
    "pronk": (0.0, 0.0, 0.0, 0.0),    # all four together
    "walk": (0.75, 0.25, 0.5, 0.0),   # four-beat lateral sequence: RL, FL, RR, FR
}
GAIT_NAMES: tuple[str, ...] = tuple(PHASE_OFFSETS)
DEFAULT_GAIT = "trot"
MAX_IK_RESIDUAL = 1e-3  # m


@dataclass(frozen=True)
class GaitParams:
    """Parameters of one periodic gait (SI units)."""

    speed: float          # m/s, forward base speed
    frequency: float      # Hz, stride frequency (rounded to whole control steps per cycle)
    duty: float           # fraction of the cycle each foot is on the ground
    swing_height: float   # m, foot lift at mid-swing
    height: float         # m, mean base height
    bob: float = 0.0      # m, base height oscillation amplitude (pronk-like phases)
    pitch: float = 0.0    # rad, base pitch oscillation amplitude (bound-like phases)
    offsets: tuple[float, float, float, float] = (0.0, 0.5, 0.5, 0.0)  # FR, FL, RR, RL

    @property
    def step_length(self) -> float:
        """Foot travel (m) relative to the body during stance."""
        return self.speed * self.duty / self.frequency


def _p(gait: str, **kw) -> GaitParams:
    return GaitParams(offsets=PHASE_OFFSETS[gait], **kw)


#: Per-robot parameters. Pupper: feet ~0.14 m below the hips (base 0.153 m), trot 0.25 m/s at 2 Hz.
#: Laikago: base 0.45 m (feet ~0.39 m below the hips), trot 0.8 m/s at ~2 Hz.
PARAMS: dict[str, dict[str, GaitParams]] = {
    "pupper": {
        "trot": _p("trot", speed=0.25, frequency=2.0, duty=0.6, swing_height=0.03, height=0.153),
        "pace": _p("pace", speed=0.2, frequency=2.0, duty=0.6, swing_height=0.03, height=0.153),
        "bound": _p("bound", speed=0.3, frequency=2.5, duty=0.4, swing_height=0.03, height=0.153, pitch=0.08),
        "pronk": _p("pronk", speed=0.15, frequency=2.5, duty=0.4, swing_height=0.025, height=0.15, bob=0.01),
        "walk": _p("walk", speed=0.12, frequency=1.25, duty=0.75, swing_height=0.03, height=0.153),
    },
    "laikago": {
        "trot": _p("trot", speed=0.8, frequency=2.0, duty=0.6, swing_height=0.08, height=0.45),
        "pace": _p("pace", speed=0.6, frequency=2.0, duty=0.6, swing_height=0.07, height=0.45),
        "bound": _p("bound", speed=1.0, frequency=2.5, duty=0.4, swing_height=0.08, height=0.44, pitch=0.08),
        "pronk": _p("pronk", speed=0.4, frequency=2.5, duty=0.4, swing_height=0.06, height=0.43, bob=0.02),
        "walk": _p("walk", speed=0.3, frequency=1.25, duty=0.75, swing_height=0.07, height=0.45),
    },
}


def gait_params(robot: str, gait: str) -> GaitParams:
    """The built-in parameters of ``gait`` for ``robot``; ValueError naming the valid gaits."""
    robots.get(robot)
    if gait not in PHASE_OFFSETS:
        raise ValueError(f"unknown gait {gait!r}; built-in gaits: {', '.join(GAIT_NAMES)}")
    if robot not in PARAMS:
        raise ValueError(f"no built-in gait parameters for robot {robot!r}")
    return PARAMS[robot][gait]


def cycle_steps(spec: RobotSpec, frequency: float) -> int:
    """Control steps per gait cycle (at least 4)."""
    return max(4, int(round(spec.control_hz / frequency)))


def foot_and_root_trajectory(spec: RobotSpec, p: GaitParams, times: np.ndarray,
                             nominal_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World foot targets (T, 4, 3) m, base positions (T, 3) m and base quaternions (T, 4) xyzw.

    ``nominal_xy`` (4, 2) m: each foot's mid-stance position in the base frame.
    """
    t = np.asarray(times, dtype=np.float64)[:, None]                  # (T, 1) s
    f, duty = p.frequency, p.duty
    offsets = np.asarray(p.offsets)[None, :]                            # (1, 4)
    cycles = t * f + offsets                                            # leg clock, cycles
    k = np.floor(cycles)                                                # index of the current cycle
    phi = cycles - k                                                    # phase in [0, 1)
    stride = p.speed / f                                                # m per cycle
    # Mid-stance time of cycle k of leg l: (k + duty/2 - offset) / f; the foot then sits under its nominal spot.
    x_mid = p.speed * (k + duty / 2 - offsets) / f                      # base x at mid-stance of cycle k
    s = np.clip((phi - duty) / (1.0 - duty), 0.0, 1.0)                  # swing progress, 0 in stance
    swing_x = stride * (s - np.sin(2 * np.pi * s) / (2 * np.pi))        # cycloid, 0 -> stride
    foot_x = x_mid + swing_x + nominal_xy[None, :, 0]
    lift = np.where(phi >= duty, p.swing_height * 0.5 * (1 - np.cos(2 * np.pi * s)), 0.0)
    feet = np.stack([foot_x, np.broadcast_to(nominal_xy[None, :, 1], foot_x.shape),
                     spec.foot_radius + lift], axis=-1)                 # (T, 4, 3)
    stance_wave = np.cos(2 * np.pi * (phi - duty / 2))                  # 1 at mid-stance, per leg
    z = p.height - p.bob * stance_wave.mean(axis=1)
    pitch = p.pitch * 0.5 * (stance_wave[:, :2].mean(axis=1) - stance_wave[:, 2:].mean(axis=1))
    root = np.stack([p.speed * t[:, 0], np.zeros(len(t)), z], axis=1)
    quat = Rotation.from_euler("y", pitch[:, None]).as_quat()
    return feet, root, quat.reshape(-1, 4)


def world_to_base(points: np.ndarray, base_pos: np.ndarray, base_quat: np.ndarray) -> np.ndarray:
    """World points (T, K, 3) m -> base frame of poses (T, 3) m, (T, 4) xyzw: ``R^T (p - base_pos)``."""
    rot = Rotation.from_quat(np.asarray(base_quat, dtype=np.float64))
    rel = np.asarray(points, dtype=np.float64) - np.asarray(base_pos, dtype=np.float64)[:, None, :]
    mats = rot.as_matrix()                                              # (T, 3, 3) body -> world
    return np.einsum("tji,tkj->tki", mats, rel)


def gait_motion(robot: str, gait: str = DEFAULT_GAIT, keyframes_per_step: int = 2, **overrides) -> Motion:
    """One cycle of a built-in gait as a looping :class:`Motion` (joint angles from Pinocchio IK).

    ``overrides`` replace :class:`GaitParams` fields, e.g. ``speed=0.0`` for the same gait in place.
    Keyframes: ``keyframes_per_step`` per control step. Raises ValueError for an unknown
    robot, gait or field, or when the feet cannot be placed (IK residual > 1 mm).
    """
    from virl_quad.kinematics import Kinematics

    spec = robots.get(robot)
    params = gait_params(robot, gait)
    bad = [k for k in overrides if k not in GaitParams.__dataclass_fields__]
    if bad:
        raise ValueError(f"unknown gait parameter(s) {', '.join(bad)}; "
                         f"valid: {', '.join(GaitParams.__dataclass_fields__)}")
    params = replace(params, **overrides)
    if not (0.0 < params.duty < 1.0) or params.frequency <= 0 or params.height <= 0:
        raise ValueError(f"invalid gait parameters {params}")
    steps = cycle_steps(spec, params.frequency)
    params = replace(params, frequency=spec.control_hz / steps)
    n = steps * keyframes_per_step
    times = np.arange(n + 1) / (n * params.frequency)                  # one cycle, both ends, s
    kin = Kinematics(spec)
    nominal = kin.foot_positions(None, None, spec.default_pose)[:, :2]  # base frame, m
    feet, root, quat = foot_and_root_trajectory(spec, params, times, nominal)
    # Warm start: solve the first frame twice so the trajectory starts on a converged solution.
    body = world_to_base(feet, root, quat)
    q0, _ = kin.leg_ik(body[0], q_init=spec.default_pose, frame="body", max_iters=200)
    q, residual = kin.ik_trajectory(body, q_init=q0, frame="body", max_iters=100)
    worst = float(residual.max())
    if worst > MAX_IK_RESIDUAL:
        raise ValueError(f"gait {gait!r} on {robot}: feet out of reach (IK residual {worst * 1000:.1f} mm); "
                         "lower the speed, swing height or base height")
    return Motion(frame_duration=float(times[1] - times[0]), root_pos=root, root_quat=quat, q=q, loop=True,
                  cycle_offset_position=True, cycle_offset_rotation=False, robot=robot, name=gait)
