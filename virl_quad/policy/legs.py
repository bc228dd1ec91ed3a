"""Closed-form leg kinematics (numpy only) from a :class:`~virl_quad.robots.spec.LegGeometry`.

A leg is an abduction joint about the body x axis carrying a planar two-link leg (hip and
knee about the body y axis). With ``R_x``/``R_y`` rotations about those axes and the
zero-angle offsets of the geometry, the foot (base frame, m) is

    foot = A + R_x(s q_abd) (H + R_y(q_hip) (K + R_y(q_knee) F))

(A: abduction origin, s: its axis sign, H, K, F: hip, knee and foot offsets). The inverse
solves it exactly for a reachable target: the foot's coordinate along the hip axis is a
constant ``c`` of the leg, so the abduction angle puts the target's (y, z) at distance ``c``
from the leg plane; the rest is the two-link planar problem, knee bent backwards (the
branch both robots stand in). Unreachable targets give the closest stretched or folded
leg (the cosines are clamped). Angles are in rad, each wrapped to the representative
nearest the middle of its joint range; the joint limits themselves are not applied here.

Works on any leading shape: feet ``(..., 4, 3)`` <-> angles ``(..., 12)``; :meth:`LegKinematics.inverse_leg`
solves one leg in plain floats (the same formulas, about 4x faster than numpy for a single pose:
the robot's control loop).
"""

from __future__ import annotations

import math

import numpy as np

from virl_quad.robots.spec import RobotSpec

_TWO_PI = 2.0 * np.pi


def leg_length(spec: RobotSpec) -> float:
    """m: the robot's mean leg length, hip joint -> knee -> foot (ValueError without ``spec.leg``)."""
    if spec.leg is None:
        raise ValueError(f"robot {spec.name!r} has no leg geometry (RobotSpec.leg)")
    return float(np.mean(spec.leg.upper_leg_length + spec.leg.lower_leg_length))


