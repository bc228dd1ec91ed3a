"""How far and how safely a gait prior's warm-start teacher carries the robot, across TG variants.

    python bench/teacher_sweep.py --demo bound --tg runs/RUN/prior_fit.json [--frequency 1,1.2]
        [--step 1,1.3] [--swing 1,1.5] [--hind-back 0,0.02] [--duty 0.4,0.6] [--stance 1,0.8]
        [--widen 0,0.04] [--seeds 0,1] [--workers 2] [--out sweep.json]

Every combination of the factors (frequency scale, step length scale, swing height scale, hind
feet moved towards the tail, m; duty factor, with the step length scaled alike so that the
stance feet keep their speed; stance height scale; every foot moved outwards, m) applied to the
TG in ``--tg`` (a run's ``prior_fit.json`` or any JSON with a ``tg`` entry; default: the robot's
gait of the demonstration's name), each run as the warm start's first round gathers
(``virl_quad.training.prior_check.teacher_trial``: observed joint angles, gathering noise,
domain randomisation) for ``--steps`` control steps per seed, in a pool of ``--workers``
processes. Prints one row per variant, furthest travel first: falls, episodes, mean forward
travel per episode (m; episodes of up to 10 s) and forward speed over the time run (m/s). The
variants' throughput scales with cores: one process per variant.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v.strip()]


def _trial(job: tuple) -> dict:
    """One variant and seed: its teacher's figures."""
    robot, demo_name, tg_dict, (f, s, w, h, d, z, y), seed, steps = job
    from virl_quad import demo as demo_lib
    from virl_quad import robots
    from virl_quad.policy.tg import TGParams
    from virl_quad.training.prior_check import teacher_trial, with_variant

    spec = robots.get(robot)
    demo = demo_lib.load(demo_name, robot)
    base = TGParams.from_dict(tg_dict)
    duty = d or base.duty
    try:
        tg = replace(base, frequency=base.frequency * f, duty=duty, step_length=base.step_length * s * duty / base.duty)
        tg = with_variant(spec, tg, h, w, 1.0, z, y)
    except ValueError as e:
        return {"variant": [f, s, w, h, d, z, y], "seed": seed, "error": str(e)}
    return {"variant": [f, s, w, h, d, z, y], "seed": seed, **teacher_trial(spec, demo, tg, steps, seed, True)}


def main() -> None:
    """Command line entry."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper")
    p.add_argument("--demo", default="bound", help="built-in gait or motion file the teacher is scored against")
    p.add_argument("--tg", default="", help="JSON with a 'tg' entry (a run's prior_fit.json); default: the gait's TG")
    p.add_argument("--frequency", default="1", help="comma-separated frequency scales")
    p.add_argument("--step", default="1", help="comma-separated step length scales")
    p.add_argument("--swing", default="1", help="comma-separated swing height scales")
    p.add_argument("--hind-back", default="0", help="comma-separated shifts of the hind feet towards the tail (m)")
    p.add_argument("--duty", default="0", help="comma-separated duty factors (0: the TG's own)")
    p.add_argument("--stance", default="1", help="comma-separated stance height scales (feet below the hips)")
    p.add_argument("--widen", default="0", help="comma-separated outward shifts of every foot (m)")
    p.add_argument("--seeds", default="0", help="comma-separated seeds, one trial each")
    p.add_argument("--steps", type=int, default=4000, help="control steps per trial")
    p.add_argument("--workers", type=int, default=2, help="processes")
    p.add_argument("--out", default="", help="write the rows as JSON here")
    a = p.parse_args()

    from virl_quad import demo as demo_lib
    from virl_quad import robots
    from virl_quad.training.prior import tg_for_demo

    spec = robots.get(a.robot)
    demo = demo_lib.load(a.demo, a.robot)
    if a.tg:
        tg_dict = json.load(open(a.tg))["tg"]
    else:
        tg_dict = tg_for_demo(demo, spec, a.demo)[0].to_dict()
    grid = list(itertools.product(_floats(a.frequency), _floats(a.step), _floats(a.swing), _floats(a.hind_back),
                                  _floats(a.duty), _floats(a.stance), _floats(a.widen)))
    jobs = [(a.robot, a.demo, tg_dict, v, seed, a.steps) for v in grid for seed in map(int, _floats(a.seeds))]
    print(f"{len(grid)} variants x {len(jobs) // max(len(grid), 1)} seeds, {a.workers} workers; base TG {tg_dict}",
          flush=True)
    t0 = time.time()
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(_trial, jobs))
    table = {}
    for r in rows:
        if "error" in r:
            continue
        t = table.setdefault(tuple(r["variant"]), {"falls": 0, "episodes": 0, "travel": [], "speed": []})
        t["falls"] += r["falls"]
        t["episodes"] += r["episodes"]
        t["travel"].append(r["travel_m"])
        t["speed"].append(r["speed_mps"])
    print(f"{time.time() - t0:.0f} s")
    print(f"{'freq':>5s} {'step':>5s} {'swing':>5s} {'hind m':>6s} {'duty':>5s} {'stance':>6s} {'wide m':>6s} "
          f"{'falls':>9s} {'travel m':>9s} {'m/s':>6s}")
    for v, t in sorted(table.items(), key=lambda kv: -sum(kv[1]["travel"]) / len(kv[1]["travel"])):
        travel, speed = (sum(t[k]) / len(t[k]) for k in ("travel", "speed"))
        print(f"{v[0]:5.2f} {v[1]:5.2f} {v[2]:5.2f} {v[3]:6.3f} {v[4]:5.2f} {v[5]:6.2f} {v[6]:6.3f} "
              f"{t['falls']:4d}/{t['episodes']:<4d} "
              f"{travel:+9.2f} {speed:6.3f}")
    if a.out:
        with open(a.out, "w") as fh:
            json.dump({"base_tg": tg_dict, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
