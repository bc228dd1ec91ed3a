"""Does the fitted gait prior carry the robot? Its warm-start teacher, tried on the physics robot.

The video fit (:mod:`virl_quad.training.video_prior`) ranks candidate trajectory generators
(TGs) by how their kinematic renders look; nothing in a render says whether the robot can
walk the gait. Its nearest finalists often look alike to within a gray level, yet differ in
whether the warm start's teacher (the tracker of the TG, :mod:`virl_quad.training.warm_start`)
keeps the robot up: a duty factor or swing height that reads the same from the side can
tip a Pupper over on every other step. A teacher that falls in most of its episodes leaves
DAgger a student that falls as often, and PPO a policy that does.

:func:`pick_carrying` runs the teacher exactly as the warm start's first round gathers
(:func:`virl_quad.training.dagger.gather`: observed joint angles, action noise, the run's domain
randomisation) on each finalist, nearest first, and keeps the first whose teacher falls in
at most :data:`MAX_FALL_RATE` of its episodes; when none does, the one that falls least,
with a warning.

When none does and the video's gait is faster than the robot's built-in trot,
:func:`slowed_to_carry` tries the finalists again at that trot's speed.

:func:`gait_for_travel` then checks how fast, and which way, the kept finalist's teacher travels.
A side view at 48 px fixes the phase pattern, period and step well, but not what makes a gait
carry a Pupper forwards on the physics robot: its hind feet's fore-aft place, how wide apart
the feet stand, how high they clear the ground while the body rocks, and how long a step the
legs can push through. When the teacher travels against the way the video's ground slides
(:func:`virl_quad.reward.egomotion.clip_speed`), or at under :data:`MIN_SPEED_SHARE` of the
gait's own speed (step length x frequency / duty), the :data:`GAIT_VARIANTS` are tried and the
one whose teacher goes furthest the video's way is kept: among those that fall in at most
:data:`STEADY_FALL_RATE` of their episodes when any of them goes further than the kept gait,
else among those that fall in at most half (or no more than the kept gait's own teacher); a
crouch only when it goes clearly further than the furthest upright variant (:data:`UPRIGHT_SHARE`).
The contact sheet shows the fitted gait before it.
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
    "fall_rate", "travel_m", "speed_mps"}`` (mean forward travel per episode, m; forward travel
    over the time run, m/s)."""
    from virl_quad.distill import DistillArgs
    from virl_quad.training.dagger import gather, gathering_envs
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
    travel = float(stats["travel_m"])
    return {"episodes": episodes, "falls": falls, "fall_rate": falls / max(episodes, 1), "travel_m": travel,
            "speed_mps": travel * episodes * spec.control_hz / max(steps, 1)}


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


def at_speed(tg: TGParams, speed: float) -> TGParams:
    """``tg`` with its step length (m) set so that :func:`nominal_speed` is ``speed`` (m/s)."""
    return TGParams.from_dict({**tg.to_dict(), "step_length": speed * tg.duty / tg.frequency})


def slowed_to_carry(spec: RobotSpec, demo, finalists: list[TGParams], steps: int, seed: int, randomize: bool,
                    log: Callable[[str], None] = print) -> tuple[int, TGParams | None, list[dict]]:
    """When no finalist's teacher carries the robot: the nearest finalist faster than the robot's
    built-in trot that carries it at that trot's speed (its step shortened; frequency, phase
    pattern, duty and swing kept), as ``(index, TG, rows)``; ``(-1, None, rows)`` when none does.
    A video may show a gait faster than a TG carries the learner at (a dog's flying trot for a
    Pupper): its timing and pattern are what the robot can still take from it."""
    from virl_quad.training.video_prior import template

    speed = nominal_speed(template(spec))                                      # m/s
    rows = []
    for k, tg in enumerate(finalists):
        if nominal_speed(tg) <= speed * 1.01:
            continue
        slow = at_speed(tg, speed)
        row = {"finalist": k, "slowed_to_mps": speed, **teacher_trial(spec, demo, slow, steps, seed, randomize)}
        rows.append(row)
        log(f"  physics check, finalist {k} slowed to {speed:.2f} m/s (step {slow.step_length * 100:.1f} cm): its "
            f"tracker fell in {row['falls']} of {row['episodes']} episodes, mean travel {row['travel_m']:+.2f} m")
        if row["fall_rate"] <= MAX_FALL_RATE:
            return k, slow, rows
    return -1, None, rows


#: Share of its TG's own speed (step length x frequency / duty) under which a teacher's gait is
#: changed. The built-in videos' trots carry the robot at about half their TG's speed, and their
#: policies reach the speed bars; the fitted bound at a fifth, the pace backwards (docs/experiments.md).
MIN_SPEED_SHARE = 1.0 / 3.0

#: Share of its episodes under which a variant's teacher counts as steady. A teacher's falls pass
#: to its student and on to the policy: a pace teacher that falls in a third of its episodes, on
#: grippy ground (friction above about 1), makes policies that fall there as often
#: (docs/experiments.md).
STEADY_FALL_RATE = 1.0 / 8.0