class LegKinematics:
    """Foot positions from joint angles and back, for the four legs of one robot."""

    def __init__(self, spec: RobotSpec) -> None:
        """Precompute the constants of ``spec.leg`` (ValueError when the spec has none)."""
        g = spec.leg
        if g is None:
            raise ValueError(f"robot {spec.name!r} has no leg geometry (RobotSpec.leg) for closed-form leg kinematics")
        self.spec = spec
        self.origin = np.array(g.abduction_origin)                       # m (4, 3)
        self.sign = np.array(g.abduction_sign)                           # (4,)
        self.hip = np.array(g.hip_from_abduction)                        # m (4, 3)
        self.knee = np.array(g.knee_from_hip)                            # m (4, 3)
        self.foot = np.array(g.foot_from_knee)                           # m (4, 3)
        self.c = self.hip[:, 1] + self.knee[:, 1] + self.foot[:, 1]      # m, foot offset along the hip axis
        self.l1 = np.hypot(self.knee[:, 0], self.knee[:, 2])             # m, upper leg
        self.l2 = np.hypot(self.foot[:, 0], self.foot[:, 2])             # m, lower leg
        self.beta_u = np.arctan2(self.knee[:, 2], self.knee[:, 0])       # rad, upper leg direction in (x, z) at 0
        self.beta_l = np.arctan2(self.foot[:, 2], self.foot[:, 0])       # rad, lower leg direction in (x, z) at 0
        self._l_sq = self.l1 ** 2 + self.l2 ** 2
        self._l_2prod = 2.0 * self.l1 * self.l2
        mid = 0.5 * (np.asarray(spec.joint_lower) + np.asarray(spec.joint_upper)).reshape(4, 3)
        self._mid_abd, self._mid_hip = mid[:, 0], mid[:, 1]
        self._leg = [tuple(float(v) for v in row) for row in zip(          # per-leg constants as floats
            *self.origin.T, self.c, self.hip[:, 0], self.hip[:, 2], self._l_sq, self._l_2prod, self.l1, self.l2,
            self.beta_l - self.beta_u, self.beta_u, self.sign, self._mid_abd, self._mid_hip)]

    def forward(self, q12: np.ndarray) -> np.ndarray:
        """Base-frame foot positions (m, ``(..., 4, 3)``) of joint angles (rad, ``(..., 12)``)."""
        q = np.asarray(q12, dtype=np.float64)
        q = q.reshape(q.shape[:-1] + (4, 3))
        a, h, k = self.sign * q[..., 0], q[..., 1], q[..., 2]
        # lower leg, then upper leg, rotated about y: (x, z) -> (x cos + z sin, -x sin + z cos)
        hk = h + k
        ch, sh, chk, shk = np.cos(h), np.sin(h), np.cos(hk), np.sin(hk)
        x = self.hip[:, 0] + self.knee[:, 0] * ch + self.knee[:, 2] * sh + self.foot[:, 0] * chk + self.foot[:, 2] * shk
        z = self.hip[:, 2] - self.knee[:, 0] * sh + self.knee[:, 2] * ch - self.foot[:, 0] * shk + self.foot[:, 2] * chk
        y = self.c
        ca, sa = np.cos(a), np.sin(a)
        return self.origin + np.stack([x, y * ca - z * sa, y * sa + z * ca], axis=-1)

    def inverse(self, feet: np.ndarray) -> np.ndarray:
        """Joint angles (rad, ``(..., 12)``) that put the feet on base-frame targets (m, ``(..., 4, 3)``)."""
        w = np.asarray(feet, dtype=np.float64) - self.origin
        wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
        vz = -np.sqrt(np.maximum(wy * wy + wz * wz - self.c * self.c, 0.0))   # leg-plane z, foot below the axis
        abd = np.arctan2(wz, wy) - np.arctan2(vz, self.c)
        tx, tz = wx - self.hip[:, 0], vz - self.hip[:, 2]                     # hip joint -> foot, leg plane
        cos_g = np.clip((tx * tx + tz * tz - self._l_sq) / self._l_2prod, -1.0, 1.0)
        gamma = np.arccos(cos_g)                                              # >= 0: the knee bends backwards
        knee = self.beta_l - self.beta_u - gamma
        hip = self.beta_u + np.arctan2(self.l2 * np.sin(gamma), self.l1 + self.l2 * cos_g) - np.arctan2(tz, tx)
        abd = self.sign * abd
        abd = self._mid_abd + np.mod(abd - self._mid_abd + np.pi, _TWO_PI) - np.pi
        hip = self._mid_hip + np.mod(hip - self._mid_hip + np.pi, _TWO_PI) - np.pi
        return np.stack([abd, hip, knee], axis=-1).reshape(w.shape[:-2] + (12,))

    def inverse_leg(self, leg: int, x: float, y: float, z: float) -> tuple[float, float, float]:
        """(abduction, hip, knee) angles (rad) of leg ``leg`` (0-3) for one base-frame foot target
        (m): :meth:`inverse` in plain floats."""
        ox, oy, oz, c, hx, hz, l_sq, l_2prod, l1, l2, knee0, beta_u, sign, mid_abd, mid_hip = self._leg[leg]
        wy, wz = y - oy, z - oz
        vz = -math.sqrt(max(wy * wy + wz * wz - c * c, 0.0))
        abd = sign * (math.atan2(wz, wy) - math.atan2(vz, c))
        tx, tz = x - ox - hx, vz - hz
        cos_g = min(max((tx * tx + tz * tz - l_sq) / l_2prod, -1.0), 1.0)
        gamma = math.acos(cos_g)
        hip = beta_u + math.atan2(l2 * math.sin(gamma), l1 + l2 * cos_g) - math.atan2(tz, tx)
        abd = mid_abd + (abd - mid_abd + math.pi) % _TWO_PI - math.pi
        hip = mid_hip + (hip - mid_hip + math.pi) % _TWO_PI - math.pi
        return abd, hip, knee0 - gamma
