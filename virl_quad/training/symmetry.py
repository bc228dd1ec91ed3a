"""Left-right mirror of observations and actions, for rsl-rl's symmetry augmentation.

Mirroring the world in the robot's sagittal plane (y -> -y) maps a state to another valid
state: the left and right legs swap (FR <-> FL, RR <-> RL), abduction angles change sign
(their axes lie along x), hip and knee angles do not (their axes lie along y). Vectors in
the body frame change the sign of y, angular velocities (axial vectors) the signs of x and
z, the heading its sign. With a gait clock, the mirrored legs run at other phases: the
mirrored state is the gait at the clock phase shifted by ``offset_FL - offset_FR`` (half a
cycle for a trot or a pace, none for a bound), which must be the same for both leg pairs.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDict

from virl_quad.policy.observation import policy_layout

#: canonical joint order FR, FL, RR, RL x (abduction, hip, knee): the mirrored joint of each
JOINT_SWAP = [3, 4, 5, 0, 1, 2, 9, 10, 11, 6, 7, 8]
JOINT_SIGN = torch.tensor([-1.0, 1.0, 1.0] * 4)
FOOT_SWAP = [1, 0, 3, 2]


def phase_shift(offsets) -> float:
    """Cycles to add to the clock phase of a mirrored state (ValueError: the gait has no mirror)."""
    fr, fl, rr, rl = (float(o) for o in offsets)
    shifts = [(fl - fr) % 1.0, (fr - fl) % 1.0, (rl - rr) % 1.0, (rr - rl) % 1.0]
    if max(abs(math.remainder(s - shifts[0], 1.0)) for s in shifts) > 1e-6:
        raise ValueError(f"the gait with leg offsets {list(offsets)} is not left-right symmetric")
    return shifts[0]


def _joints(x: torch.Tensor) -> torch.Tensor:
    return x[..., JOINT_SWAP] * JOINT_SIGN.to(x.device)


def _rotate(sin_cos: torch.Tensor, cycles: float) -> torch.Tensor:
    a = 2.0 * math.pi * cycles
    s, c = sin_cos[..., 0], sin_cos[..., 1]
    return torch.stack([s * math.cos(a) + c * math.sin(a), c * math.cos(a) - s * math.sin(a)], dim=-1)


def mirror_policy(obs: torch.Tensor, with_phase: bool, action_size: int, shift: float) -> torch.Tensor:
    """The mirror of a batch of policy observations (see :mod:`virl_quad.policy.observation`)."""
    out, start = obs.clone(), 0
    for name, size, _ in policy_layout(with_phase, action_size):
        block = obs[..., start:start + size]
        if name == "projected_gravity":
            block = block * torch.tensor([1.0, -1.0, 1.0])
        elif name == "heading_sin_cos":
            block = block * torch.tensor([-1.0, 1.0])
        elif name == "base_ang_vel_body":
            block = block * torch.tensor([-1.0, 1.0, -1.0])
        elif name in ("joint_pos_minus_default", "joint_vel"):
            block = _joints(block)
        elif name == "last_action":
            block = mirror_action(block)
        elif name == "phase_sin_cos":
            block = _rotate(block, shift)
        out[..., start:start + size] = block
        start += size
    return out


def mirror_action(a: torch.Tensor) -> torch.Tensor:
    """The mirror of a batch of actions: 12 joint entries, then TG modulation entries unchanged."""
    return torch.cat([_joints(a[..., :12]), a[..., 12:]], dim=-1)


def mirror_privileged(x: torch.Tensor) -> torch.Tensor:
    """The mirror of the critic's privileged block (see :mod:`virl_quad.envs.quadruped`):
    base velocity (body frame), height, foot contacts, then the physical parameters, whose
    last 12 entries (motor strength) are per joint."""
    out = x.clone()
    out[..., 1] = -x[..., 1]
    out[..., 4:8] = x[..., 4:8][..., FOOT_SWAP]
    out[..., -12:] = x[..., -12:][..., JOINT_SWAP]
    return out


def augment(env, obs: TensorDict | None = None, actions: torch.Tensor | None = None):
    """rsl-rl's ``data_augmentation_func``: the batch followed by its mirror."""
    c = env.contract
    if c.with_phase and c.tg is None:
        raise ValueError("symmetry needs the trajectory generator's leg offsets to mirror the clock phase")
    shift = phase_shift(c.tg.offsets) if c.tg is not None else 0.0
    obs_aug = act_aug = None
    if obs is not None:
        mirrored = obs.clone()
        mirrored["policy"] = mirror_policy(obs["policy"], c.with_phase, c.action_size, shift)
        if "privileged" in obs.keys():
            mirrored["privileged"] = mirror_privileged(obs["privileged"])
        obs_aug = torch.cat([obs, mirrored], dim=0)
    if actions is not None:
        act_aug = torch.cat([actions, mirror_action(actions)], dim=0)
    return obs_aug, act_aug