#: Share of a crouched variant's travel that a variant at the fitted stance height must reach to
#: be kept before it. A crouch changes the silhouette the video shows and the pose the score
#: compares, so it is worth only a clearly longer walk; the share lies between what the dog
#: video's upright variants reach (they keep its crouch) and what the trot's do (docs/experiments.md).
UPRIGHT_SHARE = 0.75

#: Variants tried when the kept finalist's teacher is too slow or goes the wrong way: (m the hind
#: feet move towards the tail, factor on the swing height, factor on the step length, factor on the
#: stance height, m every foot moves outwards[, added to the duty factor]). The pace fitted to the
#: built-in video (swing 1.5 cm) drifts backwards, and walks forwards with its hind feet 2 cm back
#: and 3 cm of swing; the fitted bound (step 5 cm, swing 3 cm) goes twice as far with a 7.5 cm step,
#: 1.5-2 cm of swing and its hind feet 2-3 cm back. A crouch (stance x0.8: 0.11 m on Pupper) keeps
#: the dog video's trot walking on grippy ground, where at the full stance its loaded hind feet drag
#: through their swing; crouched, it carries a longer step (x1.2), which at the full stance falls;
#: with its feet also 4 cm wider apart it rolls less and carries a step x1.5 (docs/experiments.md).
#: The pace with its hind feet 3 cm back, a step x1.65 and a longer stance (duty +0.15) stays up on
#: grippy ground, where with its swing halved instead it rolls over.
GAIT_VARIANTS = ((0.01, 1.0, 1.0, 1.0, 0.0), (0.02, 1.0, 1.0, 1.0, 0.0), (0.0, 2.0, 1.0, 1.0, 0.0),
                 (0.01, 2.0, 1.0, 1.0, 0.0), (0.02, 2.0, 1.0, 1.0, 0.0), (0.02, 0.67, 1.5, 1.0, 0.0),
                 (0.03, 0.5, 1.5, 1.0, 0.0), (0.0, 1.0, 1.0, 0.8, 0.0), (0.01, 1.0, 1.0, 0.8, 0.0),
                 (0.01, 2.0, 1.0, 0.8, 0.0), (0.02, 2.0, 1.0, 0.8, 0.0), (0.02, 2.0, 1.2, 0.8, 0.0),
                 (0.02, 2.0, 1.5, 0.8, 0.04), (0.03, 1.0, 1.65, 1.0, 0.0, 0.15))
#: The names of a variant's entries, as the travel check's rows and the fit's report keep them,
#: and the value of each that a variant leaves as fitted.
VARIANT_KEYS = ("hind_back_m", "swing_scale", "step_scale", "stance_scale", "widen_m", "duty_shift")
VARIANT_NEUTRAL = (0.0, 1.0, 1.0, 1.0, 0.0, 0.0)


def with_variant(spec: RobotSpec, tg: TGParams, hind_back: float, swing_scale: float,
                 step_scale: float = 1.0, stance_scale: float = 1.0, widen: float = 0.0,
                 duty_shift: float = 0.0) -> TGParams:
    """``tg`` with its hind neutral feet ``hind_back`` m towards the tail, its swing height times
    ``swing_scale``, its step length times ``step_scale``, its stance height (feet below the
    hips, m) times ``stance_scale``, every neutral foot ``widen`` m further out sideways and
    ``duty_shift`` added to its duty factor (ValueError when a foot then leaves the leg's reach
    or joint limits, or the duty factor leaves the TG's range)."""
    from virl_quad.policy.tg import TrajectoryGenerator

    xy = TrajectoryGenerator(spec, tg).neutral_xy.copy()
    xy[2:, 0] -= hind_back                                 # legs FR, FL, RR, RL: the last two are hind
    xy[:, 1] += widen * np.sign(xy[:, 1])                  # m, away from the body's midline
    moved = TGParams.from_dict({**tg.to_dict(), "neutral_xy": xy.tolist(),
                                "swing_height": tg.swing_height * swing_scale,
                                "step_length": tg.step_length * step_scale,
                                "stance_height": tg.stance_height * stance_scale,
                                "duty": tg.duty + duty_shift})
    TrajectoryGenerator(spec, moved)                       # reach and joint limits checked
    return moved


def describe_variant(variant: dict) -> str:
    """One phrase for a :data:`GAIT_VARIANTS` entry as a report row names it (``hind_back_m``,
    ``swing_scale``, ``step_scale``, ``stance_scale``, ``widen_m``, ``duty_shift``; a missing
    stance factor is 1, a missing widening or duty shift 0)."""
    stance, widen = variant.get("stance_scale", 1.0), variant.get("widen_m", 0.0)
    duty = variant.get("duty_shift", 0.0)
    return (f"hind feet {variant['hind_back_m'] * 100:.1f} cm back, swing x{variant['swing_scale']:g}, step "
            f"x{variant['step_scale']:g}" + (f", stance x{stance:g}" if stance != 1.0 else "")
            + (f", feet {widen * 100:.1f} cm wider" if widen else "") + (f", duty {duty:+.2f}" if duty else ""))


