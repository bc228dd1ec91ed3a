"""Consistency checks of one robot: URDF text vs Pinocchio vs PyBullet vs the spec.

Each check returns a :class:`CheckResult` (name, PASS/FAIL, the figures behind
it). :func:`run_checks` runs them all for a spec; ``python -m virl_quad.check``
prints them. Thresholds are fixed here, never loosened to make a robot pass.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from virl_quad.quiet import import_pybullet_quietly

import_pybullet_quietly()   # first: its build-time banner would break the CLIs' one-line errors
import pybullet  # noqa: E402

from virl_quad.quiet import quiet_fd
from virl_quad.kinematics.frames import laikago_clip_root_to_zup, random_quat
from virl_quad.kinematics.model import Kinematics
from virl_quad.kinematics.urdf import inertia_validity, read_urdf
from virl_quad.robots.spec import JOINT_KINDS, LEGS, RobotSpec

MASS_TOL = 1e-3          # kg
LIMIT_TOL = 1e-6         # rad
FK_TOL = 1e-6            # m, Pinocchio vs PyBullet foot positions
FEET_GROUND_TOL = 5e-3   # m, foot sphere bottom vs z = 0 in the default pose at spawn height
AXIS_TOL = 1e-3          # |cos| slack for "abduction along x, hip and knee along y"
LIMITS_URDF_TOL = 1e-5   # m, toes of laikago_toes_limits.urdf vs the z-up URDF (1.57079 ~ pi/2 rounding)

#: Where the limits of URDFs with ``continuous`` joints come from (pybullet_data-relative).
LIMITS_URDF = {"laikago": "laikago/laikago_toes_limits.urdf"}


@dataclass
class CheckResult:
    """One check: PASS/FAIL and the figures behind it (details: extra lines, e.g. failures)."""

    name: str
    ok: bool
    figures: str
    details: list[str] = field(default_factory=list)


@dataclass
class RobotReport:
    """All checks of one robot, and its joint mapping table."""

    spec: RobotSpec
    results: list[CheckResult]
    mapping: list[dict] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return bool(self.results) and all(r.ok for r in self.results)


def _world(spec: RobotSpec):
    from virl_quad.sim.world import World  # imports cv2 etc.; only when checks run

    with quiet_fd(1):  # PyBullet prints 'argv[0]=' on connecting
        return World(spec)


def _pybullet_data(rel: str) -> str:
    import pybullet_data

    return str(Path(pybullet_data.getDataPath()) / rel)


def _fmt_axis(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    if abs(abs(v[k]) - 1.0) > AXIS_TOL:
        return "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"
    return ("+" if v[k] > 0 else "-") + "xyz"[k]


class Context:
    """The robot loaded three ways: URDF text, Pinocchio (floating base), PyBullet (World)."""

    def __init__(self, spec: RobotSpec) -> None:
        self.spec = spec
        self.path = spec.urdf_path
        if not Path(self.path).is_file():
            raise FileNotFoundError(f"URDF not found: {self.path}")
        self.links, self.joints = read_urdf(self.path)
        self.kin = Kinematics(spec, floating_base=True)
        self.world = _world(spec)
        self.bc, self.body = self.world.bc, self.world.robot

    def close(self) -> None:
        self.world.close()


# -- the checks ---------------------------------------------------------------------------------
def check_mapping(ctx: Context) -> tuple[CheckResult, list[dict]]:
    """Every canonical joint and foot found by name in URDF, PyBullet and Pinocchio, each 1-DOF revolute."""
    s, kin, bc = ctx.spec, ctx.kin, ctx.bc
    axes_pin = kin.joint_axes()
    _set_link_pose(ctx.world, [0, 0, 0], [0, 0, 0, 1], np.zeros(12))
    problems, rows = [], []
    for i, name in enumerate(s.joint_names):
        j = ctx.world.joint_ids[i]
        info = bc.getJointInfo(ctx.body, j)
        urdf = ctx.joints.get(name)
        rot = np.array(bc.getMatrixFromQuaternion(bc.getLinkState(ctx.body, j, computeForwardKinematics=True)[5]))
        axis_pb = rot.reshape(3, 3) @ np.array(info[13])
        if urdf is None or urdf.type not in ("revolute", "continuous"):
            problems.append(f"{name}: URDF type {None if urdf is None else urdf.type}")
        if info[2] != pybullet.JOINT_REVOLUTE:
            problems.append(f"{name}: PyBullet joint type {info[2]} is not revolute")
        if np.abs(axis_pb - axes_pin[i]).max() > 1e-6:
            problems.append(f"{name}: axis PyBullet {np.round(axis_pb, 4)} != Pinocchio {np.round(axes_pin[i], 4)}")
        rows.append(dict(index=i, joint=f"{LEGS[i // 3]} {JOINT_KINDS[i % 3]}", name=name, pybullet=j,
                         pin_id=int(kin.joint_ids[i]), idx_q=int(kin.idx_q[i]), nq=int(kin.nq[i]),
                         idx_v=int(kin.idx_v[i]), axis=_fmt_axis(axes_pin[i]),
                         urdf_type=None if urdf is None else urdf.type))
    for link in s.foot_links:
        if link not in ctx.links:
            problems.append(f"foot link {link} not in the URDF")
    pin_order = [LEGS[i // 3] for i in np.argsort(kin.joint_ids)[::3]]
    pb_order = [LEGS[i // 3] for i in np.argsort(ctx.world.joint_ids)[::3]]
    n_cont = int((kin.nq == 2).sum())
    fig = (f"12 joints + 4 feet by name in URDF, PyBullet, Pinocchio; leg order PyBullet {','.join(pb_order)}, "
           f"Pinocchio {','.join(pin_order)}; {n_cont} continuous joints (nq=2: cos, sin)")
    return CheckResult("joint mapping (by name)", not problems, fig, problems), rows


def check_layout(ctx: Context) -> CheckResult:
    """Abduction axes along base x, hip and knee along y; default-pose feet in their quadrants."""
    axes = ctx.kin.joint_axes().reshape(4, 3, 3)
    ok_ax = (np.all(np.abs(axes[:, 0, 0]) > 1 - AXIS_TOL)
             and np.all(np.abs(axes[:, 1:, 1]) > 1 - AXIS_TOL))
    feet = ctx.kin.foot_positions_body(ctx.spec.default_pose)
    want = np.array([[1, -1], [1, 1], [-1, -1], [-1, 1]])       # FR, FL, RR, RL signs of x, y
    ok_feet = bool(np.all(np.sign(feet[:, :2]) == want) and np.all(feet[:, 2] < 0))
    sign = lambda v: "+" if v > 0 else "-"  # noqa: E731
    fig = ("abduction axis " + " ".join(f"{leg}{sign(a)}x" for leg, a in zip(LEGS, axes[:, 0, 0]))
           + "; hip " + " ".join(sign(a) + "y" for a in axes[:, 1, 1])
           + "; knee " + " ".join(sign(a) + "y" for a in axes[:, 2, 1])
           + "; default-pose feet below the base, FR/FL/RR/RL in their quadrants" + ("" if ok_feet else ": NO"))
    details = [] if ok_feet else [f"default-pose feet (base frame, m): {np.round(feet, 4).tolist()}"]
    return CheckResult("leg layout and joint axes", bool(ok_ax and ok_feet), fig, details)


def check_base_frame(ctx: Context) -> CheckResult:
    """PyBullet's base pose (inertial frame) equals the URDF base link frame used by Pinocchio."""
    pos, orn = ctx.bc.getDynamicsInfo(ctx.body, -1)[3:5]
    dev = max(np.abs(pos).max(), np.abs(np.array(orn) - [0, 0, 0, 1]).max())
    return CheckResult("PyBullet base pose = URDF base frame", dev < 1e-9,
                       f"base inertial origin xyz {np.round(pos, 6).tolist()}, quat {np.round(orn, 6).tolist()}")


