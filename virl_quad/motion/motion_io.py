"""Motion files: motion_imitation / DeepMimic JSON clips and pybullet's real Laikago recording.

JSON clip (``.txt`` or ``.json``)::

    {"LoopMode": "Wrap" | "Clamp", "FrameDuration": s, "EnableCycleOffsetPosition": bool,
     "EnableCycleOffsetRotation": bool, "Frames": [[x, y, z, qx, qy, qz, qw, 12 joint angles], ...]}

Frame convention of motion_imitation's Laikago clips (checked, see ``contacts.py``): the root
orientation is the base orientation of ``laikago_toes_limits.urdf``, whose chassis frame is
not z-up (it is spawned with Euler(pi/2, 0, pi/2)); the root position is that base's PyBullet
position, which coincides with the z-up chassis origin; joint angles are URDF angles
(not motor angles: the motor offsets (0, -0.6, +0.66) rad would push the feet ~9 cm
into the ground). This project's Laikago is ``laikago_toes_zup_lores.urdf``, so reading
a clip converts the root orientation ``q_zup = q_file * Euler(pi/2, 0, pi/2)^-1`` and
keeps position and joint angles. Files this project writes for another robot carry a
``"Robot"`` key and store that robot's own (z-up) root orientation.

Laikago recording (``pybullet_data/laikago/data1.txt``): CSV rows ``index, time (ms),
12 joint angles`` in the Laikago SDK convention; URDF angle = sign * angle + offset with
offsets (0, -0.7, +0.7) rad per leg and signs (-1, 1, 1, 1, 1, 1, -1, 1, 1, 1, 1, 1).
It has no root trajectory: the root is kept at the spawn height, level.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from virl_quad.motion.motion import Motion
from virl_quad.kinematics.frames import LIMITS_URDF_BASE_IN_ZUP, quat_conjugate, quat_multiply

ROW_WIDTH = 19  # root position 3 + root quaternion 4 + 12 joint angles
REQUIRED_KEYS = ("LoopMode", "FrameDuration", "Frames")
LOOP_MODES = ("Wrap", "Clamp")

#: Laikago SDK -> URDF joint angles (pybullet's own laikago example): urdf = sign * sdk + offset.
RECORDING_OFFSETS = np.array([0.0, -0.7, 0.7] * 4)                    # rad
RECORDING_SIGNS = np.array([-1, 1, 1, 1, 1, 1, -1, 1, 1, 1, 1, 1.0])
RECORDING_WIDTH = 14  # index, time (ms), 12 joint angles


def _clip_quat_to_zup(quat: np.ndarray) -> np.ndarray:
    """motion_imitation Laikago root orientation(s) -> z-up URDF base orientation(s), xyzw."""
    return quat_multiply(quat, quat_conjugate(LIMITS_URDF_BASE_IN_ZUP))


def _zup_quat_to_clip(quat: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_clip_quat_to_zup`."""
    return quat_multiply(quat, LIMITS_URDF_BASE_IN_ZUP)


def laikago_recording_path() -> Path:
    """Path of pybullet_data's real Laikago recording ``laikago/data1.txt``."""
    import pybullet_data

    return Path(pybullet_data.getDataPath()) / "laikago" / "data1.txt"


def _read_text(path: str | os.PathLike) -> str:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"motion file not found: {p}")
    try:
        return p.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"cannot read motion file {p}: {e}") from None


