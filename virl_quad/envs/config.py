"""Options of :class:`~virl_quad.envs.quadruped.QuadrupedEnv`, by concern, and their checks.

:func:`checked` validates a configuration as the env would, without a simulator (the VecEnv
checks its options in the parent process before it starts any worker).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from virl_quad import robots
from virl_quad.cli import Sectioned
from virl_quad.demo.demonstration import Demonstration
from virl_quad.envs.randomize import DRConfig
from virl_quad.policy.action import ActionMap
from virl_quad.policy.contract import PolicyContract
from virl_quad.policy.tg import TGParams
from virl_quad.robots.spec import MAX_TARGET_STEP, RAMP_TIME, RobotSpec
from virl_quad.sim.params import DEFAULT_GROUND
from virl_quad.sim.pd import PD_MODES


@dataclass
class EpisodeConfig:
    """How an episode starts and ends."""

    episode_seconds: float | None = None   # s, time limit; None = the robot's default
    time_limit: bool = True                # truncate at episode_seconds (the VecEnv does it itself)
    terminate_on_fall: bool = True         # end the episode when the robot falls
    rsi: bool = True                       # reference state initialisation when the demo has a motion
    stand_start: bool = False              # start as a HAL hands a robot over: standing, the default
                                           # pose held for stand_seconds, clock at phase 0 (not RSI)
    stand_seconds: float = RAMP_TIME       # s, the hold before a standing start (the deploy safety
                                           # layer's ramp time)


@dataclass
class ActionConfig:
    """What an action means (the policy contract's action facts)."""

    action_scale: float | None = None      # rad per unit action; None = the robot's default
    action_clip: float = 2.0               # |a| is clipped to this before scaling
    max_target_step: float | None = MAX_TARGET_STEP  # rad per control period a PD target may move
                                           # (the deploy safety layer's limit); None: unlimited
    tg: TGParams | None = None             # trajectory generator the policy acts as a residual on (action
                                           # size 14); None: actions are offsets from the default pose (12)


@dataclass
class PhysicsConfig:
    """How the physics is stepped and randomised."""

    sim_dt: float | None = None            # s, physics step; None = the robot's default
    substeps: int | None = None            # physics steps per control step; None = the robot's default
    pd: str = "implicit"                   # how the joint PD is stepped: "implicit" (PyBullet's joint motors)
                                           # or "explicit" (torques; needs a 1 ms physics step on Pupper),
                                           # see virl_quad.sim.pd
    randomize: bool = True                 # domain randomisation on/off
    randomization: dict | None = None      # per-parameter range overrides, see DRConfig


@dataclass
class CameraConfig:
    """What the follow camera renders."""

    render: bool = True                    # produce agent_image (off: a blank frame, faster)
    ground: str | None = None              # what the camera sees of the ground, "checker" or "plain";
                                           # None: the demonstration's, else DEFAULT_GROUND
    draw_as: str | None = None             # draw the agent on this robot's body (the one a demonstration
                                           # video shows: virl_quad.sim.shadow); None: its own


@dataclass
class EnvConfig(Sectioned):
    """Options of :class:`QuadrupedEnv`, by concern; ``virl_quad.envs.make`` and
    :meth:`make` take them by their flat names (``action_scale=0.3``)."""

    demo: Demonstration | None = None      # demonstration: expert_image, phase, RSI
    oracle_reward: bool = False            # reward = ground-truth pose-imitation score (needs demo.motion)
    oracle_speed_weight: float = 0.0       # share of the oracle reward given to the forward-speed term
                                           # (ORACLE_SPEED_SIGMA); 0: the score alone
    episode: EpisodeConfig
    action: ActionConfig
    physics: PhysicsConfig
    camera: CameraConfig


def with_timing(spec: RobotSpec, cfg: EnvConfig) -> RobotSpec:
    """The spec with the config's physics step / substeps, validated."""
    dt = spec.sim_dt if cfg.physics.sim_dt is None else float(cfg.physics.sim_dt)
    n = spec.substeps if cfg.physics.substeps is None else int(cfg.physics.substeps)
    if not (0 < dt <= 0.01) or n < 1:
        raise ValueError(f"sim_dt must be in (0, 0.01] s and substeps >= 1, got {dt} s and {n}")
    return dataclasses.replace(spec, sim_dt=dt, substeps=n) if (dt, n) != (spec.sim_dt, spec.substeps) else spec


def ground_of(cfg: EnvConfig) -> str:
    """The ground to draw: the config's, else the demonstration's, else the default; ValueError
    when the config and the demonstration disagree (the frames would differ in more than motion)."""
    demo_ground = (cfg.demo.camera or {}).get("ground") if cfg.demo is not None else None
    if cfg.camera.ground is not None and demo_ground is not None and demo_ground != cfg.camera.ground:
        raise ValueError(f"the demonstration was rendered on the {demo_ground!r} ground, the env would draw "
                         f"{cfg.camera.ground!r}: agent and expert frames would differ in more than the motion")
    return cfg.camera.ground or demo_ground or DEFAULT_GROUND


def drawn_body(spec: RobotSpec, cfg: EnvConfig) -> RobotSpec | None:
    """The body the agent is drawn on when it is not its own (``draw_as``); ValueError for an
    unknown robot or one without closed-form leg kinematics."""
    name = cfg.camera.draw_as
    if name is None or name == spec.name or not cfg.camera.render:
        return None
    body = robots.get(name)
    if body.leg is None or spec.leg is None:
        raise ValueError(f"draw_as={name!r}: drawing {spec.name} on another body needs both robots' leg geometry")
    return body


def policy_contract(spec: RobotSpec, cfg: EnvConfig, demo_frames: int | None) -> PolicyContract:
    """The policy contract of an env for ``spec`` with ``cfg`` whose demonstration has ``demo_frames``
    frames (None: no demonstration): action scale, clip and rate limit, the TG, and the phase clock
    (the TG's, else one cycle per demonstration loop, else none)."""
    a = cfg.action
    if a.tg is not None and not isinstance(a.tg, TGParams):
        raise ValueError(f"tg must be TGParams or None, got {type(a.tg).__name__}")
    scale = a.action_scale if a.action_scale is not None else spec.action_scale
    phase_hz = 1.0 / (demo_frames * spec.control_dt) if a.tg is None and demo_frames else None
    return PolicyContract(float(scale), float(a.action_clip), a.max_target_step, spec.control_dt, a.tg, phase_hz)


def checked(spec: RobotSpec, cfg: EnvConfig) -> tuple[RobotSpec, ActionMap]:
    """The robot (with the config's physics step) and action map (with its policy contract) of
    an env of ``cfg``, every option checked as :class:`QuadrupedEnv` would, without a simulator: ValueError (one
    line) for a bad physics step or PD mode, a ground the demonstration was not rendered on, a
    demonstration at another frame rate, bad randomisation ranges, a TG out of the robot's reach,
    or an oracle reward without a reference motion."""
    spec = with_timing(spec, cfg)
    if cfg.physics.pd not in PD_MODES:
        raise ValueError(f"unknown PD mode {cfg.physics.pd!r}; choose one of: {', '.join(PD_MODES)}")
    ground_of(cfg)
    drawn_body(spec, cfg)
    DRConfig.from_overrides(cfg.physics.randomization, DRConfig.for_robot(spec))
    demo = cfg.demo
    if demo is not None and abs(demo.fps - spec.control_hz) > 1e-3 * spec.control_hz:
        raise ValueError(f"demonstration is at {demo.fps:.3f} fps but {spec.name} is controlled at "
                         f"{spec.control_hz:.3f} Hz; re-render or import it for this robot")
    if cfg.oracle_reward and (demo is None or demo.motion is None):
        raise ValueError("oracle_reward needs a demonstration with a reference motion")
    if cfg.episode.stand_seconds < 0.0:
        raise ValueError(f"stand_seconds must be >= 0, got {cfg.episode.stand_seconds}")
    if not 0.0 <= cfg.oracle_speed_weight <= 1.0:
        raise ValueError(f"oracle_speed_weight must lie in [0, 1], got {cfg.oracle_speed_weight}")
    contract = policy_contract(spec, cfg, demo.num_frames if demo is not None else None)
    return spec, ActionMap(spec, contract)                      # ValueError: a TG out of reach or limits