def _limits_source(ctx: Context) -> tuple[str, dict]:
    joints = [ctx.joints.get(n) for n in ctx.spec.joint_names]
    if all(j is not None and j.lower is not None for j in joints):
        return ctx.path, ctx.joints
    rel = LIMITS_URDF.get(ctx.spec.name)
    if rel is None:
        raise ValueError("joints have no limits in the URDF and no limits URDF is known")
    return _pybullet_data(rel), read_urdf(_pybullet_data(rel))[1]


def check_limits(ctx: Context) -> CheckResult:
    """Spec joint limits equal the URDF's (XML, Pinocchio and PyBullet), or the limits URDF's."""
    s, kin = ctx.spec, ctx.kin
    try:
        src, joints = _limits_source(ctx)
    except ValueError as e:
        return CheckResult("joint limits vs spec", False, str(e))
    missing = [n for n in s.joint_names if n not in joints or joints[n].lower is None]
    if missing:
        return CheckResult("joint limits vs spec", False, f"{Path(src).name} lacks limits of {missing}")
    lo = np.array([joints[n].lower for n in s.joint_names])
    hi = np.array([joints[n].upper for n in s.joint_names])
    diffs = {"XML": max(np.abs(lo - s.joint_lower).max(), np.abs(hi - s.joint_upper).max())}
    details = [f"{n}: spec [{a:.4f}, {b:.4f}] vs {Path(src).name} [{c:.4f}, {d:.4f}]"
               for n, a, b, c, d in zip(s.joint_names, s.joint_lower, s.joint_upper, lo, hi)
               if abs(a - c) > LIMIT_TOL or abs(b - d) > LIMIT_TOL]
    if src == ctx.path:
        m = kin.model
        pin_lo, pin_hi = m.lowerPositionLimit[kin.idx_q], m.upperPositionLimit[kin.idx_q]
        diffs["Pinocchio"] = max(np.abs(pin_lo - s.joint_lower).max(), np.abs(pin_hi - s.joint_upper).max())
        info = [ctx.bc.getJointInfo(ctx.body, j) for j in ctx.world.joint_ids]
        pb_lo, pb_hi = np.array([i[8] for i in info]), np.array([i[9] for i in info])
        diffs["PyBullet"] = max(np.abs(pb_lo - s.joint_lower).max(), np.abs(pb_hi - s.joint_upper).max())
        where = f"spec = {Path(src).name} limits"
    else:
        kinds = sorted({ctx.joints[n].type for n in s.joint_names})
        where = (f"{Path(ctx.path).name} joints are {'/'.join(kinds)} (no limits): spec limits come from "
                 f"{Path(src).name}; spec = its limits")
    ok = all(d <= LIMIT_TOL for d in diffs.values())
    fig = where + " (max |diff| " + ", ".join(f"{k} {v:.1e}" for k, v in diffs.items()) + " rad)"
    return CheckResult("joint limits vs spec", ok, fig, details)