def parse_motion_json(text: str, name: str = "motion") -> Motion:
    """Parse the text of a motion_imitation JSON clip into a :class:`Motion` (see module doc)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{name}: not valid JSON ({e.msg} at line {e.lineno})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{name}: expected a JSON object with keys {', '.join(REQUIRED_KEYS)}")
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise ValueError(f"{name}: missing key(s) {', '.join(missing)}")
    mode = data["LoopMode"]
    if mode not in LOOP_MODES:
        raise ValueError(f"{name}: LoopMode must be one of {', '.join(LOOP_MODES)}, got {mode!r}")
    try:
        dt = float(data["FrameDuration"])
    except (TypeError, ValueError):
        raise ValueError(f"{name}: FrameDuration must be a number, got {data['FrameDuration']!r}") from None
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"{name}: FrameDuration must be positive, got {dt}")
    frames = data["Frames"]
    if not isinstance(frames, list) or len(frames) < 2:
        raise ValueError(f"{name}: Frames must be a list of at least 2 rows")
    for i, row in enumerate(frames):
        if not isinstance(row, list) or len(row) != ROW_WIDTH:
            width = len(row) if isinstance(row, list) else type(row).__name__
            raise ValueError(f"{name}: frame {i} has {width} numbers, expected {ROW_WIDTH} "
                             "(root position 3, root quaternion xyzw 4, 12 joint angles)")
    try:
        arr = np.array(frames, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: Frames must contain only numbers") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: Frames contain NaN or inf")
    robot = str(data.get("Robot", "laikago"))
    quat = arr[:, 3:7]
    if np.any(np.linalg.norm(quat, axis=1) < 1e-9):
        raise ValueError(f"{name}: a root quaternion is zero")
    quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    if robot == "laikago":
        quat = _clip_quat_to_zup(quat)
    return Motion(frame_duration=dt, root_pos=arr[:, :3], root_quat=quat, q=arr[:, 7:],
                  loop=(mode == "Wrap"),
                  cycle_offset_position=bool(data.get("EnableCycleOffsetPosition", False)),
                  cycle_offset_rotation=bool(data.get("EnableCycleOffsetRotation", False)),
                  robot=robot, name=name)


def read_motion_json(path: str | os.PathLike) -> Motion:
    """Read a motion_imitation JSON clip (``.txt``/``.json``); raises a one-line ValueError if malformed."""
    return parse_motion_json(_read_text(path), name=Path(path).name)


def motion_to_json(motion: Motion) -> str:
    """The motion_imitation JSON text of ``motion`` (Laikago roots in the clip convention)."""
    quat = motion.root_quat
    robot = motion.robot or "laikago"
    if robot == "laikago":
        quat = _zup_quat_to_clip(quat)
    rows = np.concatenate([motion.root_pos, quat, motion.q], axis=1)
    data = {
        "LoopMode": "Wrap" if motion.loop else "Clamp",
        "FrameDuration": motion.frame_duration,
        "EnableCycleOffsetPosition": bool(motion.cycle_offset_position),
        "EnableCycleOffsetRotation": bool(motion.cycle_offset_rotation),
    }
    if robot != "laikago":
        data["Robot"] = robot
    head = json.dumps(data, indent=1)[:-2]
    body = ",\n".join("  [" + ", ".join(f"{v:.6f}" for v in row) + "]" for row in rows)
    return head + ',\n "Frames": [\n' + body + "\n ]\n}\n"


def write_motion_json(motion: Motion, path: str | os.PathLike) -> Path:
    """Write ``motion`` as a motion_imitation JSON clip; returns the path."""
    p = Path(path)
    p.write_text(motion_to_json(motion))
    return p


def parse_laikago_recording(text: str, spawn_height: float, name: str = "data1.txt",
                            fps: float = 100.0) -> Motion:
    """Parse a Laikago SDK recording (CSV, see module doc) into a clamped Motion sampled at ``fps`` (Hz)."""
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        parts = [s for s in line.replace(",", " ").split() if s]
        if len(parts) != RECORDING_WIDTH:
            raise ValueError(f"{name}: line {lineno} has {len(parts)} numbers, expected {RECORDING_WIDTH} "
                             "(index, time ms, 12 joint angles)")
        try:
            rows.append([float(s) for s in parts])
        except ValueError:
            raise ValueError(f"{name}: line {lineno} is not all numbers") from None
    if len(rows) < 2:
        raise ValueError(f"{name}: needs at least 2 rows, got {len(rows)}")
    arr = np.array(rows)
    t = (arr[:, 1] - arr[0, 1]) * 1e-3            # s
    if not np.all(np.diff(t) > 0):
        raise ValueError(f"{name}: timestamps must increase")
    q_urdf = arr[:, 2:] * RECORDING_SIGNS + RECORDING_OFFSETS  # rad
    n = max(1, int(round(t[-1] * fps)))
    grid = np.linspace(0.0, t[-1], n + 1)
    q = np.stack([np.interp(grid, t, q_urdf[:, j]) for j in range(12)], axis=1)
    root = np.tile([0.0, 0.0, spawn_height], (n + 1, 1))
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n + 1, 1))
    return Motion(frame_duration=t[-1] / n, root_pos=root, root_quat=quat, q=q, loop=False,
                  cycle_offset_position=False, cycle_offset_rotation=False, robot="laikago", name=name)


def read_laikago_recording(path: str | os.PathLike | None = None, spawn_height: float | None = None,
                           fps: float = 100.0) -> Motion:
    """Read pybullet's real Laikago recording (default ``laikago/data1.txt``) as a clamped Motion."""
    if spawn_height is None:
        from virl_quad import robots

        spawn_height = robots.get("laikago").spawn_height
    path = laikago_recording_path() if path is None else Path(path)
    return parse_laikago_recording(_read_text(path), spawn_height, name=Path(path).name, fps=fps)


def read_motion(path: str | os.PathLike) -> Motion:
    """Read any motion file: a JSON clip, or a Laikago recording CSV (told apart by content)."""
    text = _read_text(path)
    name = Path(path).name
    if text.lstrip().startswith("{"):
        return parse_motion_json(text, name=name)
    first = text.strip().split("\n", 1)[0] if text.strip() else ""
    if first and first.replace(",", " ").split()[0].lstrip("-").replace(".", "", 1).isdigit():
        from virl_quad import robots

        return parse_laikago_recording(text, robots.get("laikago").spawn_height, name=name)
    raise ValueError(f"{name}: neither a motion_imitation JSON clip nor a Laikago recording CSV")
