"""PyBullet simulation backend: the HAL's robot is :class:`virl_quad.sim.world.World`.

>>> with SimBackend("pupper") as robot:                                   # doctest: +SKIP
...     state = robot.read_state()                 # protocol RobotState, sim time stamp
...     robot.write_command(safety.tick(state))    # one control period of explicit PD

Each :meth:`SimBackend.write_command` advances the simulation by exactly one control period
(``spec.substeps`` physics steps) with the command's targets AND gains, so the HAL's safety
layer drives the simulated motors exactly as it would drive real ones. With
``randomize=True`` the physics (masses, inertia, friction, motor strength, gain errors) are
drawn once from :class:`virl_quad.envs.randomize.DRConfig` with ``seed``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virl_quad.deploy.backends.base import Backend, BackendError, check_command
from virl_quad.deploy.protocol import NUM_JOINTS, JointCommand, RobotState

GRAVITY = 9.81  # m/s²


class SimBackend(Backend):
    """A simulated robot on a flat ground plane (see the module docstring)."""

    name = "sim"

    def __init__(self, spec: Any = "pupper", randomize: bool = False, seed: int = 0,
                 dr: Any | None = None) -> None:
        """``spec``: RobotSpec or robot name; ``randomize``: draw physics parameters with
        ``seed`` from ``dr`` (a DRConfig; the robot's default ranges if None)."""
        super().__init__(spec)
        from virl_quad.sim.world import World   # pybullet is imported only when a sim is made

        self.world = World(self.spec)
        self.randomization = None
        if randomize:
            from virl_quad.envs.randomize import DRConfig, sample

            self.randomization = sample(dr or DRConfig.for_robot(self.spec), np.random.default_rng(seed), self.spec)
            self.world.apply_params(self.randomization.physics)
        self.world.reset()
        self._accel_world = np.zeros(3)         # m/s², base acceleration over the last period

    # ------------------------------------------------------------------ Backend interface

    def read_state(self) -> RobotState:
        """The simulated measurement: IMU (quat, gyro, accelerometer), encoders, contacts, and
        the base position and velocity (simulation only); ``timestamp`` = sim time (s)."""
        if self.closed:
            raise BackendError("sim backend is closed")
        s = self.world.state()
        rot = np.array(self.world.bc.getMatrixFromQuaternion(s.base_quat)).reshape(3, 3)  # body -> world
        # accelerometer: specific force = acceleration - gravity, in the body frame (m/s²)
        accel_body = rot.T @ (self._accel_world + np.array([0.0, 0.0, GRAVITY]))
        return RobotState(
            q=s.q.copy(), dq=s.dq.copy(), tau=s.tau.copy(), quat=s.base_quat.copy(),
            gyro=s.base_ang_vel_body.copy(), accel=accel_body,
            contacts=s.foot_contact.astype(np.float64), timestamp=float(s.time),
            base_pos=s.base_pos.copy(), base_vel=s.base_lin_vel.copy(),
        )

    def write_command(self, cmd: JointCommand) -> None:
        """Simulate one control period of ``tau = kp (q_target - q) - kd dq + tau_ff`` (saturated
        at the torque limit). Gains are scaled by the drawn gain errors when randomised."""
        if self.closed:
            raise BackendError("sim backend is closed")
        q_t, kp, kd, ff = check_command(cmd)
        params = self.world.params
        v0 = np.array(self.world.bc.getBaseVelocity(self.world.robot)[0])
        self.world.step(q_t, ff, kp=kp * params.kp_scale, kd=kd * params.kd_scale)
        v1 = np.array(self.world.bc.getBaseVelocity(self.world.robot)[0])
        self._accel_world = (v1 - v0) / self.control_dt

    def close(self) -> None:
        """One damped period (kp 0, spec kd), then disconnect the simulator. Safe twice."""
        if self.closed:
            return
        try:
            q, _ = self.world.joint_states()
            damp = JointCommand(q, np.zeros(NUM_JOINTS), np.array(self.spec.kd, dtype=np.float64),
                                np.zeros(NUM_JOINTS))
            self.write_command(damp)
        except Exception:   # the simulator may already be gone; closing must not fail
            pass
        finally:
            self.closed = True
            self.world.close()

    # ------------------------------------------------------------------ simulation extras

    def reset(self) -> None:
        """Put the robot back on its feet (default pose, spawn height, at rest), as an operator
        would before re-arming; the simulation clock keeps running."""
        if self.closed:
            raise BackendError("sim backend is closed")
        t = self.world.time
        self.world.reset()
        self.world.time = t
        self._accel_world = np.zeros(3)

    @property
    def sim_time(self) -> float:
        """Simulated time since reset, s."""
        return float(self.world.time)
