"""A warm start that already walks: the actor imitates a tracker of the gait prior before PPO.

The trajectory generator (TG) played open-loop does not carry a Pupper forward: its PD gains
(4 N·m/rad) are too weak to follow the joint trajectory. A tracker that feeds back the
measured joint error on top of the TG's next pose,

    target = q_tg(phase + lead) + gain * (q_tg(phase) - q)          (rad)

(``gain``, ``lead`` and the gathering noise: the robot's ``tracker_*``; Laikago's stiff PD
needs no feedback) follows it
(``virl_quad.evaluation.tracker``). It needs nothing but the TG and the robot's own joint
angles, which the policy observes (the TG phase too), so it is a function of the observation
and a proprioceptive policy can represent it: ``virl_quad.training.dagger`` copies it into
the actor (the training architecture and observation) in a few minutes. PPO then starts from
a policy that walks, with a critic fitted to it first (:meth:`VirlPPO.freeze_actor`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from virl_quad.policy.tg import TGParams, TrajectoryGenerator
from virl_quad.robots.spec import RobotSpec


@dataclass
class _Pose:
    q: np.ndarray          # rad (12)


class TGMotion:
    """The TG's own joint trajectory as a looping motion (``state_at(t).q``, t in s of the
    demonstration clock, at the TG's nominal frequency): what the warm-start teacher tracks."""

    loop = True

    def __init__(self, spec: RobotSpec, params: TGParams) -> None:
        self.tg = TrajectoryGenerator(spec, params)
        self.frequency = float(params.frequency)   # Hz
        self.duration = 1.0 / self.frequency       # s, one cycle

    def state_at(self, t: float) -> _Pose:
        """The TG's joint targets (rad) at time ``t`` (s)."""
        return _Pose(self.tg.joint_targets((t * self.frequency) % 1.0))


def distill_into(actor: torch.nn.Module, spec: RobotSpec, demo, tg: TGParams, hidden: str, seed: int,
                 rounds: int, steps: int, randomize: bool, log: Callable[[str], None] = print) -> dict:
    """DAgger-distil the tracker of ``tg`` into ``actor`` (an rsl-rl MLPModel of the run's
    architecture, weights and observation normaliser replaced), gathering under the robot's
    domain randomisation when ``randomize`` (the teacher feeds back the observed joint angles,
    so its action stays a function of the observation); returns the student's last round
    statistics (episodes, falls, mean travel in m)."""
    from virl_quad.distill import DistillArgs
    from virl_quad.training.dagger import distil

    args = DistillArgs(robot=spec.name, rounds=rounds, steps=steps, hidden=hidden, seed=seed, quiet=True,
                       randomize=randomize, gain=spec.tracker_gain, lead=spec.tracker_lead,
                       noise=spec.tracker_noise)
    student, info = distil(args, log=lambda line: log(f"warm start: {line}"), demo=demo,
                           env_options={"tg": tg}, motion=TGMotion(spec, tg))
    std = actor.distribution.std_param.detach().clone()   # the run's exploration noise (scalar std type)
    actor.load_state_dict(student.state_dict())
    with torch.no_grad():
        actor.distribution.std_param.copy_(std)
    return info["student"]
