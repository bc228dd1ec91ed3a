"""Robot registry: ``get(name) -> RobotSpec``.

>>> from virl_quad import robots
>>> robots.get("pupper").control_hz
50.0
"""

from __future__ import annotations

from virl_quad.robots import laikago, pupper
from virl_quad.robots.spec import JOINT_KINDS, LEGS, NUM_JOINTS, RobotSpec

REGISTRY: dict[str, RobotSpec] = {
    pupper.SPEC.name: pupper.SPEC,
    laikago.SPEC.name: laikago.SPEC,
}


def names() -> tuple[str, ...]:
    """Names of the registered robots."""
    return tuple(REGISTRY)


def get(name: str | RobotSpec) -> RobotSpec:
    """Return the spec of robot ``name``; raise ValueError naming the valid choices. A
    :class:`RobotSpec` is returned as it is, so every function taking a robot takes either a
    name (command lines, files) or the spec object itself (a variant the registry does not hold)."""
    if isinstance(name, RobotSpec):
        return name
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown robot {name!r}; choose one of: {', '.join(REGISTRY)}") from None


__all__ = ["get", "names", "RobotSpec", "LEGS", "JOINT_KINDS", "NUM_JOINTS", "REGISTRY"]
