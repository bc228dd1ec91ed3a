"""A periodic trajectory generator (TG): the gait prior a policy acts as a residual on.

PMTG-style (Iscen et al. 2018): per-leg foot trajectories in the body frame, driven by the
phase clock, turned into joint targets by closed-form leg IK (:mod:`virl_quad.policy.legs`).
The policy modulates the TG's frequency and amplitude and adds joint residuals
(:mod:`virl_quad.policy.action`).

Foot of leg ``l`` at clock phase ``phi`` (the same gait definition as
:mod:`virl_quad.motion.gaits`, seen from the body): the leg phase is
``phi_l = (phi + offset_l) mod 1``; in stance (``phi_l < duty``) the foot moves straight
backwards at constant speed from ``+L/2`` to ``-L/2`` about its neutral x (``L``: step
length), at ``stance_height`` below the abduction joint; in swing (progress
``s = (phi_l - duty) / (1 - duty)``) it returns forwards along a cycloid with the body's
stance speed at both ends (a foot at rest on the ground at lift-off and touch-down when the
body moves at ``L f / duty``), rising ``swing_height`` at mid-swing. ``y`` stays at the
neutral y.

Modulation by the policy (two action entries ``m``, see :func:`modulation`):
frequency scale ``1 + 0.5 m0`` bounded to [0.5, 1.5]; amplitude scale (step length and swing
height) ``1 + 0.5 m1`` bounded to [0, 1.5].
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from virl_quad.policy.legs import LegKinematics
from virl_quad.robots.spec import RobotSpec

MODULATION_GAIN = 0.5                          # scale change per unit of modulation action
FREQUENCY_SCALE_RANGE = (0.5, 1.5)             # bounds of the frequency scale
AMPLITUDE_SCALE_RANGE = (0.0, 1.5)             # bounds of the step length and swing height scale
REACH_TOLERANCE = 1e-4                         # m, largest IK miss accepted for a nominal TG foot

#: (lower, upper, lower bound excluded) of each scalar field of :class:`TGParams`.
BOUNDS: dict[str, tuple[float, float, bool]] = {
    "frequency": (0.0, 10.0, True),            # Hz
    "duty": (0.05, 0.95, False),               # fraction of the cycle in stance
    "step_length": (0.0, 1.0, False),          # m
    "swing_height": (0.0, 0.5, False),         # m
    "stance_height": (0.0, 2.0, True),         # m
}


def _number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"TG field {name!r} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class TGParams:
    """Parameters of the trajectory generator (plain data, JSON-serialisable)."""

    frequency: float                                   # Hz, gait cycles per second
    offsets: tuple[float, float, float, float]        # fraction of a cycle, legs FR, FL, RR, RL, in [0, 1)
    duty: float                                        # fraction of the cycle each foot is in stance
    step_length: float                                 # m, foot travel relative to the body during stance
    swing_height: float                                # m, foot lift at mid-swing
    stance_height: float                               # m, foot frame origin below the abduction joint origin
    neutral_xy: tuple[tuple[float, float], ...] | None = None   # m, per-leg mid-stance foot (x, y), base
                                                       # frame; None: the feet of the spec's default pose

    def __post_init__(self) -> None:
        for name, (lo, hi, open_lo) in BOUNDS.items():
            v = _number(name, getattr(self, name))
            if v > hi or v < lo or (open_lo and v == lo):
                raise ValueError(f"TG field {name!r} = {v} is outside {'(' if open_lo else '['}{lo}, {hi}]")
            object.__setattr__(self, name, v)
        off = self.offsets
        if not isinstance(off, (list, tuple)) or len(off) != 4:
            raise ValueError(f"TG field 'offsets' must list 4 leg offsets (FR, FL, RR, RL), got {off!r}")
        off = tuple(_number("offsets", v) for v in off)
        if any(not 0.0 <= v < 1.0 for v in off):
            raise ValueError(f"TG field 'offsets' must lie in [0, 1), got {list(off)}")
        object.__setattr__(self, "offsets", off)
        if self.neutral_xy is not None:
            xy = self.neutral_xy
            if not isinstance(xy, (list, tuple)) or len(xy) != 4 or any(
                    not isinstance(p, (list, tuple)) or len(p) != 2 for p in xy):
                raise ValueError(f"TG field 'neutral_xy' must be 4 (x, y) pairs, got {xy!r}")
            xy = tuple((_number("neutral_xy", p[0]), _number("neutral_xy", p[1])) for p in xy)
            if any(abs(v) > 2.0 for p in xy for v in p):
                raise ValueError(f"TG field 'neutral_xy' must lie within 2 m of the base, got {xy}")
            object.__setattr__(self, "neutral_xy", xy)

    def to_dict(self) -> dict:
        """Plain dict (lists, floats, None) for JSON."""
        d = asdict(self)
        d["offsets"] = list(self.offsets)
        d["neutral_xy"] = None if self.neutral_xy is None else [list(p) for p in self.neutral_xy]
        return d

    @classmethod
    def from_dict(cls, d: object) -> TGParams:
        """Inverse of :meth:`to_dict`; ValueError naming the missing, unknown or bad field."""
        if not isinstance(d, dict):
            raise ValueError(f"TG parameters must be a JSON object, got {type(d).__name__}")
        fields = list(cls.__dataclass_fields__)
        unknown = sorted(set(d) - set(fields))
        if unknown:
            raise ValueError(f"unknown TG field(s) {', '.join(map(repr, unknown))}; valid: {', '.join(fields)}")
        missing = [f for f in fields if f not in d and f != "neutral_xy"]
        if missing:
            raise ValueError(f"TG field {missing[0]!r} is missing")
        return cls(**d)


def modulation(m: np.ndarray) -> tuple[float, float]:
    """(frequency scale, amplitude scale) from the two modulation entries of an action."""
    f = 1.0 + MODULATION_GAIN * float(m[0])
    a = 1.0 + MODULATION_GAIN * float(m[1])
    f = min(max(f, FREQUENCY_SCALE_RANGE[0]), FREQUENCY_SCALE_RANGE[1])
    a = min(max(a, AMPLITUDE_SCALE_RANGE[0]), AMPLITUDE_SCALE_RANGE[1])
    return f, a


def modulation_facts() -> dict:
    """How the modulation entries act (written into the policy metadata and checked on load)."""
    return {"gain": MODULATION_GAIN, "frequency_scale": list(FREQUENCY_SCALE_RANGE),
            "amplitude_scale": list(AMPLITUDE_SCALE_RANGE)}


def foot_positions(phase: float | np.ndarray, offsets: np.ndarray, duty: float, step_length: float,
                   swing_height: float, neutral_xy: np.ndarray, stance_z: np.ndarray) -> np.ndarray:
    """The TG's feet (m, base frame; see the module doc) at clock ``phase`` (scalar -> ``(4, 3)``,
    ``(..., 1)`` -> ``(..., 4, 3)``): leg ``offsets`` (4,) cycles, ``duty``, ``step_length`` (m),
    ``swing_height`` (m), ``neutral_xy`` (4, 2) m, ``stance_z`` (4,) m (foot z in stance)."""
    length = step_length
    phi = np.mod(np.asarray(phase, dtype=np.float64) + offsets, 1.0)           # leg phases (..., 4)
    s = np.maximum(phi - duty, 0.0) / (1.0 - duty)                             # swing progress, 0 in stance
    ang = 2.0 * np.pi * s
    stance_x = 0.5 * length - length * phi / duty
    swing_x = length * ((s - np.sin(ang) / (2.0 * np.pi)) - (1.0 - duty) * s) / duty - 0.5 * length
    x = neutral_xy[:, 0] + np.where(phi >= duty, swing_x, stance_x)
    z = stance_z + (0.5 * swing_height) * (1.0 - np.cos(ang))                  # no lift in stance (s = 0)
    y = np.broadcast_to(neutral_xy[:, 1], x.shape)
    return np.stack([x, y, z], axis=-1)


class TrajectoryGenerator:
    """The TG of one robot: foot positions and joint targets at a phase."""

    def __init__(self, spec: RobotSpec, params: TGParams) -> None:
        """ValueError when a nominal foot trajectory is out of the leg's reach or its joint limits."""
        self.spec, self.params = spec, params
        self.legs = LegKinematics(spec)
        if params.neutral_xy is None:
            self.neutral_xy = self.legs.forward(spec.default_pose)[:, :2]          # m (4, 2)
        else:
            self.neutral_xy = np.asarray(params.neutral_xy, dtype=np.float64)
        self.stance_z = self.legs.origin[:, 2] - params.stance_height               # m (4,)
        self.offsets = np.asarray(params.offsets, dtype=np.float64)
        self._leg = [tuple(float(v) for v in row) for row in zip(self.offsets, *self.neutral_xy.T, self.stance_z)]
        self._check_reach()

    def _check_reach(self) -> None:
        feet = self.foot_positions(np.linspace(0.0, 1.0, 64, endpoint=False)[:, None])
        q = self.legs.inverse(feet)
        miss = float(np.abs(self.legs.forward(q) - feet).max())
        if miss > REACH_TOLERANCE:
            raise ValueError(f"TG feet are out of {self.spec.name}'s reach by {miss * 1000:.1f} mm "
                             "(stance height, step length or swing height too large)")
        lo, hi = np.asarray(self.spec.joint_lower), np.asarray(self.spec.joint_upper)
        out = float(np.max(np.maximum(lo - q, 0.0) + np.maximum(q - hi, 0.0)))
        if out > 1e-6:
            raise ValueError(f"TG joint angles leave {self.spec.name}'s joint limits by {out:.3f} rad")

    def foot_positions(self, phase: float | np.ndarray, amplitude: float = 1.0) -> np.ndarray:
        """Base-frame feet (m): ``(4, 3)`` for a scalar phase, ``(..., 4, 3)`` for phases ``(..., 1)``."""
        p = self.params
        return foot_positions(phase, self.offsets, p.duty, p.step_length * amplitude, p.swing_height * amplitude,
                              self.neutral_xy, self.stance_z)

    def joint_targets(self, phase: float | np.ndarray, amplitude: float = 1.0) -> np.ndarray:
        """Joint angles (rad, ``(12,)`` for a scalar phase, ``(..., 12)`` for phases ``(..., 1)``)
        that put the feet on the TG trajectory."""
        if np.ndim(phase) == 0:                  # one pose (the control loop): plain floats, same formulas
            return self._joint_targets_one(float(phase), float(amplitude))
        return self.legs.inverse(self.foot_positions(phase, amplitude))

    def _joint_targets_one(self, phase: float, amplitude: float) -> np.ndarray:
        p = self.params
        length, lift, duty = p.step_length * amplitude, p.swing_height * amplitude, p.duty
        out = []
        for leg, (offset, nx, ny, sz) in enumerate(self._leg):
            phi = (phase + offset) % 1.0
            if phi < duty:                       # stance: straight back at constant speed
                x, z = 0.5 * length - length * phi / duty, sz
            else:                                # swing: cycloid forward, lifted
                s = (phi - duty) / (1.0 - duty)
                ang = 2.0 * math.pi * s
                x = length * ((s - math.sin(ang) / (2.0 * math.pi)) - (1.0 - duty) * s) / duty - 0.5 * length
                z = sz + 0.5 * lift * (1.0 - math.cos(ang))
            out.extend(self.legs.inverse_leg(leg, nx + x, ny, z))
        return np.array(out)
