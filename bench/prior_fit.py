"""Does the gait prior fitted to the video alone find the video's phase pattern? (run by hand)

    python bench/prior_fit.py [--robot pupper] [--videos trot,pace,bound,pronk,walk,dog_trot,dog_pace]
                              [--motions ../shared/motions] [--sheets DIR] [--shown-on laikago]

For each video: a built-in gait's demonstration, or a dog motion-capture clip from
``--motions`` retargeted to the robot and rendered (``dog_trot`` -> ``dog_trot.txt``; skipped
when the folder is absent). With ``--shown-on ROBOT`` the clips are instead retargeted to that
robot, rendered as ``demo render --video`` writes an ``.mp4`` (the larger RGB render) and
imported for ``--robot`` (the issue's dog video). As in training, the fit draws its candidates on
the registered robot whose body the video shows. The TG is fitted to the frames alone
(``virl_quad.training.video_prior``); the truth is the least-squares fit to the reference
motion (``virl_quad.training.prior.fit_tg``). A pattern is right when every leg's phase
offset relative to leg FR is within 1/8 cycle of the truth's. Prints a markdown table and the
count; ``--sheets`` writes each fit's contact sheet (video | fit) there.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.training.prior import fit_tg
from virl_quad.training.video_prior import fit_tg_to_video, relative_offsets, same_pattern, save_fit_sheet, silhouettes

DEFAULT_MOTIONS = Path(__file__).resolve().parents[2] / "shared" / "motions"


def _pattern(offsets) -> str:
    return ", ".join(f"{o:.2f}".rstrip("0").rstrip(".") if o else "0" for o in relative_offsets(offsets))


def _video_of(clip: Path, body: str, robot: str):
    """The clip retargeted to ``body``, rendered to an .mp4 as ``demo render --video`` does, imported for ``robot``."""
    import tempfile

    from virl_quad.demo.render import render_demonstration
    from virl_quad.demo.video_import import import_video

    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / f"{clip.stem}.mp4"
        render_demonstration(demo_lib.load(str(clip), body).motion, body, video=video, preview="render")
        return import_video(video, robot)


def main() -> int:
    """Fit every video, print the table; exit 0."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper", help="robot the videos are rendered on and the TG is for")
    p.add_argument("--videos", default="trot,pace,bound,pronk,walk,dog_trot,dog_pace",
                   help="built-in gait names and motion-clip names (a .txt in --motions), comma separated")
    p.add_argument("--motions", type=Path, default=DEFAULT_MOTIONS, help="folder of motion-capture clips")
    p.add_argument("--sheets", type=Path, help="write the contact sheets (video | fit) into this folder")
    p.add_argument("--shown-on", default="", help="render the motion clips on this robot as an .mp4 and import it")
    a = p.parse_args()
    bodies = [robots.get(n) for n in robots.names()]          # the fit picks the body the video shows, as training does
    spec = robots.get(a.robot)
    print("| video | truth (FR, FL, RR, RL) | fitted | Hz fitted (truth) | difference (gray levels) | body drawn on | s | pattern |")
    print("|---|---|---|---|---|---|---|---|")
    right = total = 0
    for name in [v.strip() for v in a.videos.split(",") if v.strip()]:
        source = name if name in demo_lib.GAIT_NAMES else a.motions / f"{name}.txt"
        if not isinstance(source, str) and not source.is_file():
            print(f"| {name} | (no {source}: skipped) | | | | | | |")
            continue
        demo = demo_lib.load(str(source), a.robot)
        truth, _ = fit_tg(demo.motion, spec)
        if a.shown_on and not isinstance(source, str):
            demo = _video_of(source, a.shown_on, a.robot)
        finalists, report, fitted = fit_tg_to_video(demo.frames, demo.fps, spec, bodies=bodies)
        params = finalists[0]
        ok = same_pattern(params.offsets, truth.offsets)
        right, total = right + ok, total + 1
        print(f"| {name} | {_pattern(truth.offsets)} | {_pattern(params.offsets)} | {params.frequency:.2f} "
              f"({truth.frequency:.2f}) | {report['distance'] * 255:.2f} | {report['body']} | {report['seconds']:.0f} | "
              f"{'right' if ok else 'WRONG'} |", flush=True)
        if a.sheets:
            save_fit_sheet(silhouettes(demo.frames), fitted[0], a.sheets / f"{name}.png")
    print(f"\n{right} of {total} phase patterns right")
    return 0


if __name__ == "__main__":
    sys.exit(main())
