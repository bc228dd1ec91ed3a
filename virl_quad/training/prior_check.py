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
