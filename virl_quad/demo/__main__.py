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
from pathlib import Path

import numpy as np

from virl_quad import robots
from virl_quad.cli import Parser

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


def cmd_render(a: argparse.Namespace) -> None:
    """Render a built-in gait or a motion file to ``.npz`` (and optionally ``.mp4``)."""
    from virl_quad.demo import render
    from virl_quad.motion import gaits, motion_io, retarget

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


def cmd_import(a: argparse.Namespace) -> None:
    """Import a video file to ``.npz``."""
    from virl_quad.demo import render, video_import

    d = video_import.import_video(a.video, a.robot, follow={"auto": None, "on": True, "off": False}[a.follow])
    render.save_npz(d, a.out)
    print(f"wrote {a.out}: {_describe(d)}; subject followed: {d.camera.get('followed')}")


def cmd_show(a: argparse.Namespace) -> None:
    """Write a contact sheet PNG of a saved demonstration."""
    from virl_quad.demo import render, sheet

    d = render.load_npz(a.demo)
    sheet.save_contact_sheet(d, a.out, columns=a.columns, max_frames=a.frames)
    print(f"wrote {a.out}: {_describe(d)}")


def cmd_contacts(a: argparse.Namespace) -> None:
    """Print the ground-contact table of every clip in a folder, on both robots."""
    from virl_quad.motion import contacts

    rows = contacts.contact_table(a.dir, tuple(a.robots))
    print(contacts.format_table(rows))
    if a.strict and not all(r.ok for r in rows):
        raise SystemExit(1)


def cmd_score(a: argparse.Namespace) -> None:
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


def cmd_roundtrip(a: argparse.Namespace) -> None:
    """Render -> .mp4 -> import error, and ground motion of forward vs in-place demos after import."""
    from virl_quad.demo import checks

    robots.get(a.robot)
    r = checks.progress_visibility(a.robot, a.gait, preview=a.preview, seconds=a.seconds)
    print(f"{a.robot} {a.gait}, preview {a.preview}: round-trip MAE {r['roundtrip_mae_forward']:.2f} "
          f"(in place {r['roundtrip_mae_in_place']:.2f}) gray levels of 255")
    print(f"{'ground strip':18s} {'change/frame':>13s} {'shift px/frame':>15s}")
    for name in ("rendered_forward", "rendered_in_place", "imported_forward", "imported_in_place"):
        print(f"{name:18s} {r[name + '_ground_change']:13.3f} {r[name + '_ground_shift_px']:15.3f}")


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m virl_quad.demo`` argument parser."""
    from virl_quad.motion.gaits import GAIT_NAMES
    from virl_quad.demo.render import PREVIEW_SIZE, PREVIEWS

    p = _Parser(prog="python -m virl_quad.demo", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("render", help="render a built-in gait or a motion file")
    r.add_argument("--robot", required=True, help=f"one of: {', '.join(robots.names())}")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--gait", help=f"built-in gait: {', '.join(GAIT_NAMES)} (trot when neither this nor --motion)")
    g.add_argument("--motion", help="motion file (.txt/.json motion_imitation clip, Laikago recording)")
    r.add_argument("--out", required=True, help="output .npz")
    r.add_argument("--video", help="also write an .mp4 preview here")
    r.add_argument("--video-size", type=int, default=PREVIEW_SIZE, help="preview side in px (render preview)")
    r.add_argument("--preview", choices=PREVIEWS, default="render",
                   help="what --video shows: render, a larger RGB render to watch; frames, the 48x48 "
                        "frames the reward model sees, enlarged")
    r.add_argument("--seconds", type=float, default=2.0, help="at least this long, whole cycles (s)")
    r.set_defaults(func=cmd_render)
    i = sub.add_parser("import", help="import a video file")
    i.add_argument("video", help="video file (.mp4, .avi, ...)")
    i.add_argument("--robot", required=True, help=f"one of: {', '.join(robots.names())}")
    i.add_argument("--out", required=True, help="output .npz")
    i.add_argument("--follow", choices=("auto", "on", "off"), default="auto", help="follow the moving subject")
    i.set_defaults(func=cmd_import)
    s = sub.add_parser("show", help="contact sheet of a saved demonstration")
    s.add_argument("demo", help="demonstration .npz")
    s.add_argument("--out", required=True, help="output .png")
    s.add_argument("--columns", type=int, default=8, help="frames per row of the sheet")
    s.add_argument("--frames", type=int, default=32, help="at most this many frames, evenly spaced")
    s.set_defaults(func=cmd_show)
    c = sub.add_parser("contacts", help="ground-contact table of motion clips")
    c.add_argument("--dir", default=None, help="folder of clips (default ../shared/motions)")
    c.add_argument("--robots", nargs="+", default=["laikago", "pupper"], help="robots to check each clip on")
    c.add_argument("--strict", action="store_true", help="exit 1 when a clip fails the criteria")
    c.set_defaults(func=cmd_contacts)
    k = sub.add_parser("score", help="self-check of the ground-truth score on a gait")
    k.add_argument("--robot", default="pupper", help=f"one of: {', '.join(robots.names())}")
    k.add_argument("--gait", default="trot", help=f"one of: {', '.join(GAIT_NAMES)}")
    k.add_argument("--seconds", type=float, default=4.0, help="length of the scored stretch (s)")
    k.set_defaults(func=cmd_score)
    t = sub.add_parser("roundtrip", help="render -> .mp4 -> import error and forward-progress visibility")
    t.add_argument("--robot", default="pupper", help=f"one of: {', '.join(robots.names())}")
    t.add_argument("--gait", default="trot", help=f"one of: {', '.join(GAIT_NAMES)}")
    t.add_argument("--preview", choices=PREVIEWS, default="frames", help="which video to round-trip (see render)")
    t.add_argument("--seconds", type=float, default=2.0, help="length of the render (s)")
    t.set_defaults(func=cmd_roundtrip)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (2 for bad input, with a one-line message on stderr)."""
    from virl_quad.quiet import import_pybullet_quietly

    import_pybullet_quietly()
    try:
        args = build_parser().parse_args(argv)
        if getattr(args, "video", None) and args.command == "render":
            Path(args.video).parent.mkdir(parents=True, exist_ok=True)
        args.func(args)
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
