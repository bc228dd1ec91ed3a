"""Reference motion: keyframes of root pose and joint angles, played back at any time.

A :class:`Motion` stores ``N`` evenly spaced keyframes (``frame_duration`` s apart):
root position (m, world), root orientation (xyzw quaternion of the robot's own z-up
base frame, world) and the 12 joint angles (rad, canonical order FR, FL, RR, RL x
(abduction, hip, knee), URDF convention). Between keyframes the root position and
joint angles are interpolated linearly and the root orientation by slerp
(``scipy.spatial.transform.Slerp``).

Looping ("Wrap") follows DeepMimic / motion_imitation: a clip of ``N`` frames lasts
``(N - 1) * frame_duration`` s, its last frame being the first frame of the next
cycle. With ``cycle_offset_position`` each new cycle starts where the previous one
ended in the ground plane (x, y shifted by the clip's net displacement, z not);
with ``cycle_offset_rotation`` it is also turned by the clip's net heading change
about the vertical axis. A clamped ("Clamp") clip holds its first / last frame
outside ``[0, duration]``.

Velocities of :meth:`Motion.state_at` are central finite differences over half a
keyframe interval each side (one-sided at the ends of a clamped clip).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from virl_quad.motion.state import MotionState

#: Accepted playback speed factors for time warping (VIRL's augmentation range).
WARP_RANGE = (0.5, 2.0)


def heading(quat_xyzw: np.ndarray) -> np.ndarray:
    """Heading (rad): yaw of the base x axis projected on the ground plane; quat (..., 4) xyzw."""
    x_axis = Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64)).apply([1.0, 0.0, 0.0])
    return np.arctan2(x_axis[..., 1], x_axis[..., 0])


def _planar(angle: float, translation_xy: np.ndarray) -> np.ndarray:
    """3x3 homogeneous matrix of a rotation by ``angle`` (rad) and a translation (m) in the plane."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, translation_xy[0]], [s, c, translation_xy[1]], [0.0, 0.0, 1.0]])


