"""Leg inverse kinematics: damped least squares, 4 legs at once, base held fixed.

Each leg's foot depends only on its own 3 joints, so the 12x12 problem splits
into four 3x3 ones, solved together with batched numpy. Joint limits are kept
by projection: a joint at a limit that the step would push further out is
frozen for that step (its Jacobian column zeroed, the step solved again), then
the angles are clamped. Units: m, rad.

Damped least squares is local: from a poor start it can stop at a joint limit
with the foot short of a reachable target. A leg that does not converge from
``q_init`` is therefore retried from closed-form seeds (:class:`LegGeometry`:
both abduction branches x both knee branches), and the best leg solution kept.
"""

from __future__ import annotations

import numpy as np

from virl_quad.kinematics.frames import to_body

_FRAMES = ("world", "body")
_TWO_PI = 2.0 * np.pi


def _dls(jac: np.ndarray, err: np.ndarray, damping: float) -> np.ndarray:
    """Damped least-squares step per leg: J^T (J J^T + damping^2 I)^-1 e; (4,3,3), (4,3) -> (4,3)."""
    jjt = jac @ np.swapaxes(jac, 1, 2) + (damping ** 2) * np.eye(3)
    return np.einsum("lji,lj->li", jac, np.linalg.solve(jjt, err[..., None])[..., 0])


class LegGeometry:
    """Closed-form IK seeds for legs whose hip and knee axes are parallel and both
    perpendicular to the abduction axis (both project robots; checked here).

    Uses the zero-configuration geometry from Pinocchio (product of exponentials),
    so it is exact for such legs; DLS then polishes the seed and enforces limits.
    """

    def __init__(self, kin) -> None:
        import pinocchio as pin

        m, d = kin.model, kin.data
        pin.framesForwardKinematics(m, d, kin.q_pin())
        joint_pos = np.array([d.oMi[int(j)].translation for j in kin.joint_ids]).reshape(4, 3, 3)
        self.a0, h0, k0 = joint_pos[:, 0], joint_pos[:, 1], joint_pos[:, 2]
        f0 = np.array([d.oMf[f].translation for f in kin.foot_frame_ids])
        axes = kin.joint_axes().reshape(4, 3, 3)
        ua, uh, uk = axes[:, 0], axes[:, 1], axes[:, 2]
        self.ok = bool(np.all(np.abs(np.einsum("li,li->l", ua, uh)) < 1e-4)
                       and np.all(np.abs(np.einsum("li,li->l", uh, uk)) > 1 - 1e-8))
        self.ua, self.uh = ua, uh
        self.n = np.cross(ua, uh)
        self.sk = np.einsum("li,li->l", uh, uk)                 # +1 / -1: knee axis along / against hip axis
        self.c = np.einsum("li,li->l", uh, f0 - self.a0)       # constant offset of the foot along the hip axis
        self.p_ha = self._plane(h0 - self.a0)
        self.v1 = self._plane(k0 - h0)
        self.v2 = self._plane(f0 - k0)
        self.lower = kin.lower.reshape(4, 3)
        self.upper = kin.upper.reshape(4, 3)

    def _plane(self, v: np.ndarray) -> np.ndarray:
        """Coordinates (along ua, along n) of vectors (4, 3) in the plane normal to the hip axis."""
        return np.stack([np.einsum("li,li->l", self.ua, v), np.einsum("li,li->l", self.n, v)], axis=-1)

    def _wrap(self, ang: np.ndarray) -> np.ndarray:
        """Angles (4, k, 3) moved by multiples of 2 pi to the representative nearest the limits."""
        lo, hi = self.lower[:, None, :], self.upper[:, None, :]
        best = ang.copy()
        best_v = np.maximum(lo - ang, 0) + np.maximum(ang - hi, 0)
        for shift in (-2, -1, 1, 2):
            a = ang + shift * _TWO_PI
            v = np.maximum(lo - a, 0) + np.maximum(a - hi, 0)
            take = v < best_v
            best[take], best_v[take] = a[take], v[take]
        return best

    def seeds(self, targets_body: np.ndarray) -> np.ndarray:
        """Up to 4 candidate leg solutions per leg, (4 legs, 4 candidates, 3), rad, wrapped toward limits."""
        w = np.asarray(targets_body) - self.a0
        wx = np.einsum("li,li->l", self.ua, w)
        wy = np.einsum("li,li->l", self.uh, w)
        wn = np.einsum("li,li->l", self.n, w)
        s_abs = np.sqrt(np.maximum(wy ** 2 + wn ** 2 - self.c ** 2, 0.0))
        out = np.empty((4, 4, 3))
        n1, n2 = np.linalg.norm(self.v1, axis=1), np.linalg.norm(self.v2, axis=1)
        th1, th2 = np.arctan2(self.v1[:, 1], self.v1[:, 0]), np.arctan2(self.v2[:, 1], self.v2[:, 0])
        for i, s in enumerate((s_abs, -s_abs)):
            abd = np.arctan2(wn, wy) - np.arctan2(s, self.c)
            t = np.stack([wx, s], axis=-1) - self.p_ha                         # planar target from the hip
            cos_el = (np.sum(t ** 2, axis=1) - n1 ** 2 - n2 ** 2) / np.maximum(2 * n1 * n2, 1e-12)
            el = np.arccos(np.clip(cos_el, -1.0, 1.0))
            for j, phi in enumerate((th1 - th2 + el, th1 - th2 - el)):
                mid = self.v1 + np.stack([np.cos(phi) * self.v2[:, 0] - np.sin(phi) * self.v2[:, 1],
                                          np.sin(phi) * self.v2[:, 0] + np.cos(phi) * self.v2[:, 1]], axis=-1)
                # the hip rotation acts as a rotation by -hip in (ua, n) coordinates (n x ua = hip axis)
                hip = -(np.arctan2(t[:, 1], t[:, 0]) - np.arctan2(mid[:, 1], mid[:, 0]))
                knee = -phi * self.sk
                out[:, 2 * i + j] = np.stack([abd, hip, knee], axis=-1)
        return self._wrap(out)


