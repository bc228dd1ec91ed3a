"""Per-tick record of a HAL run (``--record run.npz``), for tests and offline checks."""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from virl_quad.deploy.protocol import JointCommand, RobotState
from virl_quad.deploy.safety import Mode

#: Mode names; the record stores each tick's mode as an index into this tuple.
MODES: tuple[str, ...] = tuple(m.value for m in Mode)


class Recorder:
    """Per-tick log of what the HAL measured and applied (kept in memory, saved as .npz)."""

    def __init__(self, maxlen: int = 30_000) -> None:
        """Keep the last ``maxlen`` ticks (10 min at 50 Hz)."""
        self.rows: deque[tuple[Any, ...]] = deque(maxlen=maxlen)

    def add(self, state: RobotState | None, mode: Mode, cmd: JointCommand, tick: int) -> None:
        """Remember one tick: the state it started from and the command applied."""
        nan = np.full(3, np.nan)
        if state is None:
            q, quat, pos, t = np.full(12, np.nan), np.full(4, np.nan), nan, np.nan
        else:
            q, quat, t = state.q, state.quat, state.timestamp
            pos = state.base_pos if state.base_pos is not None else nan
        self.rows.append((tick, t, MODES.index(mode.value), cmd.q_target, cmd.kp, cmd.kd, cmd.tau_ff, q, quat, pos))

    def save(self, path: str, spec: Any) -> None:
        """Write the arrays (tick, t [s], mode [index into modes], q_target, kp, kd, tau_ff,
        q [rad], quat [xyzw], base_pos [m]) to ``path``."""
        cols = list(zip(*self.rows)) if self.rows else [[]] * 10
        names = ("tick", "t", "mode", "q_target", "kp", "kd", "tau_ff", "q", "quat", "base_pos")
        arrays = {n: np.asarray(c, dtype=np.float64 if n not in ("tick", "mode") else np.int64)
                  for n, c in zip(names, cols)}
        np.savez(path, **arrays, modes=np.array(MODES), robot=spec.name, control_dt=spec.control_dt)
