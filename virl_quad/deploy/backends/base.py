"""The interface every robot backend implements, and the backend registry.

A backend is what the HAL loop talks to once per control period::

    with get_backend("pupper_serial", port="/dev/ttyACM0") as robot:
        state = robot.read_state()          # RobotState, canonical joint order
        robot.write_command(safety.tick(state))

Backends do no safety logic beyond refusing malformed commands (wrong shape,
NaN/inf) with ValueError: :mod:`virl_quad.deploy.safety` decides what is safe.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from typing import Any, Callable, Union

import numpy as np

from virl_quad.deploy.protocol import NUM_FEET, NUM_JOINTS, JointCommand, RobotState


class BackendError(RuntimeError):
    """The robot (or simulator) could not be read or written."""


class BackendTimeout(BackendError):
    """No fresh state arrived within the backend's timeout."""


def check_command(cmd: JointCommand) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (q_target, kp, kd, tau_ff) as float arrays; ValueError if a field is not 12
    finite values or a gain is negative. Last line of defence in every backend."""
    out = []
    for name in ("q_target", "kp", "kd", "tau_ff"):
        a = np.asarray(getattr(cmd, name), dtype=np.float64)
        if a.shape != (NUM_JOINTS,) or not np.all(np.isfinite(a)):
            raise ValueError(f"command field {name} must be {NUM_JOINTS} finite values")
        out.append(a)
    if np.any(out[1] < 0) or np.any(out[2] < 0):
        raise ValueError("command gains kp, kd must be non-negative")
    return out[0], out[1], out[2], out[3]


def resolve_spec(spec: Any) -> Any:
    """A RobotSpec from a spec or a robot name ("pupper", "laikago")."""
    if isinstance(spec, str):
        from virl_quad import robots

        return robots.get(spec)
    return spec


class Backend(ABC):
    """One robot or simulator, read and written once per control period."""

    #: registry name, set by subclasses
    name: str = ""

    def __init__(self, spec: Any) -> None:
        self.spec = resolve_spec(spec)   # virl_quad.robots.RobotSpec (or a robot name)
        self.closed = False

    @property
    def control_dt(self) -> float:
        """Control period in s."""
        return float(self.spec.control_dt)

    @abstractmethod
    def read_state(self) -> RobotState:
        """Return the latest measurement; raise BackendError (e.g. BackendTimeout) if none."""

    @abstractmethod
    def write_command(self, cmd: JointCommand) -> None:
        """Apply one joint PD command (the HAL passes only SafetyController.tick() outputs)."""

    def close(self) -> None:
        """Release the robot (hardware backends leave it damped). Safe to call twice."""
        self.closed = True

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class LoopbackBackend(Backend):
    """A robot without hardware: each joint is a point inertia driven by the PD law with
    torque saturation. For HAL and safety tests; no contacts, no gravity, level base."""

    name = "loopback"

    def __init__(self, spec: Any, inertia: float = 0.01, substeps: int = 10,
                 q0: np.ndarray | None = None) -> None:
        super().__init__(spec)
        spec = self.spec
        self.inertia = inertia          # kg·m² per joint
        self.substeps = substeps
        self.q = np.array(spec.default_pose if q0 is None else q0, dtype=np.float64)   # rad
        self.dq = np.zeros(NUM_JOINTS)  # rad/s
        self.tau = np.zeros(NUM_JOINTS)  # N·m
        self.quat = np.array([0.0, 0.0, 0.0, 1.0])   # settable by tests (x, y, z, w)
        self.time = 0.0                 # s
        self.commands: list[JointCommand] = []

    def read_state(self) -> RobotState:
        """Current joint state, level base, unknown contacts."""
        if self.closed:
            raise BackendError("loopback backend is closed")
        return RobotState(q=self.q.copy(), dq=self.dq.copy(), tau=self.tau.copy(), quat=self.quat.copy(),
                          gyro=np.zeros(3), accel=np.array([0.0, 0.0, 9.81]),
                          contacts=np.full(NUM_FEET, np.nan), timestamp=self.time)

    def write_command(self, cmd: JointCommand) -> None:
        """Integrate the PD law for one control period (semi-implicit Euler)."""
        if self.closed:
            raise BackendError("loopback backend is closed")
        q_t, kp, kd, ff = check_command(cmd)
        self.commands.append(cmd)
        h = self.control_dt / self.substeps
        for _ in range(self.substeps):
            tau = kp * (q_t - self.q) - kd * self.dq + ff
            self.tau = np.clip(tau, -self.spec.torque_limit, self.spec.torque_limit)
            self.dq = self.dq + h * self.tau / self.inertia
            self.q = self.q + h * self.dq
        self.time += self.control_dt


# ----------------------------------------------------------------------------- registry

#: name -> Backend subclass, or "module:ClassName" imported on first use.
BACKENDS: dict[str, Union[str, Callable[..., Backend]]] = {
    "loopback": LoopbackBackend,
    "pupper_serial": "virl_quad.deploy.backends.pupper_serial:PupperSerialBackend",
    "sim": "virl_quad.deploy.backends.sim:SimBackend",   # PyBullet backend (module added separately)
}


def register_backend(name: str, target: Union[str, Callable[..., Backend]]) -> None:
    """Register a backend class (or a lazy "module:ClassName" path) under ``name``."""
    if isinstance(target, str) and ":" not in target:
        raise ValueError(f"lazy backend target must look like 'package.module:ClassName', got {target!r}")
    BACKENDS[name] = target


def backend_names() -> tuple[str, ...]:
    """Names of the registered backends."""
    return tuple(BACKENDS)


def get_backend(name: str, **kwargs: Any) -> Backend:
    """Construct backend ``name`` with ``kwargs``; ValueError naming the valid choices if
    unknown, BackendError if its module cannot be imported."""
    target = BACKENDS.get(name) if isinstance(name, str) else None
    if target is None:
        raise ValueError(f"unknown backend {name!r}; choose one of: {', '.join(BACKENDS)}")
    if isinstance(target, str):
        module_name, _, attr = target.partition(":")
        try:
            target = getattr(importlib.import_module(module_name), attr)
        except (ImportError, AttributeError) as e:
            raise BackendError(f"backend {name!r} ({module_name}:{attr}) is not available: {e}") from e
    return target(**kwargs)
