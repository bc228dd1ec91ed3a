"""Read the numbers a URDF states (XML only, no simulator): link inertials and joints.

Used by the checks to compare what the file says with what Pinocchio and
PyBullet made of it. Units as in URDF: m, rad, kg, kg·m².
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class UrdfInertial:
    """One link's ``<inertial>``: mass (kg), COM origin (m, rad) and inertia (kg·m², about the COM)."""

    link: str
    mass: float
    xyz: np.ndarray
    rpy: np.ndarray
    inertia: np.ndarray  # (3, 3) symmetric, in the inertial origin's frame


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>``: type, parent/child links, origin, axis, limits (None when absent)."""

    name: str
    type: str
    parent: str
    child: str
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray
    lower: float | None
    upper: float | None


def _vec(el: ET.Element | None, attr: str, default: str = "0 0 0") -> np.ndarray:
    text = default if el is None else el.get(attr, default)
    return np.array([float(v) for v in text.split()], dtype=np.float64)


def read_urdf(path: str) -> tuple[dict[str, UrdfInertial | None], dict[str, UrdfJoint]]:
    """Links (name -> inertial, None when the link has none) and joints (name -> joint), file order."""
    root = ET.parse(path).getroot()
    links: dict[str, UrdfInertial | None] = {}
    for link in root.findall("link"):
        name = link.get("name")
        inertial = link.find("inertial")
        if inertial is None:
            links[name] = None
            continue
        origin = inertial.find("origin")
        mass_el = inertial.find("mass")
        mass = float(mass_el.get("value")) if mass_el is not None else 0.0
        i_el = inertial.find("inertia")
        g = (lambda k: float(i_el.get(k, "0"))) if i_el is not None else (lambda k: 0.0)
        inertia = np.array([[g("ixx"), g("ixy"), g("ixz")],
                            [g("ixy"), g("iyy"), g("iyz")],
                            [g("ixz"), g("iyz"), g("izz")]])
        links[name] = UrdfInertial(name, mass, _vec(origin, "xyz"), _vec(origin, "rpy"), inertia)
    joints: dict[str, UrdfJoint] = {}
    for joint in root.findall("joint"):
        origin = joint.find("origin")
        limit = joint.find("limit")
        kind = joint.get("type")
        has_limits = limit is not None and kind in ("revolute", "prismatic") and "lower" in limit.attrib
        joints[joint.get("name")] = UrdfJoint(
            name=joint.get("name"), type=kind,
            parent=joint.find("parent").get("link"), child=joint.find("child").get("link"),
            xyz=_vec(origin, "xyz"), rpy=_vec(origin, "rpy"), axis=_vec(joint.find("axis"), "xyz", "1 0 0"),
            lower=float(limit.get("lower")) if has_limits else None,
            upper=float(limit.get("upper", "0")) if has_limits else None,
        )
    return links, joints


def inertia_validity(inertia: np.ndarray, mass: float, rel_tol: float = 1e-9) -> tuple[bool, float, float]:
    """Whether a rotational inertia (about the COM) is physically valid.

    Valid: mass > 0, the tensor symmetric and positive definite, and its principal
    moments obey the triangle inequality ``I1 + I2 >= I3``. Returns
    ``(ok, smallest principal moment, smallest triangle margin min(Ia + Ib - Ic))``, kg·m².
    """
    inertia = np.asarray(inertia, dtype=np.float64)
    symmetric = np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-12)
    eig = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    margin = float(eig[0] + eig[1] - eig[2])  # sorted ascending: the tightest of the three
    scale = max(float(eig[2]), 1e-300)
    ok = bool(mass > 0 and symmetric and eig[0] > rel_tol * scale and eig[0] > 0
              and margin >= -rel_tol * scale)
    return ok, float(eig[0]), margin
