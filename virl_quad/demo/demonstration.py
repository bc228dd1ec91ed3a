"""What the environment consumes: a demonstration video at the control rate, maybe with its motion.

A :class:`Demonstration` is a stack of 48x48 grayscale frames, one per
control step, plus, when it was rendered from a known reference motion, that
motion (for reference state initialisation and the ground-truth score).
Anything with ``duration`` (s), ``loop`` (bool) and ``state_at(t) -> MotionState``
serves as the motion (:class:`virl_quad.motion.state.MotionLike`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from virl_quad.motion.state import MotionLike


@dataclass
class Demonstration:
    """A demonstration video (frames at the control rate) and, when known, its reference motion."""

    frames: np.ndarray                  # (T, 48, 48) uint8
    fps: float                          # Hz, equals the env's control rate
    robot: str = ""
    source: str = ""
    camera: dict = field(default_factory=dict)
    motion: MotionLike | None = None
    loop: bool = True
    displacement: np.ndarray | None = None  # (T, 2) m, subject's forward/vertical displacement, if known

    def __post_init__(self) -> None:
        f = self.frames
        if not isinstance(f, np.ndarray) or f.dtype != np.uint8 or f.ndim != 3 or f.shape[1:] != (48, 48):
            shape = getattr(f, "shape", None)
            dtype = getattr(f, "dtype", None)
            raise ValueError(f"demonstration frames must be uint8 (T, 48, 48), got {dtype} {shape}")
        if len(f) == 0:
            raise ValueError("demonstration has no frames")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"demonstration fps must be positive, got {self.fps}")

    @property
    def num_frames(self) -> int:
        """Number of frames."""
        return len(self.frames)

    @property
    def duration(self) -> float:
        """Length in s."""
        return self.num_frames / self.fps

    def index(self, step: int) -> int:
        """Frame index of demonstration step ``step`` (wraps when looping, else clamps)."""
        return step % self.num_frames if self.loop else min(max(step, 0), self.num_frames - 1)