def nominal_speed(tg: TGParams) -> float:
    """The body speed (m/s) at which ``tg``'s stance feet move backwards: step length x frequency / duty."""
    return tg.step_length * tg.frequency / tg.duty


def pick_variant(spec: RobotSpec, demo, tg: TGParams, trial: dict, direction: float, steps: int, seed: int,
                 randomize: bool, log: Callable[[str], None] = print) -> tuple[TGParams, list[dict]]:
    """When ``tg``'s teacher (its :func:`teacher_trial` figures: ``trial``) travels against
    ``direction`` (+1: the video's subject goes forwards, -1: backwards) or at under
    :data:`MIN_SPEED_SHARE` of :func:`nominal_speed`, try the :data:`GAIT_VARIANTS` and keep the
    one that travels furthest in ``direction``, further than ``tg``'s teacher, among those whose
    teacher falls in at most :data:`STEADY_FALL_RATE` of its episodes; when none of those goes
    further, among those that fall in at most ``max(MAX_FALL_RATE, trial's fall rate)`` (none:
    ``tg``). Returns the kept TG and one row per variant tried."""
    speed = trial["speed_mps"] * direction                               # m/s the video's way
    if trial["travel_m"] * direction < 0:
        log("  the kept gait's tracker travels against the video's ground slide: trying gait variants")
    elif speed < MIN_SPEED_SHARE * nominal_speed(tg):
        log(f"  the kept gait's tracker goes {speed:.3f} m/s, under {MIN_SPEED_SHARE:.2f} of its gait's "
            f"{nominal_speed(tg):.3f} m/s: trying gait variants")
    else:
        return tg, []
    tried = []                                                           # (TG, row) per variant
    for variant in GAIT_VARIANTS:
        try:
            moved = with_variant(spec, tg, *variant)
        except ValueError:
            continue
        entries = variant + VARIANT_NEUTRAL[len(variant):]
        row = {**dict(zip(VARIANT_KEYS, entries)), **teacher_trial(spec, demo, moved, steps, seed, randomize)}
        tried.append((moved, row))
        log(f"  {describe_variant(row)}: its tracker fell in {row['falls']} of {row['episodes']} episodes, "
            f"mean travel {row['travel_m']:+.2f} m")
    rows = [row for _, row in tried]
    loose = max(MAX_FALL_RATE, trial.get("fall_rate", 0.0))
    k = choose_variant(rows, trial["travel_m"] * direction, direction, loose)
    for i, r in enumerate(rows):
        r["kept"] = i == k
    return (tg if k is None else tried[k][0]), rows


def choose_variant(rows: list[dict], own_travel: float, direction: float, max_fall_rate: float) -> int | None:
    """The index of the row (:func:`teacher_trial` figures) whose teacher travels furthest in
    ``direction`` and further than ``own_travel`` (m, the kept gait's own teacher, already signed
    that way), among those falling in at most :data:`STEADY_FALL_RATE` of their episodes; when none
    of those goes further, among those falling in at most ``max_fall_rate``; None when none does.
    A crouch that goes furthest gives way to the furthest variant at the fitted stance height
    when that one goes at least :data:`UPRIGHT_SHARE` as far."""
    def walk(i: int) -> float:
        return rows[i]["travel_m"] * direction                           # m, the video's way

    for allowed in (STEADY_FALL_RATE, max_fall_rate):
        further = [i for i, r in enumerate(rows) if r["fall_rate"] <= allowed and walk(i) > own_travel]
        if further:
            best = max(further, key=walk)
            tall = max((i for i in further if rows[i].get("stance_scale", 1.0) == 1.0), key=walk, default=best)
            return tall if walk(tall) >= UPRIGHT_SHARE * walk(best) else best
    return None


def gait_for_travel(spec: RobotSpec, demo, tg: TGParams, report: dict, steps: int, seed: int,
                    randomize: bool, log: Callable[[str], None] = print) -> TGParams:
    """The video fit's kept TG (``report``: the fit's report, with its ``physics_check`` rows and
    ``kept_finalist``), changed by :func:`pick_variant` when its teacher travels against the
    ground's slide in the demonstration, or too slowly (a video with no patterned ground:
    unchanged). Adds
    ``travel_check`` (rows) and ``variant`` (the kept one, or None) to ``report``."""
    from virl_quad.reward.egomotion import clip_speed, search_reach

    slide = clip_speed(demo.frames, demo.fps, reach=search_reach(demo.frames))   # px per window: < 0 forwards
    trial = next((r for r in reversed(report.get("physics_check", []))       # a slowed finalist's row is last
                  if r["finalist"] == report["kept_finalist"]), None)
    report["variant"] = None
    if slide is None or trial is None:
        return tg
    moved, report["travel_check"] = pick_variant(spec, demo, tg, trial, -float(np.sign(slide)), steps, seed,
                                                 randomize, log)
    kept = next((r for r in report["travel_check"] if r.get("kept")), None)
    if kept is not None:
        report["variant"] = {k: kept[k] for k in VARIANT_KEYS}
    return moved
