"""Ground-contact check of a reference motion: do its feet touch the ground without sinking?

This is the kinematic proof of a motion file's frame convention: played back with the
wrong root orientation or joint-angle offsets, the feet float tens of cm above the
ground or sink far below it. Heights are those of the foot sphere bottoms (foot frame z
minus ``spec.foot_radius``, m) from Pinocchio forward kinematics, which matches
PyBullet's ``World.foot_positions`` (both robots' base inertial origins are at the base
link origins).

Criteria (per clip): the lowest foot is within ``TOUCH`` (2 cm) of the ground for most
(> 50 %) of every gait cycle, and no foot sinks more than ``SINK`` (2 cm) below it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from virl_quad import robots
from virl_quad.motion.motion import Motion

TOUCH = 0.02  # m, "touching": lowest foot sphere bottom at most this high
SINK = 0.02   # m, largest allowed penetration
MOTION_SUFFIXES = (".txt", ".json")


@dataclass
class ContactStats:
    """Ground-contact figures of one motion on one robot (heights in m)."""

    clip: str
    robot: str
    min_low: float          # m, lowest foot height, minimum over time
    median_low: float       # m, lowest foot height, median over time
    max_low: float          # m, lowest foot height, maximum over time (flight phases)
    max_penetration: float  # m, deepest any foot goes below the ground (>= 0)
    touch_fraction: float   # share of the worst cycle with the lowest foot within TOUCH
    ik_residual: float = 0.0  # m, worst retargeting IK residual (0 when not retargeted)

    @property
    def ok(self) -> bool:
        """True when the clip meets both criteria (see module doc)."""
        return self.touch_fraction > 0.5 and self.max_penetration <= SINK


def foot_heights(motion: Motion, robot: str, times: np.ndarray) -> np.ndarray:
    """Foot sphere bottom heights (m) above the ground, (len(times), 4), FR FL RR RL."""
    from virl_quad.kinematics import Kinematics

    spec = robots.get(robot)
    kin = Kinematics(spec)
    poses = [motion.pose_at(t) for t in np.asarray(times, dtype=np.float64)]
    feet = np.array([kin.foot_positions(p, r, q) for p, r, q in poses])
    return feet[..., 2] - spec.foot_radius


def ground_contact(motion: Motion, robot: str | None = None, samples_per_frame: int = 2,
                   ik_residual: float = 0.0) -> ContactStats:
    """Contact figures of ``motion`` played on ``robot`` (default ``motion.robot``), over each cycle.

    A looping motion is checked over one cycle (later cycles repeat its heights); a clamped one over
    the whole clip, cut into pieces of about one second for the per-cycle touch fraction.
    """
    robot = robot or motion.robot
    n = (motion.num_frames - 1) * samples_per_frame
    times = np.linspace(0.0, motion.duration, n + 1)
    heights = foot_heights(motion, robot, times)
    low = heights.min(axis=1)
    touching = low <= TOUCH
    pieces = 1 if motion.loop else max(1, int(round(motion.duration)))
    fraction = min(float(np.mean(chunk)) for chunk in np.array_split(touching, pieces))
    return ContactStats(clip=motion.name, robot=robot, min_low=float(low.min()), median_low=float(np.median(low)),
                        max_low=float(low.max()), max_penetration=float(max(0.0, -heights.min())),
                        touch_fraction=fraction, ik_residual=ik_residual)


def shared_motions_dir() -> Path:
    """``../shared/motions`` next to the repository root (may not exist)."""
    return Path(__file__).resolve().parents[2].parent / "shared" / "motions"


def motion_files(folder: str | Path | None = None) -> list[Path]:
    """Motion files (``.txt``/``.json``, README excluded) in ``folder`` (default: the shared motions)."""
    folder = Path(folder) if folder is not None else shared_motions_dir()
    if not folder.is_dir():
        raise FileNotFoundError(f"motion folder not found: {folder}")
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in MOTION_SUFFIXES and p.is_file())


def contact_table(folder: str | Path | None = None, targets: tuple[str, ...] = ("laikago", "pupper")) -> list[ContactStats]:
    """Contact figures of every clip in ``folder`` on each robot of ``targets`` (retargeted as needed)."""
    from virl_quad.motion.motion_io import read_motion
    from virl_quad.motion.retarget import retarget_with_residual

    rows = []
    for path in motion_files(folder):
        motion = read_motion(path)
        for robot in targets:
            if robot == motion.robot:
                rows.append(ground_contact(motion, robot))
            else:
                moved, residual = retarget_with_residual(motion, robot)
                rows.append(ground_contact(moved, robot, ik_residual=float(residual.max())))
            rows[-1].clip = path.name
    return rows


def format_table(rows: list[ContactStats]) -> str:
    """A plain-text table of contact figures (heights in cm)."""
    head = (f"{'clip':24s} {'robot':8s} {'min low':>8s} {'median':>8s} {'max low':>8s} {'max pen':>8s} "
            f"{'touch':>6s} {'IK res':>7s} ok")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.clip:24s} {r.robot:8s} {r.min_low * 100:7.2f}c {r.median_low * 100:7.2f}c "
                     f"{r.max_low * 100:7.2f}c {r.max_penetration * 100:7.2f}c {r.touch_fraction * 100:5.0f}% "
                     f"{r.ik_residual * 1000:5.1f}mm {'yes' if r.ok else 'NO'}")
    lines.append("heights in cm of the foot sphere bottoms; touch = share of the worst cycle with the lowest "
                 f"foot within {TOUCH * 100:.0f} cm of the ground; IK res = worst retargeting residual")
    return "\n".join(lines)
