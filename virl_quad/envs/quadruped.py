"""Gymnasium environment: one quadruped in PyBullet, proprioceptive policy state and camera frames.

Observation (``gymnasium.spaces.Dict``):
- ``policy``      float32, see :mod:`virl_quad.policy.observation` (what the robot can measure),
- ``privileged``  float32: body-frame base velocity x2.0, base height (m), foot contacts,
                  the randomised physical parameters (critic only),
- ``agent_image`` uint8 (48, 48): the follow camera's view of the agent (with ``draw_as``: its
                  pose drawn on that robot's body, :mod:`virl_quad.sim.shadow`),
- ``expert_image`` uint8 (48, 48): with a demonstration, its frame at the env's demonstration clock.
Action (:class:`virl_quad.policy.ActionMap`, the policy server's too): without a trajectory
generator 12 joint position offsets from the default pose, ``target = default + action_scale * a``
(rad); with one (``tg``) 12 residuals on the TG's joint targets and 2 TG modulation entries
(frequency and amplitude scale), ``target = TG(phase) + action_scale * a[:12]``. Either way moved
at most ``max_target_step`` rad per step (the deploy safety layer's limit) and clipped to the
joint limits. The phase clock runs at the TG's frequency, else at the demonstration's cycle
(none without either). No task reward (0.0): the VIRL reward is computed by the trainer; with
``oracle_reward`` the env's reward is the ground-truth score, mixed by ``oracle_speed_weight`` with a
term for the reference's forward speed.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np

from virl_quad.envs.config import EnvConfig, checked, drawn_body, ground_of
from virl_quad.envs.randomize import DRConfig, Randomization, sample
from virl_quad.policy import observation as obs_lib
from virl_quad.robots.spec import RobotSpec
from virl_quad.sim.camera import FRAME_SIZE
from virl_quad.sim.params import PhysicsParams
from virl_quad.sim.shadow import Shadow
from virl_quad.sim.world import SimState, World

# Nominal measurement noise std (x the episode's obs_noise draw), as legged_gym.
NOISE_GRAVITY = 0.05   # unit vector components
NOISE_GYRO = 0.2       # rad/s
NOISE_Q = 0.01         # rad
NOISE_DQ = 1.5         # rad/s
PRIVILEGED_SIZE = 3 + 1 + 4 + PhysicsParams.vector_size()
ORACLE_SPEED_SIGMA = 0.2   # m/s, width of the oracle reward's forward-speed term


def forward_speed(quat: np.ndarray, lin_vel: np.ndarray) -> float:
    """Base velocity (m/s, world frame) along the base's heading (its yaw, the x axis on the ground)."""
    h = obs_lib.yaw(quat)
    return float(lin_vel[0] * np.cos(h) + lin_vel[1] * np.sin(h))


def speed_reward(v: float, v_ref: float) -> float:
    """The oracle's forward-speed term in [0, 1]: ``exp(-((v - v_ref) / ORACLE_SPEED_SIGMA)^2)``. The
    score's own speed term (weight 0.1, ``exp(-2 dv^2)``) pays a robot walking backwards at 0.04 m/s
    89 % of a robot matching a 0.2 m/s reference, so a reward of the score alone lets gaits drift."""
    return float(np.exp(-((v - v_ref) / ORACLE_SPEED_SIGMA) ** 2))