def check_default_pose(ctx: Context) -> CheckResult:
    """The spec's default pose lies within the joint limits."""
    v = ctx.kin.limit_violation(ctx.spec.default_pose)
    return CheckResult("default pose within limits", bool(v.max() <= 0.0),
                       f"max violation {v.max():.3g} rad")


def check_mass(ctx: Context) -> CheckResult:
    """Total mass (kg) in the URDF text, Pinocchio and PyBullet vs the spec."""
    import pinocchio as pin

    masses = {"URDF": sum(li.mass for li in ctx.links.values() if li is not None),
              "Pinocchio": pin.computeTotalMass(ctx.kin.model),
              "PyBullet": sum(ctx.world.nominal_mass.values())}
    worst = max(abs(m - ctx.spec.total_mass) for m in masses.values())
    fig = f"spec {ctx.spec.total_mass:.4f} kg; " + ", ".join(f"{k} {v:.4f}" for k, v in masses.items())
    return CheckResult("total mass vs spec", worst <= MASS_TOL, fig + f" (max |diff| {worst:.1e} kg)")


def _inertia_result(name: str, items: list[tuple[str, float, np.ndarray]], what: str) -> CheckResult:
    bad, min_eig, min_margin = [], np.inf, np.inf
    for label, mass, inertia in items:
        ok, eig, margin = inertia_validity(inertia, mass)
        min_eig, min_margin = min(min_eig, eig), min(min_margin, margin)
        if not ok:
            bad.append(f"{label}: mass {mass:.4g} kg, min principal moment {eig:.3e}, triangle margin {margin:.3e}")
    fig = (f"{len(items) - len(bad)}/{len(items)} {what} valid; min principal moment {min_eig:.2e} kg·m², "
           f"min triangle margin (I1+I2-I3) {min_margin:.2e} kg·m²")
    return CheckResult(name, not bad and bool(items), fig, bad)


