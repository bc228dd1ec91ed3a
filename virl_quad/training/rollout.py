"""One rollout of PPO: ``alg.act`` -> ``env.step`` -> ``alg.process_env_step``, ``steps`` times.

The vector env's envs step in groups (:attr:`QuadrupedVecEnv.groups`, two with worker
processes) and the rollout is *pipelined*: the policy acts on one group's observations
while the workers step the other group, so the workers do not wait for the policy, the
NaN check or the storage. The transitions are the same as a one-group rollout's: every
group takes step k with the same policy before step k is stored, the groups' halves of each
transition joined in env order.
"""

from __future__ import annotations

import copy
from typing import Callable

import torch
from rsl_rl.utils import check_nan
from tensordict import TensorDict


def rollout(alg, env, obs: TensorDict, steps: int, on_step: Callable[[torch.Tensor], None],
            check_nans: bool = True) -> TensorDict:
    """Collect ``steps`` transitions of every env of ``env`` (a :class:`QuadrupedVecEnv`) into
    ``alg``'s storage, starting from ``obs``; ``on_step(dones)`` after each is stored. Returns
    the observations after the last step. One group steps as the plain loop would."""
    if getattr(alg.actor, "is_recurrent", False) or getattr(alg.critic, "is_recurrent", False):
        raise ValueError("the rollout acts before it stores the last step: a recurrent policy's "
                         "hidden states would be reset too late")
    groups = env.groups
    with torch.inference_mode():
        pending = []
        for g, (lo, hi) in enumerate(groups):
            actions, transition = _act(alg, obs[lo:hi])
            env.step_async(actions.to(env.device), g)
            pending.append(transition)
        for k in range(steps):
            taken, pending, results = pending, [], []
            for g in range(len(groups)):
                o, r, d, ex = env.step_wait(g)
                if check_nans:
                    check_nan(o, r, d)          # rsl-rl's check: ValueError naming the group
                o = o.to(alg.device)
                results.append((o, r.to(alg.device), d.to(alg.device), ex))
                if k + 1 < steps:              # the next step of this group, while the others step
                    actions, transition = _act(alg, o)
                    env.step_async(actions.to(env.device), g)
                    pending.append(transition)
            obs = torch.cat([x[0] for x in results])
            rewards, dones = torch.cat([x[1] for x in results]), torch.cat([x[2] for x in results])
            extras = {key: torch.cat([x[3][key] for x in results]) for key in results[0][3] if key != "log"}
            alg.transition = _joined(taken)
            alg.process_env_step(obs, rewards, dones, {**extras, "log": {}})
            on_step(dones)
    return obs


def _act(alg, obs: TensorDict):
    """``alg.act`` on a group's observations; the transition it filled, detached from ``alg``."""
    actions = alg.act(obs)
    transition = copy.copy(alg.transition)
    alg.transition.clear()
    return actions, transition


def _joined(parts: list):
    """One transition of every env from the groups' (env order)."""
    if len(parts) == 1:
        return parts[0]
    out = copy.copy(parts[0])
    for name, first in vars(parts[0]).items():
        if isinstance(first, (torch.Tensor, TensorDict)):
            setattr(out, name, torch.cat([getattr(p, name) for p in parts]))
        elif isinstance(first, tuple) and first and all(isinstance(x, torch.Tensor) for x in first):
            setattr(out, name, tuple(torch.cat([getattr(p, name)[i] for p in parts]) for i in range(len(first))))
    return out
