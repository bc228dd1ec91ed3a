"""Does the fitted gait prior carry the robot? Its warm-start teacher, tried on the physics robot.

The video fit (:mod:`virl_quad.training.video_prior`) ranks candidate trajectory generators
(TGs) by how their kinematic renders look; nothing in a render says whether the robot can
walk the gait. Its nearest finalists often look alike to within a gray level, yet differ in
whether the warm start's teacher (the tracker of the TG, :mod:`virl_quad.training.warm_start`)
keeps the robot up: a duty factor or swing height that reads the same from the side can
tip a Pupper over on every other step. A teacher that falls in most of its episodes leaves
DAgger a student that falls as often, and PPO a policy that does.

:func:`pick_carrying` runs the teacher exactly as the warm start's first round gathers
(:func:`virl_quad.distill.gather`: observed joint angles, action noise, the run's domain
randomisation) on each finalist, nearest first, and keeps the first whose teacher falls in
at most :data:`MAX_FALL_RATE` of its episodes; when none does, the one that falls least,
with a warning.

:func:`gait_for_travel` then checks which way the kept finalist's teacher travels. A side view
at 48 px fixes the phase pattern, period and step well, but not what makes a Pupper's pace go
forwards on the physics robot: its hind feet's fore-aft place and how high the feet clear the
ground while the body rocks. When the teacher travels against the way the video's ground slides
(:func:`virl_quad.reward.egomotion.clip_speed`), the :data:`GAIT_VARIANTS` are tried and the one
whose teacher goes furthest the video's way, falling in at most half its episodes (or no more
than the kept gait's own teacher), is kept. The contact sheet shows the fitted gait before it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from virl_quad.policy.tg import TGParams
from virl_quad.robots.spec import RobotSpec

#: Largest share of its episodes in which a finalist's teacher may fall. The built-in trot's
#: teacher falls in about a third and DAgger still makes a student that does not fall; the
#: pace's nearest finalist fell in two thirds, and so did its student (docs/experiments.md).
MAX_FALL_RATE = 0.5


def teacher_trial(spec: RobotSpec, demo, tg: TGParams, steps: int, seed: int, randomize: bool) -> dict:
    """The warm-start teacher of ``tg`` for ``steps`` control steps: ``{"episodes", "falls",
    "fall_rate", "travel_m"}`` (mean forward travel per episode, m)."""
    from virl_quad.distill import DistillArgs, gather, gathering_envs
    from virl_quad.training.warm_start import TGMotion

    args = DistillArgs(robot=spec.name, rounds=1, steps=steps, seed=seed, quiet=True, randomize=randomize,
                       gain=spec.tracker_gain, lead=spec.tracker_lead, noise=spec.tracker_noise)
    pair = gathering_envs(args, demo, {"tg": tg})
    try:
        _, _, stats = gather(pair, None, 1.0, steps, np.random.default_rng(seed), args, 0, TGMotion(spec, tg))
    finally:
        for env in pair:
            env.close()
    episodes, falls = int(stats["episodes"]), int(stats["falls"])
    return {"episodes": episodes, "falls": falls, "fall_rate": falls / max(episodes, 1),
            "travel_m": float(stats["travel_m"])}


def pick_carrying(spec: RobotSpec, demo, finalists: list[TGParams], steps: int, seed: int, randomize: bool,
                  log: Callable[[str], None] = print) -> tuple[int, list[dict]]:
    """The index of the nearest finalist (``finalists``: nearest first) whose teacher falls in at
    most :data:`MAX_FALL_RATE` of its episodes, else of the one that falls least; and one row of
    :func:`teacher_trial` figures (plus ``finalist``, its index) per finalist tried."""
    if not finalists:
        raise ValueError("no finalists to check")
    rows = []
    for k, tg in enumerate(finalists):
        row = {"finalist": k, **teacher_trial(spec, demo, tg, steps, seed, randomize)}
        rows.append(row)
        log(f"  physics check, finalist {k} (duty {tg.duty:.2f}, step {tg.step_length * 100:.1f} cm, swing "
            f"{tg.swing_height * 100:.1f} cm): its tracker fell in {row['falls']} of {row['episodes']} episodes, "
            f"mean travel {row['travel_m']:+.2f} m")
        if row["fall_rate"] <= MAX_FALL_RATE:
            return k, rows
    best = min(rows, key=lambda r: (r["fall_rate"], r["finalist"]))
    log(f"warning: every finalist's tracker fell in more than {MAX_FALL_RATE:.0%} of its episodes: this prior "
        f"cannot carry {spec.name}; going on with finalist {best['finalist']}, which falls least")
    return best["finalist"], rows


#: Variants tried when the kept finalist's teacher travels against the video's direction:
#: (m the hind feet move towards the tail, factor on the swing height). The pace fitted to the
#: built-in video (swing 1.5 cm) drifts backwards; with its hind feet 2 cm back and 3 cm of swing
#: its teacher walks forwards (docs/experiments.md).
GAIT_VARIANTS = ((0.01, 1.0), (0.02, 1.0), (0.0, 2.0), (0.01, 2.0), (0.02, 2.0))


def with_variant(spec: RobotSpec, tg: TGParams, hind_back: float, swing_scale: float) -> TGParams:
    """``tg`` with its hind neutral feet ``hind_back`` m towards the tail and its swing height
    times ``swing_scale`` (ValueError when a foot then leaves the leg's reach)."""
    from virl_quad.policy.tg import TrajectoryGenerator

    xy = TrajectoryGenerator(spec, tg).neutral_xy.copy()
    xy[2:, 0] -= hind_back                                 # legs FR, FL, RR, RL: the last two are hind
    moved = TGParams.from_dict({**tg.to_dict(), "neutral_xy": xy.tolist(),
                                "swing_height": tg.swing_height * swing_scale})
    TrajectoryGenerator(spec, moved)                       # reach and joint limits checked
    return moved


def pick_variant(spec: RobotSpec, demo, tg: TGParams, trial: dict, direction: float, steps: int, seed: int,
                 randomize: bool, log: Callable[[str], None] = print) -> tuple[TGParams, list[dict]]:
    """When ``tg``'s teacher (its :func:`teacher_trial` figures: ``trial``) travels against
    ``direction`` (+1: the video's subject goes forwards, -1: backwards), try the
    :data:`GAIT_VARIANTS` and keep the one that travels furthest in ``direction`` among those whose
    teacher falls in at most ``max(MAX_FALL_RATE, trial's fall rate)`` of its episodes (none:
    ``tg``). Returns the kept TG and one row per variant tried."""
    if trial["travel_m"] * direction >= 0:
        return tg, []
    log("  the kept gait's tracker travels against the video's ground slide: trying gait variants")
    allowed = max(MAX_FALL_RATE, trial.get("fall_rate", 0.0))
    best, best_travel, best_row, rows = tg, trial["travel_m"] * direction, None, []
    for hind_back, swing_scale in GAIT_VARIANTS:
        try:
            moved = with_variant(spec, tg, hind_back, swing_scale)
        except ValueError:
            continue
        row = {"hind_back_m": hind_back, "swing_scale": swing_scale,
               **teacher_trial(spec, demo, moved, steps, seed, randomize)}
        rows.append(row)
        log(f"  hind feet {hind_back * 100:.1f} cm back, swing x{swing_scale:g}: its tracker fell in {row['falls']} "
            f"of {row['episodes']} episodes, mean travel {row['travel_m']:+.2f} m")
        if row["fall_rate"] <= allowed and row["travel_m"] * direction > best_travel:
            best, best_travel, best_row = moved, row["travel_m"] * direction, row
    for r in rows:
        r["kept"] = r is best_row
    return best, rows


def gait_for_travel(spec: RobotSpec, demo, tg: TGParams, report: dict, steps: int, seed: int,
                    randomize: bool, log: Callable[[str], None] = print) -> TGParams:
    """The video fit's kept TG (``report``: the fit's report, with its ``physics_check`` rows and
    ``kept_finalist``), changed by :func:`pick_variant` when its teacher travels against the
    ground's slide in the demonstration (a video with no patterned ground: unchanged). Adds
    ``travel_check`` (rows) and ``variant`` (the kept one, or None) to ``report``."""
    from virl_quad.reward.egomotion import clip_speed

    slide = clip_speed(demo.frames, demo.fps)           # px per window: < 0 where the subject goes forwards
    trial = next((r for r in report.get("physics_check", []) if r["finalist"] == report["kept_finalist"]), None)
    report["variant"] = None
    if slide is None or trial is None:
        return tg
    moved, report["travel_check"] = pick_variant(spec, demo, tg, trial, -float(np.sign(slide)), steps, seed,
                                                 randomize, log)
    kept = next((r for r in report["travel_check"] if r.get("kept")), None)
    if kept is not None:
        report["variant"] = {"hind_back_m": kept["hind_back_m"], "swing_scale": kept["swing_scale"]}
    return moved