def check_inertia_urdf(ctx: Context) -> CheckResult:
    """Every URDF link's mass > 0 and inertia positive definite with the triangle inequality."""
    items = [(n, li.mass, li.inertia) for n, li in ctx.links.items() if li is not None]
    res = _inertia_result("inertias valid (URDF numbers)", items, "links")
    res.details += [f"{n}: no <inertial>" for n, li in ctx.links.items() if li is None]
    res.ok = res.ok and all(li is not None for li in ctx.links.values())
    return res


def check_inertia_pinocchio(ctx: Context) -> CheckResult:
    """The same on Pinocchio's bodies (links welded by fixed joints are lumped together)."""
    m = ctx.kin.model
    items = [(m.names[j], m.inertias[j].mass, np.array(m.inertias[j].inertia)) for j in range(1, m.njoints)]
    return _inertia_result("inertias valid (Pinocchio)", items, "bodies")


def _set_link_pose(world, pos, quat, q) -> None:
    """Place the robot so its base LINK frame is at (pos, quat): PyBullet's base pose is the inertial frame."""
    bc = world.bc
    ipos, iorn = bc.getDynamicsInfo(world.robot, -1)[3:5]
    p, o = bc.multiplyTransforms(list(pos), list(quat), ipos, iorn)
    world.set_pose(p, o, q)


def check_fk(ctx: Context, samples: int = 100, seed: int = 0) -> CheckResult:
    """Foot positions by Pinocchio FK vs PyBullet over random base poses and joint angles in limits.

    PyBullet keeps poses in single precision (about 1e-7 relative), so agreement is
    ~1e-7 m near the origin and grows with distance: base positions stay within 1 m.
    """
    rng = np.random.default_rng(seed)
    s, worst = ctx.spec, 0.0
    for _ in range(samples):
        pos = rng.uniform([-1, -1, 0], [1, 1, 1])
        quat = random_quat(rng)
        q = rng.uniform(s.joint_lower, s.joint_upper)
        _set_link_pose(ctx.world, pos, quat, q)
        diff = ctx.world.foot_positions() - ctx.kin.foot_positions(pos, quat, q)
        worst = max(worst, float(np.linalg.norm(diff, axis=1).max()))
    return CheckResult("FK feet Pinocchio vs PyBullet", worst < FK_TOL,
                       f"max error {worst:.2e} m over {samples} random configs x 4 feet "
                       f"(random base pose within 1 m, angles uniform in limits; tol {FK_TOL:.0e} m)")


def check_feet_on_ground(ctx: Context) -> CheckResult:
    """Default pose at the spawn height: foot sphere bottoms (PyBullet and Pinocchio) at z = 0."""
    ctx.world.reset()
    s = ctx.spec
    heights = ctx.world.foot_positions()[:, 2] - s.foot_radius
    pin_h = ctx.kin.foot_positions([0, 0, s.spawn_height], [0, 0, 0, 1], s.default_pose)[:, 2] - s.foot_radius
    worst = max(np.abs(heights).max(), np.abs(pin_h).max())
    fig = (f"spawn {s.spawn_height} m, foot radius {s.foot_radius} m; sphere bottom z: "
           + ", ".join(f"{leg} {1e3 * h:+.2f} mm" for leg, h in zip(LEGS, heights))
           + f" (Pinocchio max |z| {1e3 * np.abs(pin_h).max():.2f} mm; tol {1e3 * FEET_GROUND_TOL:.0f} mm)")
    return CheckResult("feet on the ground at default pose", worst <= FEET_GROUND_TOL, fig)


