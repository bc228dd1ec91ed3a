"""The run's set-up before the envs start: its demonstration, the multi-task clips, and the action
space (the trajectory generator fitted to the demonstration video or its reference motion).

Each writes what it chose into the run folder (``demo.npz``, ``other_demos.npz``,
``prior_fit.json``/``prior_fit.png``) so a resumed run sees the same demonstration and clips.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from virl_quad.cli import UserError
from virl_quad.training.config import FRAMELESS_REWARDS, TrainArgs


def load_demo(args: TrainArgs, run_dir: Path):
    """The run's demonstration: the copy saved in the run folder (checked against what this
    version renders), else ``--demo`` loaded for the robot and saved there."""
    from virl_quad import demo as demo_lib

    saved = run_dir / "demo.npz"
    if saved.exists():
        d = demo_lib.load(str(saved), args.run.robot)
        if args.run.reward not in FRAMELESS_REWARDS:
            check_same_rendering(d, args)
        return d
    d = demo_lib.load(args.run.demo, args.run.robot, ground=args.env.ground)
    run_dir.mkdir(parents=True, exist_ok=True)
    from virl_quad.demo.render import save_npz

    save_npz(d, saved)
    return d


def check_same_rendering(saved, args: TrainArgs) -> None:
    """UserError if the run's saved demonstration frames differ from what the renderer makes of
    its source now (another ground or camera since the run began): the agent's frames would
    then come from another renderer than the expert's, and the learned reward would be wrong."""
    from virl_quad import demo as demo_lib

    if saved.motion is None:
        return                                   # an imported video: nothing rendered to compare
    try:
        now = demo_lib.load(args.run.demo, args.run.robot, ground=args.env.ground)
    except (ValueError, FileNotFoundError, OSError):
        return                                   # the source is not here: trust the saved frames
    if now.frames.shape != saved.frames.shape or np.abs(now.frames.astype(np.int16) - saved.frames).mean() > 1.0:
        raise UserError(f"the run's demonstration frames differ from what this version renders for {args.run.demo!r} "
                        f"(the renderer changed, e.g. its ground): train a new run")


def other_clips(args: TrainArgs, run_dir: Path) -> list[np.ndarray]:
    """Frames of the multi-task clips (saved in the run folder so a resume sees the same ones)."""
    saved = run_dir / "other_demos.npz"
    if saved.exists():
        with np.load(saved) as f:
            return [f[k] for k in sorted(f.files)]
    from virl_quad import demo as demo_lib
    from virl_quad.motion.gaits import GAIT_NAMES

    choice = args.distance.other_demos.strip()
    gait = args.run.demo.removeprefix("gait:")
    if choice == "auto":
        sources = [f"gait:{g}" for g in GAIT_NAMES if g != gait] if gait in GAIT_NAMES else []
    elif choice in ("", "none"):
        sources = []
    else:
        sources = [s.strip() for s in choice.split(",") if s.strip()]
    clips = [demo_lib.load(s, args.run.robot, ground=args.env.ground).frames for s in sources]
    run_dir.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(saved, **{f"clip{i:02d}": c for i, c in enumerate(clips)})
    if sources:
        print(f"multi-task clips for the distance model: {', '.join(sources)}", flush=True)
    return clips


def action_options(args: TrainArgs, demo, resume_data: dict | None, run_dir: Path) -> dict:
    """The env options that define the policy's actions: a resumed run's own (its checkpoint's
    contract), else the robot's defaults with ``--tg``'s trajectory generator (``--prior-from``:
    fitted to the demonstration video, or to its reference motion)."""
    from virl_quad.training import checkpoint

    if resume_data is not None:
        return checkpoint.contract_of(resume_data, args.run.robot).env_overrides()
    if not args.prior.tg:
        return {}
    from virl_quad import robots

    spec = robots.get(args.run.robot)
    try:
        if args.prior.prior_from == "video":
            tg, report = prior_from_video(args, demo, spec, run_dir)
        else:
            from virl_quad.training.prior import tg_for_demo

            tg, report = tg_for_demo(demo, spec, args.run.demo)
    except ValueError as e:
        raise UserError(str(e)) from None
    print(f"trajectory generator: {report}", flush=True)
    return {"tg": tg}


def prior_from_video(args: TrainArgs, demo, spec, run_dir: Path):
    """The TG fitted to the demonstration's frames, the nearest finalist whose warm-start teacher
    carries the robot when there is a warm start (:mod:`virl_quad.training.prior_check`; when none
    does, the nearest that does at the robot's built-in trot speed), with hind feet and swing
    changed where that teacher travels against the video's ground; writes
    prior_fit.json and prior_fit.png (video | fitted gait) into the run folder."""
    from virl_quad import robots
    from virl_quad.training.prior_check import MAX_FALL_RATE, gait_for_travel, pick_carrying, slowed_to_carry
    from virl_quad.training.video_prior import describe, fit_tg_to_video, save_fit_sheet, silhouettes

    print("fitting the gait prior to the demonstration video ...", flush=True)
    say = lambda line: print(line, flush=True)
    local = args.env.workers == "local" and args.env.num_workers > 0          # the user's process count
    bodies = [robots.get(name) for name in robots.names()]                     # which one the video shows
    finalists, report, fitted = fit_tg_to_video(demo.frames, demo.fps, spec, log=say,
                                                workers=args.env.num_workers if local else None, bodies=bodies)
    k = 0
    if args.prior.warm_start_rounds > 0:
        k, report["physics_check"] = pick_carrying(spec, demo, finalists, args.prior.warm_start_steps,
                                                   args.run.seed, args.env.randomize, say)
    tg = finalists[k]
    if args.prior.warm_start_rounds > 0 and report["physics_check"][k]["fall_rate"] > MAX_FALL_RATE:
        j, slow, rows = slowed_to_carry(spec, demo, finalists, args.prior.warm_start_steps, args.run.seed,
                                        args.env.randomize, say)
        report["physics_check"] += rows
        if slow is not None:
            k, tg, report["slowed_to_mps"] = j, slow, rows[-1]["slowed_to_mps"]
    report["kept_finalist"], report["distance"] = k, report["finalists"][k]["distance"]
    if args.prior.warm_start_rounds > 0:
        tg = gait_for_travel(spec, demo, tg, report, args.prior.warm_start_steps, args.run.seed,
                             args.env.randomize, say)
    run_dir.mkdir(parents=True, exist_ok=True)
    sheet = save_fit_sheet(silhouettes(demo.frames), fitted[k], run_dir / "prior_fit.png", fps=demo.fps,
                           title=f"video | fit: {tg.frequency:.2f} Hz, duty {tg.duty:.2f}")
    (run_dir / "prior_fit.json").write_text(json.dumps({"tg": tg.to_dict(), **report}, indent=2) + "\n")
    return tg, f"{describe(tg, report)}; video | fit: {sheet}"


def drawn_as(run_dir: Path, robot: str) -> str | None:
    """The robot whose body the agent's frames are drawn on: the body the gait prior's fit found
    in the demonstration video (``prior_fit.json``) when that is another robot than ``robot``,
    so that the distance model compares motions rather than bodies; None otherwise (no fit:
    ``--no-tg`` or ``--prior-from reference``)."""
    fit = run_dir / "prior_fit.json"
    if not fit.exists():
        return None
    body = json.loads(fit.read_text()).get("body")
    return body if body and body != robot else None

