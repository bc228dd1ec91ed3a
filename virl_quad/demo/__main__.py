"""Command line: render, import, inspect and check demonstrations.

    python -m virl_quad.demo render --robot pupper --gait trot --out demo.npz [--video demo.mp4]
    python -m virl_quad.demo render --robot pupper --motion dog_trot.txt --out demo.npz
    python -m virl_quad.demo import clip.mp4 --robot laikago --out demo.npz
    python -m virl_quad.demo show demo.npz --out grid.png
    python -m virl_quad.demo contacts [--dir ../shared/motions]
    python -m virl_quad.demo score [--robot pupper] [--gait trot]
    python -m virl_quad.demo roundtrip [--robot pupper] [--preview render|frames]

Bad input (missing file, unreadable or empty video, malformed motion file, unknown gait or
robot) prints one line ``error: ...`` on stderr and exits with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import sys
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from virl_quad import robots
from virl_quad.cli import Parser, add_options, from_options, opt
from virl_quad.demo.render import PREVIEW_SIZE, PREVIEWS
from virl_quad.motion.gaits import GAIT_NAMES

EXIT_USAGE = 2


class UsageError(Exception):
    """A command-line mistake: reported in one line, exit code 2."""


class _Parser(Parser):
    """The shared parser, raising its one-line error so :func:`main` can return exit code 2."""

    def error(self, message: str) -> typing.NoReturn:  # noqa: D102 - argparse hook
        raise UsageError(message)


def _describe(d) -> str:
    motion = "with reference motion" if d.motion is not None else "no reference motion"
    return f"{d.num_frames} frames, {d.fps:.2f} fps, {d.duration:.2f} s, robot {d.robot or '?'}, {motion}"


def cmd_render(a: RenderArgs) -> None:
    """Render a built-in gait or a motion file to ``.npz`` (and optionally ``.mp4``)."""
    from virl_quad.demo import render
    from virl_quad.motion import gaits, motion_io, retarget

    if a.gait and a.motion:
        raise UsageError("argument --motion: not allowed with argument --gait")
    robots.get(a.robot)
    if a.motion:
        motion = retarget.retarget(motion_io.read_motion(a.motion), a.robot)
        source = str(a.motion)
    else:
        motion = gaits.gait_motion(a.robot, a.gait or gaits.DEFAULT_GAIT)
        source = f"gait:{a.gait or gaits.DEFAULT_GAIT}"
    d = render.render_demonstration(motion, a.robot, source=source, min_seconds=a.seconds, video=a.video,
                                    preview_size=a.video_size, preview=a.preview)
    render.save_npz(d, a.out)
    print(f"wrote {a.out}: {_describe(d)}" + (f"; video {a.video}" if a.video else ""))


def cmd_import(a: ImportArgs) -> None:
    """Import a video file to ``.npz``."""
    from virl_quad.demo import render, video_import

    d = video_import.import_video(a.video, a.robot, follow={"auto": None, "on": True, "off": False}[a.follow])
    render.save_npz(d, a.out)
    print(f"wrote {a.out}: {_describe(d)}; subject followed: {d.camera.get('followed')}")


def cmd_show(a: ShowArgs) -> None:
    """Write a contact sheet PNG of a saved demonstration."""
    from virl_quad.demo import render, sheet

    d = render.load_npz(a.demo)
    sheet.save_contact_sheet(d, a.out, columns=a.columns, max_frames=a.frames)
    print(f"wrote {a.out}: {_describe(d)}")


def cmd_contacts(a: ContactsArgs) -> None:
    """Print the ground-contact table of every clip in a folder, on both robots."""
    from virl_quad.motion import contacts

    rows = contacts.contact_table(a.dir, tuple(a.robots))
    print(contacts.format_table(rows))
    if a.strict and not all(r.ok for r in rows):
        raise SystemExit(1)


def cmd_score(a: ScoreArgs) -> None:
    """Self-check of the score on a gait: playback (1.0), default pose, quarter-cycle shift."""
    from virl_quad.demo import render
    from virl_quad.evaluation import score
    from virl_quad.motion import gaits

    spec = robots.get(a.robot)
    motion = render.fit_loop(gaits.gait_motion(a.robot, a.gait), spec.control_hz)
    times = np.arange(int(a.seconds * spec.control_hz)) / spec.control_hz
    n = len(times)
    playback = score.Trajectory(**motion.sample(times))
    hold = score.Trajectory(root_pos=playback.root_pos.copy(), root_quat=np.tile([0, 0, 0, 1.0], (n, 1)),
                            q=np.tile(spec.default_pose, (n, 1)), dq=np.zeros((n, 12)),
                            root_lin_vel=np.zeros((n, 3)), root_ang_vel=np.zeros((n, 3)))
    hold.root_pos[:, 2] = spec.spawn_height
    shifted = score.Trajectory(**motion.sample(times + motion.duration / 4))
    keys = list(score.TERMS) + ["total", "total_best_offset", "best_offset"]
    print(f"{a.robot} {a.gait}: cycle {motion.duration:.3f} s, {n} steps")
    print(f"{'case':22s} " + " ".join(f"{k:>13s}" for k in keys))
    for name, traj in (("playback", playback), ("default pose", hold), ("quarter-cycle shift", shifted)):
        res = score.score_trajectory(traj, motion, times, a.robot)
        print(f"{name:22s} " + " ".join(f"{res[k]:13.4f}" for k in keys))


def cmd_roundtrip(a: RoundtripArgs) -> None:
    """Render -> .mp4 -> import error, and ground motion of forward vs in-place demos after import."""
    from virl_quad.demo import checks

    robots.get(a.robot)
    r = checks.progress_visibility(a.robot, a.gait, preview=a.preview, seconds=a.seconds)
    print(f"{a.robot} {a.gait}, preview {a.preview}: round-trip MAE {r['roundtrip_mae_forward']:.2f} "
          f"(in place {r['roundtrip_mae_in_place']:.2f}) gray levels of 255")
    print(f"{'ground strip':18s} {'change/frame':>13s} {'shift px/frame':>15s}")
    for name in ("rendered_forward", "rendered_in_place", "imported_forward", "imported_in_place"):
        print(f"{name:18s} {r[name + '_ground_change']:13.3f} {r[name + '_ground_shift_px']:15.3f}")


@dataclass
class RenderArgs:
    """Render a built-in gait or a motion file."""

    robot: str = opt("", f"one of: {', '.join(robots.names())}", required=True)
    gait: str | None = opt(None, f"built-in gait: {', '.join(GAIT_NAMES)} (trot when neither this nor --motion)")
    motion: str | None = opt(None, "motion file (.txt/.json motion_imitation clip, Laikago recording); not with --gait")
    out: str = opt("", "output .npz", required=True)
    video: str | None = opt(None, "also write an .mp4 preview here")
    video_size: int = opt(PREVIEW_SIZE, "preview side in px (render preview)")
    preview: str = opt("render", "what --video shows: render, a larger RGB render to watch; frames, the 48x48 "
                                 "frames the reward model sees, enlarged", choices=PREVIEWS)
    seconds: float = opt(2.0, "at least this long, whole cycles (s)")


@dataclass
class ImportArgs:
    """Import a video file."""

    video: str = opt("", "video file (.mp4, .avi, ...)", positional=True, required=True)
    robot: str = opt("", f"one of: {', '.join(robots.names())}", required=True)
    out: str = opt("", "output .npz", required=True)
    follow: str = opt("auto", "follow the moving subject", choices=("auto", "on", "off"))


@dataclass
class ShowArgs:
    """Contact sheet of a saved demonstration."""

    demo: str = opt("", "demonstration .npz", positional=True, required=True)
    out: str = opt("", "output .png", required=True)
    columns: int = opt(8, "frames per row of the sheet")
    frames: int = opt(32, "at most this many frames, evenly spaced")


@dataclass
class ContactsArgs:
    """Ground-contact table of motion clips."""

    dir: str | None = opt(None, "folder of clips (unset: ../shared/motions)")
    robots: list[str] = opt(["laikago", "pupper"], "robots to check each clip on", nargs="+")
    strict: bool = opt(False, "exit 1 when a clip fails the criteria")


@dataclass
class ScoreArgs:
    """Self-check of the ground-truth score on a gait."""

    robot: str = opt("pupper", f"one of: {', '.join(robots.names())}")
    gait: str = opt("trot", f"one of: {', '.join(GAIT_NAMES)}")
    seconds: float = opt(4.0, "length of the scored stretch (s)")


@dataclass
class RoundtripArgs:
    """Render -> .mp4 -> import error and forward-progress visibility."""

    robot: str = opt("pupper", f"one of: {', '.join(robots.names())}")
    gait: str = opt("trot", f"one of: {', '.join(GAIT_NAMES)}")
    preview: str = opt("frames", "which video to round-trip (see render)", choices=PREVIEWS)
    seconds: float = opt(2.0, "length of the render (s)")


#: subcommand -> (its options, what it runs)
COMMANDS: dict[str, tuple[type, typing.Callable]] = {
    "render": (RenderArgs, cmd_render), "import": (ImportArgs, cmd_import), "show": (ShowArgs, cmd_show),
    "contacts": (ContactsArgs, cmd_contacts), "score": (ScoreArgs, cmd_score),
    "roundtrip": (RoundtripArgs, cmd_roundtrip),
}


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m virl_quad.demo`` argument parser: one subcommand per :data:`COMMANDS` entry,
    its options from the entry's dataclass."""
    p = _Parser(prog="python -m virl_quad.demo", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, (cls, _) in COMMANDS.items():
        add_options(sub.add_parser(name, help=(cls.__doc__ or "").strip().rstrip(".").lower()), cls)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (2 for bad input, with a one-line message on stderr)."""
    from virl_quad.quiet import import_pybullet_quietly

    import_pybullet_quietly()
    try:
        ns = build_parser().parse_args(argv)
        cls, run = COMMANDS[ns.command]
        args = from_options(cls, vars(ns))
        if ns.command == "render" and args.video:
            Path(args.video).parent.mkdir(parents=True, exist_ok=True)
        run(args)
    except UsageError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except (ValueError, FileNotFoundError, OSError) as e:
        msg = " ".join(str(e).split()) or type(e).__name__
        print(f"error: {msg}", file=sys.stderr)
        return EXIT_USAGE
    return 0


if __name__ == "__main__":
    sys.exit(main())