def check_self_collision(ctx: Context) -> CheckResult:
    """No pair of non-adjacent links touches in the default pose (PyBullet, margin 0)."""
    ctx.world.reset()
    pairs = ctx.world.self_collisions(0.0)
    bc = ctx.bc

    def name(link: int) -> str:
        return bc.getBodyInfo(ctx.body)[0].decode() if link < 0 else bc.getJointInfo(ctx.body, link)[12].decode()

    details = []
    for a, b in pairs:
        d = min(c[8] for c in bc.getClosestPoints(ctx.body, ctx.body, 0.0, a, b))
        details.append(f"{name(a)} / {name(b)}: distance {1e3 * d:.2f} mm")
    # the closest non-adjacent pair within 5 cm, for scale
    near = [(c[8], a, b) for a, b in ctx.world.self_collisions(0.05)
            for c in bc.getClosestPoints(ctx.body, ctx.body, 0.05, a, b)]
    closest = min(near) if near else None
    fig = f"{len(pairs)} touching pairs of non-adjacent links" + (": " + "; ".join(details) if details else "")
    if closest is not None:
        fig += f"; closest pair {name(closest[1])} / {name(closest[2])} {1e3 * closest[0]:.2f} mm"
    return CheckResult("no self-collision at default pose", not pairs, fig)


def check_limits_urdf_equivalence(ctx: Context, samples: int = 100, seed: int = 1) -> CheckResult:
    """Laikago: the limits URDF (motion_imitation's) and the z-up URDF put the toes at the same place
    for the same joint angles, once a clip root pose goes through ``laikago_clip_root_to_zup``."""
    rel = LIMITS_URDF[ctx.spec.name]
    other = _world(dataclasses.replace(ctx.spec, urdf=rel, urdf_in_pybullet_data=True))
    rng = np.random.default_rng(seed)
    worst = 0.0
    try:
        for _ in range(samples):
            pos, quat = rng.uniform([-1, -1, 0], [1, 1, 1]), random_quat(rng)
            q = rng.uniform(ctx.spec.joint_lower, ctx.spec.joint_upper)
            other.set_pose(pos, quat, q)
            zpos, zquat = laikago_clip_root_to_zup(pos, quat)
            ctx.world.set_pose(zpos, zquat, q)
            diff = other.foot_positions() - ctx.world.foot_positions()
            worst = max(worst, float(np.linalg.norm(diff, axis=1).max()))
    finally:
        other.close()
    return CheckResult(f"{Path(rel).name} = z-up URDF kinematics", worst < LIMITS_URDF_TOL,
                       f"toe max error {worst:.2e} m over {samples} random clip roots + angles "
                       f"(same joint angles; root via laikago_clip_root_to_zup; tol {LIMITS_URDF_TOL:.0e} m)")


def run_checks(spec: RobotSpec, samples: int = 100, seed: int = 0) -> RobotReport:
    """Run every check for ``spec``; a robot that cannot be loaded gets one failing 'load' row."""
    try:
        ctx = Context(spec)
    except Exception as e:  # noqa: BLE001 - reported as a FAIL row, not a traceback
        return RobotReport(spec, [CheckResult("load URDF (Pinocchio, PyBullet)", False, f"{type(e).__name__}: {e}")])
    try:
        try:
            mapping, rows = check_mapping(ctx)
        except Exception as e:  # noqa: BLE001
            mapping, rows = CheckResult("joint mapping (by name)", False, f"{type(e).__name__}: {e}"), []
        checks = [check_layout, check_base_frame, check_limits, check_default_pose, check_mass,
                  check_inertia_urdf, check_inertia_pinocchio, lambda c: check_fk(c, samples, seed),
                  check_feet_on_ground, check_self_collision]
        if spec.name in LIMITS_URDF and not all(ctx.joints[n].lower is not None for n in spec.joint_names):
            checks.append(lambda c: check_limits_urdf_equivalence(c, samples, seed + 1))
        return RobotReport(spec, [mapping] + [_guarded(check, ctx) for check in checks], rows)
    finally:
        ctx.close()


def _guarded(check, ctx: Context) -> CheckResult:
    """Run one check; an exception inside it becomes a FAIL row naming the check."""
    try:
        return check(ctx)
    except Exception as e:  # noqa: BLE001 - reported, not raised
        name = getattr(check, "__name__", "check").removeprefix("check_").replace("_", " ")
        return CheckResult(name, False, f"error: {type(e).__name__}: {e}")
