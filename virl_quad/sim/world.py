"""A PyBullet world with one quadruped (and optionally a kinematic 'ghost' copy).

The world owns its own DIRECT physics client, so several worlds can live in
one process. It knows nothing about rewards or episodes: it steps PD control,
reads state and renders. Arrays use the canonical joint order of the spec.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from virl_quad.quiet import import_pybullet_quietly

import_pybullet_quietly()   # first: its build-time banner would break the CLIs' one-line errors
import pybullet  # noqa: E402
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from virl_quad.quiet import quiet_fd
from virl_quad.robots.spec import RobotSpec
from virl_quad.sim import camera
from virl_quad.sim import ground as ground_mod
from virl_quad.sim.params import DEFAULT_GROUND, PhysicsParams
from virl_quad.sim.pd import PD_MODES, pd_motor, pd_torque

GRAVITY = 9.81  # m/s²
_PARK = (0.0, 0.0, -50.0)  # m, where a body not being rendered waits
GROUND_RENDERERS = ("numpy", "tiny")


@dataclass
class SimState:
    """What the simulator knows about the robot at one instant, privileged parts included (SI units,
    canonical joint order); the robot-side measurement is :class:`virl_quad.deploy.protocol.RobotState`."""

    time: float                    # s since reset
    base_pos: np.ndarray           # m, world (3)
    base_quat: np.ndarray          # xyzw, world (4)
    base_lin_vel: np.ndarray       # m/s, world (3)
    base_ang_vel: np.ndarray       # rad/s, world (3)
    base_lin_vel_body: np.ndarray  # m/s, body frame (3)
    base_ang_vel_body: np.ndarray  # rad/s, body frame (3) = the IMU gyro
    rpy: np.ndarray                # rad, roll pitch yaw (3)
    q: np.ndarray                  # rad (12)
    dq: np.ndarray                 # rad/s (12)
    tau: np.ndarray                # N·m, the PD law's torque in the last physics step, clipped (12)
    foot_contact: np.ndarray       # bool (4), FR FL RR RL
    fall_contact: bool             # a body/thigh link touches the ground


class World:
    """One robot (plus an optional ghost) on a ground plane (``ground``: one of
    :data:`~virl_quad.sim.params.GROUNDS`); ``pd``: how the joint PD is stepped, one of
    :data:`~virl_quad.sim.pd.PD_MODES`; ``ground_renderer``: who draws the ground in renders,
    ``"numpy"`` (the default, :mod:`virl_quad.sim.ground`) or ``"tiny"`` (TinyRenderer, the
    reference the numpy ground is tested against: the same picture, slower)."""

    def __init__(self, spec: RobotSpec, *, ghost: bool = False, ground: str = DEFAULT_GROUND,
                 pd: str = "implicit", ground_renderer: str = "numpy") -> None:
        if pd not in PD_MODES:
            raise ValueError(f"unknown PD mode {pd!r}; choose one of: {', '.join(PD_MODES)}")
        if ground_renderer not in GROUND_RENDERERS:
            raise ValueError(f"unknown ground renderer {ground_renderer!r}; choose one of: "
                             f"{', '.join(GROUND_RENDERERS)}")
        ground_mod.check_ground(ground)
        self.spec = spec
        self.pd = pd
        with quiet_fd(1):  # PyBullet prints 'argv[0]=' from C when it connects
            self.bc = BulletClient(connection_mode=pybullet.DIRECT)
        self.client = self.bc._client
        bc = self.bc
        bc.setAdditionalSearchPath(pybullet_data.getDataPath())
        bc.setGravity(0, 0, -GRAVITY)
        bc.setPhysicsEngineParameter(fixedTimeStep=spec.sim_dt, numSolverIterations=10,
                                   deterministicOverlappingPairs=1)
        self.ground = bc.loadURDF("plane100.urdf", useMaximalCoordinates=True)
        if ground_renderer == "tiny":
            bc.changeVisualShape(self.ground, -1, textureUniqueId=bc.loadTexture(ground_mod.texture_path(ground)),
                                 rgbaColor=[1, 1, 1, 1])
        else:   # invisible to TinyRenderer; camera.render draws it
            bc.changeVisualShape(self.ground, -1, rgbaColor=[1, 1, 1, 0])
        self._drawn_ground = ground if ground_renderer == "numpy" else None
        self.robot = self._load_robot()
        self.ghost = self._load_robot(ghost=True) if ghost else None
        info = [bc.getJointInfo(self.robot, j) for j in range(bc.getNumJoints(self.robot))]
        by_joint = {i[1].decode(): i[0] for i in info}
        by_link = {i[12].decode(): i[0] for i in info}
        by_link[bc.getBodyInfo(self.robot)[0].decode()] = -1
        missing = [n for n in spec.joint_names if n not in by_joint]
        if missing:
            raise ValueError(f"URDF {spec.urdf_path} lacks joints {missing}")
        self.joint_ids = [by_joint[n] for n in spec.joint_names]
        self.foot_ids = [by_link[n] for n in spec.foot_links]
        self.fall_ids = {by_link[n] for n in spec.contact_fall_links}
        self.link_ids = [-1] + [i[0] for i in info]
        self.nominal_mass = {l: bc.getDynamicsInfo(self.robot, l)[0] for l in self.link_ids}
        self.nominal_inertia = {l: np.array(bc.getDynamicsInfo(self.robot, l)[2]) for l in self.link_ids}
        self.params = PhysicsParams()
        self.kp = np.array(spec.kp, dtype=np.float64)
        self.kd = np.array(spec.kd, dtype=np.float64)
        self.torque_limit = np.array(spec.torque_limit, dtype=np.float64)
        self.tau = np.zeros(12)
        self.time = 0.0
        self.apply_params(self.params)

    # -- construction -------------------------------------------------------------------------
    def _load_robot(self, ghost: bool = False) -> int:
        s, bc = self.spec, self.bc
        flags = pybullet.URDF_USE_INERTIA_FROM_FILE
        body = bc.loadURDF(s.urdf_path, [0, 0, s.spawn_height], flags=flags)
        n = bc.getNumJoints(body)
        # Switch off PyBullet's default velocity motors: torques come from our PD.
        bc.setJointMotorControlArray(body, list(range(n)), pybullet.VELOCITY_CONTROL, forces=[0.0] * n)
        if ghost:
            for link in range(-1, n):
                bc.setCollisionFilterGroupMask(body, link, 0, 0)
            bc.resetBasePositionAndOrientation(body, _PARK, [0, 0, 0, 1])
        return body

    def apply_params(self, params: PhysicsParams) -> None:
        """Apply physical parameters (masses, inertia, gains, friction, ground) to the agent."""
        bc, s = self.bc, self.spec
        self.params = params
        for link in self.link_ids:
            mass = self.nominal_mass[link] * params.mass_scale + (params.payload if link == -1 else 0.0)
            scale = mass / self.nominal_mass[link] if self.nominal_mass[link] > 0 else 1.0
            inertia = self.nominal_inertia[link] * scale * params.inertia_scale
            bc.changeDynamics(self.robot, link, mass=mass, localInertiaDiagonal=inertia.tolist())
        friction = s.joint_friction if params.joint_friction is None else params.joint_friction
        self.friction = float(friction)   # N·m
        damping = s.joint_damping if params.joint_damping is None else params.joint_damping
        for j in self.joint_ids:
            bc.changeDynamics(self.robot, j, jointDamping=damping, linearDamping=0.0, angularDamping=0.0)
        # Coulomb joint friction: a velocity motor aiming at zero speed with the friction as its force
        # (the explicit PD's; the implicit PD folds the friction into its own motor command).
        bc.setJointMotorControlArray(self.robot, self.joint_ids, pybullet.VELOCITY_CONTROL,
                                     targetVelocities=[0.0] * 12, forces=[friction] * 12)
        bc.changeDynamics(self.ground, -1, lateralFriction=params.ground_friction,
                          restitution=params.ground_restitution)
        for f in self.foot_ids:
            bc.changeDynamics(self.robot, f, lateralFriction=1.0, restitution=params.ground_restitution)
        self.kp = np.asarray(s.kp) * params.kp_scale
        self.kd = np.asarray(s.kd) * params.kd_scale
        self.torque_limit = np.asarray(s.torque_limit) * np.asarray(params.motor_strength)

    # -- motion ------------------------------------------------------------------------------
    def reset(self, q: np.ndarray | None = None, base_pos: np.ndarray | None = None,
              base_quat: np.ndarray | None = None, dq: np.ndarray | None = None,
              base_lin_vel: np.ndarray | None = None, base_ang_vel: np.ndarray | None = None) -> None:
        """Teleport the agent to a state (defaults: default pose, spawn height, at rest)."""
        s = self.spec
        q = s.default_pose if q is None else np.asarray(q, dtype=np.float64)
        dq = np.zeros(12) if dq is None else np.asarray(dq, dtype=np.float64)
        base_pos = [0.0, 0.0, s.spawn_height] if base_pos is None else base_pos
        base_quat = [0.0, 0.0, 0.0, 1.0] if base_quat is None else base_quat
        self._clear_contacts()
        self._teleport(self.robot, base_pos, base_quat, q, dq)
        self.bc.resetBaseVelocity(self.robot,
                                  [0.0, 0.0, 0.0] if base_lin_vel is None else list(base_lin_vel),
                                  [0.0, 0.0, 0.0] if base_ang_vel is None else list(base_ang_vel))
        self.tau = np.zeros(12)
        self.time = 0.0

    def _clear_contacts(self) -> None:
        """Drop the contact cache (solver warm start) so a reset does not depend on the last episode.

        A teleport keeps PyBullet's persistent contact manifolds; one physics step with the robot
        parked far from the ground removes them (then the caller teleports it back).
        """
        self.bc.resetBasePositionAndOrientation(self.robot, _PARK, [0, 0, 0, 1])
        self.bc.resetBaseVelocity(self.robot, [0, 0, 0], [0, 0, 0])
        self.bc.stepSimulation()

    def _teleport(self, body: int, base_pos, base_quat, q, dq=None) -> None:
        bc = self.bc
        bc.resetBasePositionAndOrientation(body, list(map(float, base_pos)), list(map(float, base_quat)))
        for k, j in enumerate(self.joint_ids):
            bc.resetJointState(body, j, float(q[k]), 0.0 if dq is None else float(dq[k]))

    def set_pose(self, base_pos, base_quat, q, body: str = "agent") -> None:
        """Place the agent or the ghost kinematically (no physics), e.g. to play a motion."""
        self._teleport(self._body(body), base_pos, base_quat, q)

    def _body(self, which: str) -> int:
        if which == "agent":
            return self.robot
        if which == "ghost" and self.ghost is not None:
            return self.ghost
        raise ValueError(f"unknown body {which!r}; choose 'agent'" + (" or 'ghost'" if self.ghost else ""))

    def joint_states(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint positions (rad) and velocities (rad/s) of the agent."""
        js = pybullet.getJointStates(self.robot, self.joint_ids, physicsClientId=self.client)
        return np.array([j[0] for j in js]), np.array([j[1] for j in js])

    def step(self, q_target: np.ndarray, tau_ff: np.ndarray | float = 0.0, kp: np.ndarray | None = None,
             kd: np.ndarray | None = None) -> None:
        """Hold PD targets (rad) for one control period (``spec.substeps`` physics steps).

        ``kp``/``kd`` (N·m/rad, N·m·s/rad) override the spec's gains (a HAL command's gains);
        ``None`` keeps the spec's, scaled by the domain randomisation.
        """
        # pybullet's functions called directly, not through BulletClient: its per-call wrapping
        # costs about as much as the PD law in this loop.
        c, robot, joints = self.client, self.robot, self.joint_ids
        kp = self.kp if kp is None else np.asarray(kp, dtype=np.float64)
        kd = self.kd if kd is None else np.asarray(kd, dtype=np.float64)
        tau_ff = np.asarray(tau_ff, dtype=np.float64)
        for _ in range(self.spec.substeps):
            q, dq = self.joint_states()
            if self.pd == "implicit":
                velocity, force, self.tau = pd_motor(q_target, q, dq, kp, kd, self.torque_limit, self.friction,
                                                     tau_ff)
                pybullet.setJointMotorControlArray(robot, joints, pybullet.VELOCITY_CONTROL,
                                                   targetVelocities=velocity.tolist(), forces=force.tolist(),
                                                   physicsClientId=c)
            else:
                self.tau = pd_torque(q_target, q, dq, kp, kd, self.torque_limit, tau_ff)
                pybullet.setJointMotorControlArray(robot, joints, pybullet.TORQUE_CONTROL,
                                                   forces=self.tau.tolist(), physicsClientId=c)
            pybullet.stepSimulation(physicsClientId=c)
        self.time += self.spec.control_dt

    def push(self, delta_lin_vel: np.ndarray) -> None:
        """Add a velocity kick (m/s, world) to the base: a random push."""
        v, w = self.bc.getBaseVelocity(self.robot)
        self.bc.resetBaseVelocity(self.robot, list(np.add(v, delta_lin_vel)), list(w))

    # -- sensing -----------------------------------------------------------------------------
    def state(self) -> SimState:
        """Read the agent's full state."""
        bc = self.bc
        pos, quat = bc.getBasePositionAndOrientation(self.robot)
        lin, ang = bc.getBaseVelocity(self.robot)
        rot = np.array(bc.getMatrixFromQuaternion(quat)).reshape(3, 3)  # body -> world
        q, dq = self.joint_states()
        contacts = bc.getContactPoints(bodyA=self.robot, bodyB=self.ground)
        touching = {c[3] for c in contacts}
        lin, ang = np.array(lin), np.array(ang)
        return SimState(
            time=self.time, base_pos=np.array(pos), base_quat=np.array(quat),
            base_lin_vel=lin, base_ang_vel=ang,
            base_lin_vel_body=rot.T @ lin, base_ang_vel_body=rot.T @ ang,
            rpy=np.array(bc.getEulerFromQuaternion(quat)),
            q=q, dq=dq, tau=self.tau.copy(),
            foot_contact=np.array([f in touching for f in self.foot_ids]),
            fall_contact=bool(touching & self.fall_ids),
        )

    def foot_positions(self, body: str = "agent") -> np.ndarray:
        """World positions (m) of the foot link frames, (4, 3)."""
        b = self._body(body)
        return np.array([self.bc.getLinkState(b, f, computeForwardKinematics=True)[4] for f in self.foot_ids])

    def self_collisions(self, margin: float = 0.0) -> list[tuple[int, int]]:
        """Pairs of non-adjacent agent links closer than ``margin`` (m)."""
        parents = {j: self.bc.getJointInfo(self.robot, j)[16] for j in self.link_ids if j >= 0}
        pairs = []
        for a in self.link_ids:
            for b in self.link_ids:
                if b <= a or parents.get(b) == a or parents.get(a) == b:
                    continue
                if self.bc.getClosestPoints(self.robot, self.robot, margin, a, b):
                    pairs.append((a, b))
        return pairs

    def render(self, size: int = camera.FRAME_SIZE, rgb: bool = False, body: str = "agent",
               cam: camera.CameraParams | None = None) -> np.ndarray:
        """Render the agent or the ghost (the other body is parked out of view)."""
        cam = cam or camera.CameraParams.from_spec(self.spec)
        target = self._body(body)
        other = self.ghost if target == self.robot else self.robot
        parked = None
        if other is not None and other == self.ghost:
            parked = self.bc.getBasePositionAndOrientation(other)
            self.bc.resetBasePositionAndOrientation(other, _PARK, [0, 0, 0, 1])
        elif other is not None:  # rendering the ghost: park the agent, keeping its velocities
            parked = (*self.bc.getBasePositionAndOrientation(other), *self.bc.getBaseVelocity(other))
            self.bc.resetBasePositionAndOrientation(other, _PARK, [0, 0, 0, 1])
        try:
            pos = self.bc.getBasePositionAndOrientation(target)[0]
            return camera.render(self.client, np.array(pos), cam, size, rgb, ground=self._drawn_ground)
        finally:
            if parked is not None:
                self.bc.resetBasePositionAndOrientation(other, parked[0], parked[1])
                if len(parked) == 4:
                    self.bc.resetBaseVelocity(other, parked[2], parked[3])

    def close(self) -> None:
        """Disconnect the physics client."""
        if self.client >= 0:
            try:
                self.bc.disconnect()
            except pybullet.error:
                pass
            self.client = -1

    def __enter__(self) -> "World":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
