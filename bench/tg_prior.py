"""The gait prior alone: the fitted trajectory generator played open-loop on the physics robot.

    python bench/tg_prior.py [--robot pupper] [--demos trot,pace,bound] [--episodes 5] [--seconds 10]

For each demonstration: the TG's parameters (``virl_quad.training.prior.tg_for_demo``: fitted
to the reference motion, else the built-in gait of its name) and the fit's RMS foot error,
then the TG with zero residual and no modulation (a policy that outputs 14 zeros) scored
with the ground-truth imitation score (``virl_quad.evaluation.rollout.evaluate``, the figures of
``python -m virl_quad.evaluate``) on the nominal robot and under domain randomisation,
beside holding the default pose: the prior-only baseline a residual policy starts from.
"""

from __future__ import annotations

import argparse

import numpy as np

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.evaluation.rollout import evaluate
from virl_quad.training.prior import tg_for_demo


def run(robot: str, source: str, episodes: int, seconds: float) -> None:
    """Fit, play and print one demonstration's prior-only baseline."""
    spec = robots.get(robot)
    demo = demo_lib.load(source, robot)
    tg, text = tg_for_demo(demo, spec, source)
    print(f"{robot} {source}: {text}")

    def prior(obs: dict) -> np.ndarray:
        return np.zeros(14)

    def stand(obs: dict) -> np.ndarray:
        return np.zeros(12)

    print(f"  {'':28s} {'score':>7s} {'x stand':>8s} {'speed ratio':>12s} {'survival':>9s} {'falls':>6s}")
    for randomize in (False, True):
        kw = dict(episodes=episodes, seed=0, episode_seconds=seconds, randomize=randomize)
        base = evaluate(stand, robot, demo, **kw)
        got = evaluate(prior, robot, demo, tg=tg, **kw)
        label = "randomised" if randomize else "nominal"
        for name, r in ((f"TG alone, {label}", got), (f"default pose, {label}", base)):
            ratio = r["total"] / base["total"] if base["total"] > 0 else float("nan")
            print(f"  {name:28s} {r['total']:7.3f} {ratio:8.2f} {r['speed_ratio']:12.2f} "
                  f"{r['survival_fraction']:9.2f} {int(r['falls']):6d}")


def main() -> None:
    """Command line entry."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper")
    p.add_argument("--demos", default="trot,pace,bound", help="comma-separated demonstration sources")
    p.add_argument("--episodes", type=int, default=5)
    p.add_argument("--seconds", type=float, default=10.0)
    a = p.parse_args()
    for source in a.demos.split(","):
        run(a.robot, source.strip(), a.episodes, a.seconds)


if __name__ == "__main__":
    main()
