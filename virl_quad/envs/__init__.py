"""Environments: ``make(robot, **overrides) -> gymnasium.Env`` and the rsl-rl vectorised env.

>>> env = make("pupper", randomize=False)
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym

from virl_quad import robots
from virl_quad.envs.quadruped import EnvConfig, QuadrupedEnv, policy_contract

#: Registered environment builders by name (one today; more tasks plug in here).
ENVS = {"quadruped": QuadrupedEnv}


def make(robot: str, *, env: str = "quadruped", render_mode: str | None = None, **overrides) -> gym.Env:
    """Build an environment for ``robot``; ``overrides`` are :class:`EnvConfig` fields.

    Raises ValueError with the valid choices for an unknown robot, env or option.
    """
    spec = robots.get(robot)
    if env not in ENVS:
        raise ValueError(f"unknown env {env!r}; choose one of: {', '.join(ENVS)}")
    names = [f.name for f in dataclasses.fields(EnvConfig)]
    unknown = [k for k in overrides if k not in names]
    if unknown:
        raise ValueError(f"unknown env option(s) {', '.join(unknown)}; valid options: {', '.join(names)}")
    return ENVS[env](spec, EnvConfig(**overrides), render_mode=render_mode)


__all__ = ["make", "EnvConfig", "QuadrupedEnv", "ENVS", "policy_contract"]
