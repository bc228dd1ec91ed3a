"""Write ``pupper.urdf`` (Stanford Pupper v2) from the public figures in ROBOTS.md.

Run ``python robots/pupper/generate.py`` after changing a number; the URDF is
committed beside this script. Shapes are boxes and spheres so the 48x48
renders stay cheap; every inertia is computed from its shape and mass.

Frames: base x forward, y left, z up. Each leg: abduction joint (axis +x) at
the hip, hip pitch joint (axis +y) 0.02 m further out, knee (axis +y) 0.08 m
below the hip, foot sphere centre 0.11 m below the knee. With these axes a
positive hip angle swings the upper leg backwards and a negative knee angle
folds the lower leg forwards, so the standing pose is (0, +0.6, -1.2) rad.
"""

from __future__ import annotations

from pathlib import Path

BODY = (0.276, 0.100, 0.050)          # m, body box
BODY_MASS = 0.991                     # kg
HIP_X, HIP_Y = 0.10, 0.04             # m, abduction joints from the body centre
ABD_OFFSET = 0.02                     # m, upper leg hangs this much further out
UPPER_LEN, LOWER_LEN = 0.08, 0.11     # m
HIP_MASS, UPPER_MASS, LOWER_MASS = 0.106, 0.142, 0.038  # kg
FOOT_RADIUS = 0.013                   # m
FOOT_MASS = 0.005                     # kg, taken out of the lower leg's 0.038 kg
HIP_BOX = (0.040, 0.030, 0.030)       # m, abduction motor housing
UPPER_BOX = (0.022, 0.016, UPPER_LEN)
LOWER_BOX = (0.012, 0.010, LOWER_LEN)
# rad: abduction, hip, knee. Effort N·m, velocity rad/s.
LIMITS = {"abduction": (-0.6, 0.6), "hip": (-0.6, 1.8), "knee": (-2.6, -0.2)}
EFFORT, VELOCITY = 1.7, 25.0
DAMPING, FRICTION = 0.0045, 0.021     # N·m·s/rad, N·m
# kg·m², reflected rotor inertia (armature) of the geared motors, added about
# each joint axis: it is what keeps the very light lower leg numerically stable
# under the PD gains (see virl_quad/sim/pd.py).
ARMATURE = 2.0e-4

LEGS = {"FR": (1, -1), "FL": (1, 1), "RR": (-1, -1), "RL": (-1, 1)}


def box_inertia(m: float, sx: float, sy: float, sz: float) -> tuple[float, float, float]:
    """Principal inertias (kg·m²) of a solid box about its centre."""
    return (m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12)


def sphere_inertia(m: float, r: float) -> tuple[float, float, float]:
    """Principal inertias (kg·m²) of a solid sphere."""
    i = 2 * m * r**2 / 5
    return (i, i, i)


def inertial(m: float, xyz: tuple[float, float, float], diag: tuple[float, float, float]) -> str:
    ixx, iyy, izz = diag
    x, y, z = xyz
    return (f'    <inertial>\n      <origin xyz="{x:.6g} {y:.6g} {z:.6g}"/>\n'
            f'      <mass value="{m:.6g}"/>\n'
            f'      <inertia ixx="{ixx:.6e}" ixy="0" ixz="0" iyy="{iyy:.6e}" iyz="0" izz="{izz:.6e}"/>\n'
            '    </inertial>\n')


def geom(tag: str, shape: str, xyz: tuple[float, float, float], material: str = "") -> str:
    x, y, z = xyz
    mat = f'      <material name="{material}"/>\n' if material and tag == "visual" else ""
    return (f'    <{tag}>\n      <origin xyz="{x:.6g} {y:.6g} {z:.6g}"/>\n'
            f'      <geometry>{shape}</geometry>\n{mat}    </{tag}>\n')


def box(size: tuple[float, float, float]) -> str:
    return f'<box size="{size[0]:.6g} {size[1]:.6g} {size[2]:.6g}"/>'


def link(name: str, m: float, com: tuple[float, float, float], diag: tuple[float, float, float],
         shape: str, material: str, collide: bool = True) -> str:
    body = inertial(m, com, diag) + geom("visual", shape, com, material)
    if collide:
        body += geom("collision", shape, com)
    return f'  <link name="{name}">\n{body}  </link>\n'


