"""Action -> PD joint targets: the one implementation, called by the env's ``step`` and the
policy server's ``handle``.

Per control step, for an action ``a`` (12 entries, or 14 with a trajectory generator):

1. ``a`` is clipped to +-``action_clip`` (the clipped action is what the next observation
   shows as the last action);
2. the phase clock advances by one period, at the TG's frequency scale from ``a[12]``
   (:func:`virl_quad.policy.tg.modulation`; scale 1 without a TG);
3. ``target = base + action_scale * a[:12]`` (rad), where ``base`` is the TG's joint targets
   at the new phase with the amplitude scale from ``a[13]``, or the default pose without a TG;
4. the target moves at most ``max_target_step`` rad from the last target (the deploy safety
   layer's rate limit), then is clamped to the joint limits.

:meth:`ActionMap.reset` starts an episode: the last target is the measured pose, the last
action zero, the clock at the given phase.
"""

from __future__ import annotations

import math

import numpy as np

from virl_quad.policy.clock import PhaseClock
from virl_quad.policy.contract import PolicyContract
from virl_quad.policy.tg import TrajectoryGenerator, modulation
from virl_quad.robots.spec import RobotSpec


class ActionMap:
    """Policy actions to joint targets for one robot and one contract; keeps the episode's state."""

    def __init__(self, spec: RobotSpec, contract: PolicyContract) -> None:
        """ValueError when the contract's TG does not fit the robot."""
        self.spec, self.contract = spec, contract
        self.size = contract.action_size
        self.scale = float(contract.action_scale)            # rad per unit action
        self.bound = float(contract.action_clip)             # |a| bound
        self.max_step = contract.max_target_step             # rad per period, or None
        self.tg = TrajectoryGenerator(spec, contract.tg) if contract.tg is not None else None
        self.clock = PhaseClock(contract.clock_hz, contract.control_dt) if contract.with_phase else None
        self._default = np.array(spec.default_pose, dtype=np.float64)
        self.last_action = np.zeros(self.size)               # clipped, unscaled
        self.last_target = self._default.copy()              # rad
        self.frequency_scale = 1.0                           # TG modulation of the last step
        self.amplitude_scale = 1.0

    @property
    def phase(self) -> float | None:
        """The clock's phase in [0, 1) (None without a clock): the observation's phase."""
        return self.clock.phase if self.clock is not None else None

    def reset(self, q: np.ndarray, phase: float = 0.0) -> None:
        """Episode start: last target = the pose ``q`` (rad), last action 0, clock at ``phase``."""
        q = np.asarray(q, dtype=np.float64).reshape(-1)
        if q.shape != (12,) or not math.isfinite(q.sum()):
            raise ValueError(f"reset pose must be 12 finite angles, got shape {q.shape}")
        self.last_target = q.copy()
        self.last_action = np.zeros(self.size)
        self.frequency_scale = self.amplitude_scale = 1.0
        if self.clock is not None:
            self.clock.reset(phase)

    def clip(self, action: np.ndarray) -> np.ndarray:
        """The action (float64) clipped to +-action_clip; ValueError on a wrong size or NaN/inf."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (self.size,):
            raise ValueError(f"action must have {self.size} entries, got shape {np.shape(action)}")
        if not math.isfinite(a.sum()):
            raise ValueError("action contains NaN or inf")
        c = self.bound
        return np.minimum(np.maximum(a, -c), c)              # np.clip, 3x faster for 14 values

    def step(self, action: np.ndarray) -> np.ndarray:
        """The PD targets (rad, 12) for ``action``; advances the clock and remembers action and target."""
        a = self.clip(action)
        if self.tg is not None:
            self.frequency_scale, self.amplitude_scale = modulation(a[12:])
            base = self.tg.joint_targets(self.clock.advance(self.frequency_scale), self.amplitude_scale)
        else:
            if self.clock is not None:
                self.clock.advance()
            base = self._default
        target = base + self.scale * a[:12]
        if self.max_step is not None:                        # rate limit, then the joint limits
            last = self.last_target
            target = np.minimum(np.maximum(target, last - self.max_step), last + self.max_step)
        target = self.spec.clip_to_limits(target)
        self.last_action, self.last_target = a, target
        return target

    def base_target(self) -> np.ndarray:
        """The target (rad, 12) that a zero residual would aim at in the next step (TG at the next
        phase without modulation, or the default pose), before rate and joint limits; the
        state is not changed. ``(target - base_target()) / action_scale`` is the residual of a target."""
        if self.tg is None:
            return self._default.copy()
        return self.tg.joint_targets((self.clock.phase + self.clock.step) % 1.0)