def solve_body(kin, targets_body: np.ndarray, q_init: np.ndarray, tol: float = 1e-6, max_iters: int = 50,
               damping: float = 1e-3, max_step: float = 0.35) -> tuple[np.ndarray, np.ndarray, int]:
    """DLS from one start on base-frame targets (4, 3). Returns (q12, residual (4,) m, iterations).

    Returns each leg's best iterate; stops when all legs are within ``tol``, after
    ``max_iters``, or when no unconverged leg improves any more (target out of reach).
    """
    lo, hi = kin.lower.reshape(4, 3), kin.upper.reshape(4, 3)
    q = np.clip(np.asarray(q_init, dtype=np.float64).reshape(4, 3), lo, hi)
    best_q = q.copy()
    best_err = np.full(4, np.inf)
    stall, it = 0, 0
    for it in range(max_iters + 1):
        pos, jac = kin.foot_jacobians(q.reshape(-1))
        e = targets_body - pos
        err = np.linalg.norm(e, axis=1)
        gain = best_err - err
        better = gain > 0
        best_err[better] = err[better]
        best_q[better] = q[better]
        active = err > tol
        if not active.any() or it == max_iters:
            break
        stall = stall + 1 if np.all(gain[active] < 1e-3 * tol) else 0
        if stall >= 3:
            break
        dq = _dls(jac, e, damping)
        blocked = ((q <= lo + 1e-12) & (dq < 0)) | ((q >= hi - 1e-12) & (dq > 0))
        if blocked.any():
            dq = _dls(jac * (~blocked)[:, None, :], e, damping)
            dq[blocked] = 0.0
        big = np.abs(dq).max(axis=1, keepdims=True)
        dq *= np.minimum(1.0, max_step / np.maximum(big, 1e-300)) * active[:, None]
        q = np.clip(q + dq, lo, hi)
    return best_q.reshape(-1), best_err, it


