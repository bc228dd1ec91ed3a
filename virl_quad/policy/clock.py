"""The policy's phase clock: one class for the training env and the policy server.

The phase is a fraction of a cycle in [0, 1). Each control step advances it by
``frequency x control_dt x scale``, where ``scale`` is the trajectory generator's frequency
modulation from the policy's action (1 without a trajectory generator). Without a
trajectory generator a clock runs at a demonstration's cycle frequency (one cycle per
demonstration loop), so the phase is the demonstration's.
"""

from __future__ import annotations

import math


class PhaseClock:
    """Phase in [0, 1), advanced once per control step."""

    def __init__(self, frequency: float, dt: float, phase: float = 0.0) -> None:
        """``frequency``: Hz, cycles per second at scale 1; ``dt``: s, the control period."""
        if not (math.isfinite(frequency) and frequency > 0 and math.isfinite(dt) and dt > 0):
            raise ValueError(f"phase clock needs a positive frequency and period, got {frequency} Hz, {dt} s")
        self.frequency = float(frequency)   # Hz
        self.dt = float(dt)                 # s
        self.phase = 0.0                    # cycles, [0, 1)
        self.reset(phase)

    def reset(self, phase: float = 0.0) -> None:
        """Set the phase (any real number, wrapped into [0, 1))."""
        p = float(phase) % 1.0
        self.phase = 0.0 if p >= 1.0 else p   # (-1e-17) % 1.0 is 1.0 in floating point

    def advance(self, scale: float = 1.0) -> float:
        """Move on by one control period at ``scale`` x the frequency; returns the new phase."""
        p = (self.phase + self.frequency * self.dt * scale) % 1.0
        self.phase = 0.0 if p >= 1.0 else p
        return self.phase

    @property
    def step(self) -> float:
        """Cycles per control step at scale 1."""
        return self.frequency * self.dt