class QuadrupedEnv(gym.Env):
    """One robot, one episode at a time. Build it with ``virl_quad.envs.make``."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, spec: RobotSpec, cfg: EnvConfig, render_mode: str | None = None) -> None:
        spec, self.actions = checked(spec, cfg)
        self.contract = self.actions.contract
        self.robot, self.cfg = spec, cfg
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(round(spec.control_hz))}
        ground = ground_of(cfg)
        self.world = World(spec, ground=ground, pd=cfg.physics.pd)
        body = drawn_body(spec, cfg)
        self.shadow = Shadow(spec, body, ground) if body is not None else None
        ph = cfg.physics
        self.dr = DRConfig.from_overrides(ph.randomization,
                                          DRConfig.for_robot(spec) if ph.randomize else DRConfig.off())
        self.demo = cfg.demo
        self.action_scale = cfg.action.action_scale if cfg.action.action_scale is not None else spec.action_scale
        seconds = cfg.episode.episode_seconds if cfg.episode.episode_seconds is not None else spec.episode_seconds
        self.max_steps = int(round(seconds / spec.control_dt))
        n_policy = self.contract.observation_size
        image = gym.spaces.Box(0, 255, (FRAME_SIZE, FRAME_SIZE), np.uint8)
        spaces = {
            "policy": gym.spaces.Box(-np.inf, np.inf, (n_policy,), np.float32),
            "privileged": gym.spaces.Box(-np.inf, np.inf, (PRIVILEGED_SIZE,), np.float32),
            "agent_image": image,
        }
        if self.demo is not None:
            spaces["expert_image"] = image
        self.observation_space = gym.spaces.Dict(spaces)
        clip = self.contract.action_clip
        self.action_space = gym.spaces.Box(-clip, clip, (self.contract.action_size,), np.float32)
        self.rand: Randomization = sample(DRConfig.off(), np.random.default_rng(0), spec)
        self.start_yaw = 0.0                                      # rad, the base's yaw at reset
        self.steps = 0
        self.demo_step = 0
        self._history: deque = deque(maxlen=8)
        self._next_push = np.inf
        self._state: SimState | None = None
        self._kin = None
        #: the reference at every demonstration step an episode can reach (a Trajectory, one row
        #: per step), sampled in one batch at the first oracle reward: the reference at a step
        #: never changes, and sampling it step by step (slerp, finite differences, foot
        #: kinematics) cost more than the physics step
        self._ref_table = None
        if cfg.oracle_reward:
            from virl_quad.kinematics import Kinematics

            self._kin = Kinematics(spec)

    # -- episode ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode: draw the randomisation, place the robot (RSI with a demo; standing
        with ``stand_start``)."""
        super().reset(seed=seed)
        rng = self.np_random
        self.rand = sample(self.dr, rng, self.robot)
        self.world.apply_params(self.rand.physics)
        self.demo_step = 0
        if self.cfg.episode.stand_start:
            self._stand()
        else:
            if self.demo is not None:
                self.demo_step = int(rng.integers(self.demo.num_frames))
                if options and "demo_step" in options:
                    self.demo_step = int(options["demo_step"])
            self._place_robot()
        self.steps = 0
        self._history.clear()
        self._state = self.world.state()
        self.start_yaw = obs_lib.yaw(self._state.base_quat)          # rad, the observation's heading origin
        # the rate limit starts from the pose; the clock where it is at the demonstration's step
        # (the TG's phase at that time of the reference motion it was fitted to; 0 without one)
        hz = self.contract.clock_hz
        self.actions.reset(self._state.q, self.demo_step * self.robot.control_dt * hz if hz and self.demo else 0.0)
        self._remember(self._state)
        self._next_push = self.world.time + self.rand.push_interval if self.rand.push_velocity > 0 else np.inf
        return self._observation(), self._info()

    def _stand(self) -> None:
        """Start as a HAL hands the robot over: placed in the default pose, which the PD holds for
        ``stand_seconds`` (the safety layer's ramp) before the policy's first action."""
        self.world.reset()
        hold = np.asarray(self.robot.default_pose, dtype=np.float64)
        for _ in range(int(round(self.cfg.episode.stand_seconds / self.robot.control_dt))):
            self.world.step(hold)

    def _place_robot(self) -> None:
        motion = self.demo.motion if self.demo is not None else None
        if motion is None or not self.cfg.episode.rsi:
            self.world.reset()
            return
        ref = motion.state_at(self.demo_step / self.demo.fps)
        q = self.robot.clip_to_limits(ref.q)
        self.world.reset(q=q, base_pos=ref.root_pos, base_quat=ref.root_quat, dq=ref.dq,
                         base_lin_vel=ref.root_lin_vel, base_ang_vel=ref.root_ang_vel)

    def step(self, action: np.ndarray):
        """Apply one action (see module doc) for one control period."""
        target = self.actions.step(action)   # ValueError for a wrong size or NaN/inf
        self.world.step(target)
        self.steps += 1
        self.demo_step += 1
        if self.world.time >= self._next_push:
            self._push()
        self._state = s = self.world.state()
        self._remember(s)
        terminated = self.cfg.episode.terminate_on_fall and self._fallen(s)
        truncated = self.cfg.episode.time_limit and self.steps >= self.max_steps and not terminated
        reward = self._oracle_reward(s) if self._kin is not None else 0.0
        return self._observation(), reward, bool(terminated), bool(truncated), self._info()

    def _oracle_reward(self, s: SimState) -> float:
        """motion_imitation's pose-imitation reward against the reference at the demo clock, mixed
        with the forward-speed term by ``oracle_speed_weight``."""
        from virl_quad.evaluation.score import Trajectory, term_errors, term_rewards

        traj = Trajectory(root_pos=s.base_pos[None], root_quat=s.base_quat[None], q=s.q[None], dq=s.dq[None],
                          root_lin_vel=s.base_lin_vel[None], root_ang_vel=s.base_ang_vel[None],
                          feet=self.world.foot_positions()[None])
        ref = self._reference_row(self.demo_step)
        total = float(term_rewards(term_errors(traj, ref, self._kin))["total"][0])
        w = self.cfg.oracle_speed_weight
        if w == 0.0:
            return total
        v = forward_speed(s.base_quat, s.base_lin_vel)
        v_ref = forward_speed(ref.root_quat[0], ref.root_lin_vel[0])
        return (1.0 - w) * total + w * speed_reward(v, v_ref)

    def _reference_row(self, step: int):
        """The reference motion at demonstration step ``step`` as a one-row Trajectory."""
        from virl_quad.evaluation.score import Trajectory, reference_trajectory

        if self._ref_table is None:
            steps = np.arange(self.demo.num_frames + self.max_steps + 1)
            self._ref_table = reference_trajectory(self.demo.motion, steps / self.demo.fps, self._kin)
        if step >= len(self._ref_table):   # no time limit: past the table, sample the step alone
            return reference_trajectory(self.demo.motion, np.array([step / self.demo.fps]), self._kin)
        t = self._ref_table
        return Trajectory(root_pos=t.root_pos[step:step + 1], root_quat=t.root_quat[step:step + 1],
                          q=t.q[step:step + 1], dq=t.dq[step:step + 1], root_lin_vel=t.root_lin_vel[step:step + 1],
                          root_ang_vel=t.root_ang_vel[step:step + 1], feet=t.feet[step:step + 1])

    def _push(self) -> None:
        angle = self.np_random.uniform(0, 2 * np.pi)
        v = self.rand.push_velocity
        self.world.push(np.array([v * np.cos(angle), v * np.sin(angle), 0.0]))
        self._next_push += self.rand.push_interval

    def _fallen(self, s: SimState) -> bool:
        sp = self.robot
        return bool(s.fall_contact or abs(s.rpy[0]) > sp.max_roll or abs(s.rpy[1]) > sp.max_pitch
                    or s.base_pos[2] < sp.min_base_height)

    # -- observation -----------------------------------------------------------------------------
    def _remember(self, s: SimState) -> None:
        self._history.append((s.time, s.base_quat, s.base_ang_vel_body, s.q, s.dq))

    def _delayed(self) -> tuple[np.ndarray, ...]:
        """Measurements as the robot would see them ``latency`` s ago (linear interpolation)."""
        t = self._history[-1][0] - self.rand.latency
        newer = self._history[-1]
        for older in reversed(self._history):
            if older[0] <= t:
                break
            newer = older
        if older[0] >= t or newer is older:
            return older[1:]
        w = (t - older[0]) / (newer[0] - older[0])
        quat = (1 - w) * older[1] + w * newer[1]
        out = [quat / np.linalg.norm(quat)]
        out += [(1 - w) * a + w * b for a, b in zip(older[2:], newer[2:])]
        return tuple(out)

    def _observation(self) -> dict:
        quat, gyro, q, dq = self._delayed()
        n = self.rand.obs_noise
        if n > 0:
            rng = self.np_random
            gyro = gyro + rng.normal(0, NOISE_GYRO * n, 3)
            q = q + rng.normal(0, NOISE_Q * n, 12)
            dq = dq + rng.normal(0, NOISE_DQ * n, 12)
        policy = obs_lib.policy_observation(self.robot, quat, gyro, q, dq, self.actions.last_action,
                                            self.actions.phase, self.start_yaw)
        if n > 0:
            policy[:3] += self.np_random.normal(0, NOISE_GRAVITY * n, 3).astype(np.float32)
        s = self._state
        privileged = np.concatenate([
            s.base_lin_vel_body * obs_lib.LIN_VEL_SCALE, [s.base_pos[2]], s.foot_contact.astype(np.float64),
            self.rand.physics.as_vector(),
        ]).astype(np.float32)
        out = {"policy": policy, "privileged": privileged, "agent_image": self._agent_image()}
        if self.demo is not None:
            out["expert_image"] = self.demo.frames[self.demo.index(self.demo_step)]
        return out

    def _agent_image(self) -> np.ndarray:
        if not self.cfg.camera.render:
            return np.zeros((FRAME_SIZE, FRAME_SIZE), np.uint8)
        if self.shadow is not None:
            s = self._state
            return self.shadow.render(s.base_pos, s.base_quat, s.q, self.rand.camera)
        return self.world.render(cam=self.rand.camera)

    def _info(self) -> dict:
        s = self._state
        return {"base_pos": s.base_pos.copy(), "time": s.time, "demo_step": self.demo_step}

    @property
    def last_action(self) -> np.ndarray:
        """The last action, clipped (what the observation shows)."""
        return self.actions.last_action

    @property
    def last_target(self) -> np.ndarray:
        """rad (12): the PD targets of the last step (the pose at reset)."""
        return self.actions.last_target

    @property
    def state(self) -> SimState:
        """The latest simulator state (ground truth, for evaluation)."""
        return self._state

    def render(self):
        """RGB preview (256x256) of the agent, for videos."""
        return self.world.render(size=256, rgb=True, cam=self.rand.camera)

    def close(self) -> None:
        """Release the physics clients."""
        self.world.close()
        if self.shadow is not None:
            self.shadow.close()