def solve(kin, targets_body: np.ndarray, q_init: np.ndarray, tol: float = 1e-6, max_iters: int = 50,
          damping: float = 1e-3, max_step: float = 0.35, reseed: bool = True,
          clamped_seeds: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """DLS from ``q_init``; legs left short of ``tol`` are retried from closed-form seeds.

    Seeds within the limits come first (they are exact solutions, polished in an
    iteration or two); seeds outside the limits, clamped, are tried only when
    ``clamped_seeds`` (a leg with no seed within limits has its target out of reach,
    and the search for the closest point costs several DLS runs).
    """
    q, res, _ = solve_body(kin, targets_body, q_init, tol, max_iters, damping, max_step)
    if not reseed or res.max() <= tol:
        return q, res
    geo = _geometry(kin)
    if not geo.ok:
        return q, res
    seeds = geo.seeds(targets_body)                                   # (4, 4, 3)
    viol = (np.maximum(geo.lower[:, None] - seeds, 0) + np.maximum(seeds - geo.upper[:, None], 0)).sum(-1)
    dist = np.abs(seeds - q.reshape(4, 1, 3)).sum(-1)
    order = np.argsort(viol + 1e-3 * dist, axis=1)                   # within limits first, then nearest
    q = q.reshape(4, 3)
    legs = np.arange(4)
    for k in range(seeds.shape[1]):
        usable = clamped_seeds | (viol[legs, order[:, k]] <= 0)
        todo = (res > tol) & usable
        if not todo.any():
            break
        start = q.copy()
        start[todo] = seeds[legs, order[:, k]][todo]
        q2, res2, _ = solve_body(kin, targets_body, start.reshape(-1), tol, max_iters, damping, max_step)
        take = res2 < res
        q[take], res[take] = q2.reshape(4, 3)[take], res2[take]
    return q.reshape(-1), res


def _geometry(kin) -> LegGeometry:
    geo = getattr(kin, "_leg_geometry", None)
    if geo is None:
        geo = LegGeometry(kin)
        kin._leg_geometry = geo
    return geo


def _targets_body(foot_targets, base_pos, base_quat, frame: str) -> np.ndarray:
    if frame not in _FRAMES:
        raise ValueError(f"frame must be one of {_FRAMES}, got {frame!r}")
    t = np.asarray(foot_targets, dtype=np.float64)
    if t.shape[-2:] != (4, 3):
        raise ValueError(f"foot targets must have shape (4, 3) (FR, FL, RR, RL x xyz), got {t.shape}")
    if frame == "body":
        if base_pos is not None or base_quat is not None:
            raise ValueError("frame='body' targets take no base pose")
        return t
    if base_pos is None or base_quat is None:
        raise ValueError("world-frame targets need base_pos and base_quat (or pass frame='body')")
    bp = np.asarray(base_pos, dtype=np.float64)
    bq = np.asarray(base_quat, dtype=np.float64)
    return to_body(t, bp[..., None, :], bq[..., None, :]) if bq.ndim > 1 else to_body(t, bp, bq)


def leg_ik(kin, foot_targets, base_pos=None, base_quat=None, q_init=None, *, frame: str = "world",
           tol: float = 1e-6, max_iters: int = 50, damping: float = 1e-3, max_step: float = 0.35,
           reseed: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles that put the 4 feet on targets, the base pose being given.

    Args:
        kin: a :class:`~virl_quad.kinematics.model.Kinematics`.
        foot_targets: (4, 3) m, foot frame origins (sphere centres) FR, FL, RR, RL; world
            coordinates (``frame="world"``, needs ``base_pos`` (3,) m and ``base_quat`` (4,)
            xyzw) or base-frame coordinates (``frame="body"``, no base pose).
        q_init: (12,) rad starting angles (default: the spec's default pose); on a
            trajectory pass the previous solution.
        tol: m, stop when every foot is this close to its target.
        max_iters: DLS iterations per start.
        damping: m, damping of the least-squares step (keeps it bounded near singular,
            stretched-leg configurations and for unreachable targets).
        max_step: rad, largest change of any joint per iteration.
        reseed: retry legs that miss ``tol`` from closed-form seeds (both abduction and
            knee branches; see :func:`solve`). Off: pure local DLS from ``q_init``.

    Returns:
        ``(q12, residual)``: angles (12,) rad, always within the spec's limits, and each
        foot's remaining distance to its target (4,) m. A residual above ``tol`` means the
        target is out of reach within the limits (the foot stops at the closest point found).
    """
    t = _targets_body(foot_targets, base_pos, base_quat, frame)
    if t.shape != (4, 3):
        raise ValueError(f"foot targets must have shape (4, 3); use ik_trajectory for {t.shape}")
    q0 = kin.spec.default_pose if q_init is None else q_init
    return solve(kin, t, np.asarray(q0, dtype=np.float64), tol, max_iters, damping, max_step, reseed)


def ik_trajectory(kin, foot_targets, base_pos=None, base_quat=None, q_init=None, *, frame: str = "world",
                  **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """:func:`leg_ik` frame by frame, each frame starting from the previous solution.

    ``foot_targets`` (T, 4, 3) m; world frame: ``base_pos`` (T, 3) and ``base_quat`` (T, 4) xyzw.
    Keyword arguments as :func:`leg_ik`. A leg whose target is out of reach takes the
    closest point that DLS finds from the previous frame (no global search after the
    first frame). Reachable targets: about 0.4 ms a frame. Returns ``(q12 (T, 12) rad, residual (T, 4) m)``.
    """
    t = _targets_body(foot_targets, base_pos, base_quat, frame)
    if t.ndim != 3:
        raise ValueError(f"trajectory foot targets must have shape (T, 4, 3), got {t.shape}")
    q = np.asarray(kin.spec.default_pose if q_init is None else q_init, dtype=np.float64)
    qs = np.empty((len(t), 12))
    res = np.empty((len(t), 4))
    for k, target in enumerate(t):
        # Out-of-reach legs search clamped seeds on the first frame only: later frames
        # follow on from the previous solution (continuity, and speed).
        q, res[k] = solve(kin, target, q, clamped_seeds=(k == 0), **kwargs)
        qs[k] = q
    return qs, res