def joint(name: str, kind: str, parent: str, child: str, xyz: tuple[float, float, float],
          axis: tuple[int, int, int] = (0, 1, 0), limit: tuple[float, float] | None = None) -> str:
    x, y, z = xyz
    s = (f'  <joint name="{name}" type="{kind}">\n    <parent link="{parent}"/>\n'
         f'    <child link="{child}"/>\n    <origin xyz="{x:.6g} {y:.6g} {z:.6g}"/>\n')
    if kind == "revolute":
        s += f'    <axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>\n'
        s += (f'    <limit lower="{limit[0]}" upper="{limit[1]}" effort="{EFFORT}" '
              f'velocity="{VELOCITY}"/>\n')
        s += f'    <dynamics damping="{DAMPING}" friction="{FRICTION}"/>\n'
    return s + "  </joint>\n"


def with_armature(diag: tuple[float, float, float]) -> tuple[float, float, float]:
    """Add the rotor's reflected inertia on all three principal axes.

    Adding the same amount to every axis keeps the tensor physically valid
    (triangle inequality), which adding it to the joint axis alone would not.
    """
    return tuple(d + ARMATURE for d in diag)


def leg(name: str, sx: int, sy: int) -> str:
    out = ""
    hip = f"{name}_hip"
    upper = f"{name}_upper_leg"
    lower = f"{name}_lower_leg"
    foot = f"{name}_foot"
    hip_com = (0.0, sy * ABD_OFFSET / 2, 0.0)
    out += joint(f"{name}_abduction_joint", "revolute", "base_link", hip,
                 (sx * HIP_X, sy * HIP_Y, 0.0), (1, 0, 0), LIMITS["abduction"])
    out += link(hip, HIP_MASS, hip_com, with_armature(box_inertia(HIP_MASS, *HIP_BOX)),
                box(HIP_BOX), "dark", collide=False)
    out += joint(f"{name}_hip_joint", "revolute", hip, upper, (0.0, sy * ABD_OFFSET, 0.0),
                 (0, 1, 0), LIMITS["hip"])
    out += link(upper, UPPER_MASS, (0.0, 0.0, -UPPER_LEN / 2),
                with_armature(box_inertia(UPPER_MASS, *UPPER_BOX)),
                box(UPPER_BOX), "light")
    out += joint(f"{name}_knee_joint", "revolute", upper, lower, (0.0, 0.0, -UPPER_LEN),
                 (0, 1, 0), LIMITS["knee"])
    lower_mass = LOWER_MASS - FOOT_MASS
    out += link(lower, lower_mass, (0.0, 0.0, -LOWER_LEN / 2),
                with_armature(box_inertia(lower_mass, *LOWER_BOX)),
                box(LOWER_BOX), "dark", collide=False)
    out += joint(f"{name}_foot_joint", "fixed", lower, foot, (0.0, 0.0, -LOWER_LEN))
    out += link(foot, FOOT_MASS, (0.0, 0.0, 0.0), sphere_inertia(FOOT_MASS, FOOT_RADIUS),
                f'<sphere radius="{FOOT_RADIUS}"/>', "dark")
    return out


def urdf() -> str:
    """The whole URDF text."""
    s = '<?xml version="1.0"?>\n<!-- Generated by robots/pupper/generate.py: edit that, not this. -->\n'
    s += '<robot name="pupper">\n'
    s += '  <material name="light"><color rgba="0.85 0.85 0.85 1"/></material>\n'
    s += '  <material name="dark"><color rgba="0.25 0.25 0.25 1"/></material>\n'
    s += link("base_link", BODY_MASS, (0.0, 0.0, 0.0), box_inertia(BODY_MASS, *BODY), box(BODY), "light")
    for name, (sx, sy) in LEGS.items():
        s += leg(name, sx, sy)
    return s + "</robot>\n"


if __name__ == "__main__":
    out = Path(__file__).with_name("pupper.urdf")
    out.write_text(urdf())
    print(f"wrote {out}")
