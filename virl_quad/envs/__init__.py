"""Environments: ``make(robot, **overrides) -> gymnasium.Env`` and the rsl-rl vectorised env.

>>> env = make("pupper", randomize=False)
"""

from __future__ import annotations

import gymnasium as gym

from virl_quad import robots
from virl_quad.cli import options
from virl_quad.envs.config import EnvConfig, policy_contract
from virl_quad.envs.quadruped import QuadrupedEnv
from virl_quad.robots.spec import RobotSpec

#: Registered environment builders by name (one today; more tasks plug in here).
ENVS = {"quadruped": QuadrupedEnv}


def make(robot: str | RobotSpec, *, env: str = "quadruped", render_mode: str | None = None, **overrides) -> gym.Env:
    """Build an environment for ``robot``; ``overrides`` are :class:`EnvConfig` fields.

    Raises ValueError with the valid choices for an unknown robot, env or option.
    """
    spec = robots.get(robot)
    if env not in ENVS:
        raise ValueError(f"unknown env {env!r}; choose one of: {', '.join(ENVS)}")
    return ENVS[env](spec, options_of(overrides), render_mode=render_mode)


def options_of(overrides: dict) -> EnvConfig:
    """The :class:`EnvConfig` of ``overrides`` (flat option names); ValueError naming the valid
    options for an unknown one."""
    names = list(options(EnvConfig()))
    unknown = [k for k in overrides if k not in names]
    if unknown:
        raise ValueError(f"unknown env option(s) {', '.join(unknown)}; valid options: {', '.join(names)}")
    return EnvConfig.make(**overrides)


__all__ = ["make", "options_of", "EnvConfig", "QuadrupedEnv", "ENVS", "policy_contract"]