@dataclass
class Motion:
    """Keyframed reference motion of one robot (see module doc for conventions)."""

    frame_duration: float            # s between keyframes
    root_pos: np.ndarray             # (N, 3) m, world
    root_quat: np.ndarray            # (N, 4) xyzw, world, this project's z-up base frame
    q: np.ndarray                    # (N, 12) rad, canonical joint order
    loop: bool = True                # True: "Wrap", False: "Clamp"
    cycle_offset_position: bool = True
    cycle_offset_rotation: bool = False
    robot: str = ""                  # robot the joint angles belong to
    name: str = ""                   # where it came from (file name, gait name)
    _slerp: Slerp = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.root_pos = np.array(self.root_pos, dtype=np.float64)
        self.root_quat = np.array(self.root_quat, dtype=np.float64)
        self.q = np.array(self.q, dtype=np.float64)
        n = len(self.root_pos)
        if n < 2:
            raise ValueError(f"motion {self.name!r} needs at least 2 frames, got {n}")
        for key, arr, width in (("root_pos", self.root_pos, 3), ("root_quat", self.root_quat, 4),
                                ("q", self.q, 12)):
            if arr.shape != (n, width):
                raise ValueError(f"motion {self.name!r}: {key} must be ({n}, {width}), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"motion {self.name!r}: {key} contains NaN or inf")
        self.frame_duration = float(self.frame_duration)
        if not (np.isfinite(self.frame_duration) and self.frame_duration > 0):
            raise ValueError(f"motion {self.name!r}: frame duration must be positive, got {self.frame_duration}")
        norms = np.linalg.norm(self.root_quat, axis=1, keepdims=True)
        if np.any(norms < 1e-9):
            raise ValueError(f"motion {self.name!r}: root_quat has a zero quaternion")
        self.root_quat = self.root_quat / norms
        self._slerp = Slerp(self.frame_times, Rotation.from_quat(self.root_quat))

    # -- properties ------------------------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        """Number of keyframes."""
        return len(self.root_pos)

    @property
    def duration(self) -> float:
        """Length of one cycle / of the clip in s: ``(N - 1) * frame_duration``."""
        return (self.num_frames - 1) * self.frame_duration

    @property
    def frame_times(self) -> np.ndarray:
        """Keyframe times (s), ``(N,)``."""
        return np.arange(self.num_frames) * self.frame_duration

    @property
    def cycle_delta_heading(self) -> float:
        """Net heading change (rad) of one cycle (last keyframe minus first), wrapped to (-pi, pi]."""
        d = float(heading(self.root_quat[-1]) - heading(self.root_quat[0]))
        return float(np.arctan2(np.sin(d), np.cos(d)))

    @property
    def cycle_displacement(self) -> np.ndarray:
        """Net root displacement (m, world x, y, z) of one cycle, last keyframe minus first."""
        return self.root_pos[-1] - self.root_pos[0]

    @property
    def mean_velocity(self) -> np.ndarray:
        """Average root velocity over one cycle (m/s, world x, y, z)."""
        return self.cycle_displacement / self.duration

    # -- playback --------------------------------------------------------------------------------
    def _cycles(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cycle index, time inside the cycle in s) of times ``t`` (s), arrays."""
        d = self.duration
        if not self.loop:
            return np.zeros(t.shape, dtype=int), np.clip(t, 0.0, d)
        k = np.floor(t / d).astype(int)
        tau = t - k * d
        wrap = tau >= d  # rounding at the end of a cycle
        k, tau = np.where(wrap, k + 1, k), np.where(wrap, 0.0, tau)
        return k, np.maximum(tau, 0.0)

    def cycle_transform(self, k: int) -> np.ndarray:
        """Planar transform (3x3 homogeneous, m) that carries cycle 0 to cycle ``k``."""
        if k == 0 or not (self.cycle_offset_position or self.cycle_offset_rotation):
            return np.eye(3)
        dh = self.cycle_delta_heading if self.cycle_offset_rotation else 0.0
        first = self.root_pos[0, :2]
        end = self.root_pos[-1, :2] if self.cycle_offset_position else first
        c, s = np.cos(dh), np.sin(dh)
        rotated_first = np.array([c * first[0] - s * first[1], s * first[0] + c * first[1]])
        one = _planar(dh, end - rotated_first)  # first keyframe -> last keyframe, in the plane
        return np.linalg.matrix_power(one, int(k))

    def poses(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Root positions (T, 3) m, orientations (T, 4) xyzw and joint angles (T, 12) rad at ``times`` (s)."""
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        k, tau = self._cycles(t)
        x = tau / self.frame_duration
        i = np.minimum(np.floor(x).astype(int), self.num_frames - 2)
        a = (x - i)[:, None]
        pos = (1.0 - a) * self.root_pos[i] + a * self.root_pos[i + 1]
        q = (1.0 - a) * self.q[i] + a * self.q[i + 1]
        rot = self._slerp(tau)
        yaw = np.zeros(len(t))
        for kk in np.unique(k):
            if kk == 0:
                continue
            m = self.cycle_transform(int(kk))
            sel = k == kk
            pos[sel, :2] = pos[sel, :2] @ m[:2, :2].T + m[:2, 2]
            yaw[sel] = np.arctan2(m[1, 0], m[0, 0])
        if np.any(yaw != 0.0):
            rot = Rotation.from_euler("z", yaw[:, None]) * rot
        quat = rot.as_quat().reshape(-1, 4)
        return pos, quat / np.linalg.norm(quat, axis=1, keepdims=True), q

    def pose_at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Root position (m), root orientation (xyzw) and joint angles (rad) at time ``t`` (s)."""
        pos, quat, q = self.poses([float(t)])
        return pos[0], quat[0], q[0]

    def sample(self, times) -> dict[str, np.ndarray]:
        """States at many times (s): MotionState fields stacked, each ``(len(times), ...)``.

        Velocities are central finite differences over half a keyframe interval each side
        (one-sided at the ends of a clamped clip, zero outside it where the pose is held).
        """
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        h = 0.5 * self.frame_duration
        lo, hi = t - h, t + h
        if not self.loop:  # one-sided inside the clip; outside it the pose is held, velocities 0
            lo, hi = np.clip(lo, 0.0, self.duration), np.clip(hi, 0.0, self.duration)
        p0, r0, q0 = self.poses(lo)
        p1, r1, q1 = self.poses(hi)
        pos, quat, q = self.poses(t)
        dt = np.maximum(hi - lo, 1e-12)[:, None]
        ang = (Rotation.from_quat(r1) * Rotation.from_quat(r0).inv()).as_rotvec().reshape(-1, 3) / dt
        return {"root_pos": pos, "root_quat": quat, "q": q, "root_lin_vel": (p1 - p0) / dt,
                "root_ang_vel": ang, "dq": (q1 - q0) / dt}

    def state_at(self, t: float) -> MotionState:
        """Reference state at time ``t`` (s), velocities by central finite differences."""
        s = self.sample([float(t)])
        return MotionState(**{k: v[0] for k, v in s.items()})

    # -- derived motions -------------------------------------------------------------------------
    def _replace(self, **changes) -> "Motion":
        fields = dict(frame_duration=self.frame_duration, root_pos=self.root_pos, root_quat=self.root_quat,
                      q=self.q, loop=self.loop, cycle_offset_position=self.cycle_offset_position,
                      cycle_offset_rotation=self.cycle_offset_rotation, robot=self.robot, name=self.name)
        fields.update(changes)
        return Motion(**fields)

    def retimed(self, speed: float) -> "Motion":
        """The same keyframes played ``speed`` times faster (any positive factor)."""
        if not (np.isfinite(speed) and speed > 0):
            raise ValueError(f"playback speed must be positive, got {speed}")
        return self._replace(frame_duration=self.frame_duration / speed)

    def time_warp(self, speed: float) -> "Motion":
        """Time warping as in VIRL: play at ``speed`` in [0.5, 2.0], linear interpolation in between."""
        lo, hi = WARP_RANGE
        if not (lo <= speed <= hi):
            raise ValueError(f"time-warp speed must be in [{lo}, {hi}], got {speed}")
        return self.retimed(speed)

    def resampled(self, fps: float) -> "Motion":
        """Keyframes re-sampled at ``fps`` (Hz) over the same duration (rounded to whole frames)."""
        n = max(1, int(round(self.duration * fps)))
        pos, quat, q = self.poses(np.linspace(0.0, self.duration, n + 1))
        return self._replace(frame_duration=self.duration / n, root_pos=pos, root_quat=quat, q=q)

    # -- storage ---------------------------------------------------------------------------------
    def to_arrays(self, prefix: str = "motion_") -> dict[str, np.ndarray]:
        """Plain arrays (for ``np.savez``) from which :meth:`from_arrays` rebuilds the motion."""
        return {
            f"{prefix}frame_duration": np.float64(self.frame_duration),
            f"{prefix}root_pos": self.root_pos, f"{prefix}root_quat": self.root_quat, f"{prefix}q": self.q,
            f"{prefix}flags": np.array([self.loop, self.cycle_offset_position, self.cycle_offset_rotation]),
            f"{prefix}robot": np.str_(self.robot), f"{prefix}name": np.str_(self.name),
        }

    @staticmethod
    def from_arrays(arrays, prefix: str = "motion_") -> "Motion":
        """Rebuild a motion saved by :meth:`to_arrays` (a dict or an ``np.load`` result)."""
        flags = np.asarray(arrays[f"{prefix}flags"], dtype=bool)
        return Motion(frame_duration=float(arrays[f"{prefix}frame_duration"]),
                      root_pos=arrays[f"{prefix}root_pos"], root_quat=arrays[f"{prefix}root_quat"],
                      q=arrays[f"{prefix}q"], loop=bool(flags[0]), cycle_offset_position=bool(flags[1]),
                      cycle_offset_rotation=bool(flags[2]), robot=str(arrays[f"{prefix}robot"]),
                      name=str(arrays[f"{prefix}name"]))
