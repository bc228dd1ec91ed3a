"""What each part of the learner buys, at equal budget (run by hand; one CPU-heavy job at a time).

    python bench/learning_curves.py [--robot pupper] [--demo trot] [--reward oracle] [--minutes 10]

Arms (each a ``python -m virl_quad.train`` subprocess with the same wall-clock budget, seed and
evaluation; ground-truth score as a multiple of holding the default pose):
- ``scratch``: the learner before the gait prior (joint offsets from the default pose, action
  std 0.5, learning rate 1e-3, no warm start, no critic warm-up);
- ``prior``: the trajectory generator alone (a residual policy that outputs zeros), evaluated once;
- ``warm start``: the warm-started actor before any PPO update (the first evaluation of the
  ``residual`` run, at the wall time its warm start took);
- ``residual``: the training defaults (TG, warm start, critic warm-up, residual PPO).
Writes one PNG (score against env steps and against wall time) and prints the table.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

SCRATCH = ["--no-tg", "--init-std", "0.5", "--learning-rate", "1e-3", "--warm-start-rounds", "0",
           "--critic-warmup", "0"]


def train(run_dir: Path, robot: str, demo: str, reward: str, minutes: float, eval_every: int,
          extra: list[str]) -> list[dict]:
    """Run one arm; its evaluations (``evaluations.jsonl``) and the final report's."""
    cmd = [sys.executable, "-m", "virl_quad.train", "--robot", robot, "--demo", demo, "--reward", reward,
           "--minutes", str(minutes), "--eval-every", str(eval_every), "--run-dir", str(run_dir), "--no-video",
           *extra]
    print("$", " ".join(cmd[1:]), flush=True)
    subprocess.run(cmd, check=True)
    curve = [json.loads(line) for line in (run_dir / "evaluations.jsonl").read_text().splitlines()]
    report = json.loads((run_dir / "report.json").read_text())
    final = report["evaluation"]
    curve.append({"iteration": report["iterations"], "env_steps": report["env_steps"],
                  "wall_time_s": report["wall_time_s"], "total": final["total"],
                  "speed_ratio": final["speed_ratio"], "falls": final["falls"],
                  "survival_fraction": final["survival_fraction"]})
    return curve


def prior_only(robot: str, demo_name: str, episodes: int) -> dict:
    """The TG with zero residual, evaluated as training evaluates."""
    from virl_quad import demo as demo_lib
    from virl_quad import robots
    from virl_quad.evaluation.rollout import evaluate
    from virl_quad.training.prior import tg_for_demo

    demo = demo_lib.load(demo_name, robot)
    tg, _ = tg_for_demo(demo, robots.get(robot), demo_name)
    return evaluate(lambda obs: np.zeros(14), robot, demo, episodes=episodes, seed=100_000, tg=tg)


def main() -> None:
    """Run the arms, print the table, write the PNG."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper")
    p.add_argument("--demo", default="trot")
    p.add_argument("--reward", default="oracle", help="training reward of the two learning arms")
    p.add_argument("--minutes", type=float, default=10.0, help="wall-clock budget of each learning arm")
    p.add_argument("--eval-every", type=int, default=20, help="iterations between evaluations")
    p.add_argument("--out", default="learning_curves.png", help="PNG to write")
    p.add_argument("--runs-dir", default="", help="keep the arms' run folders here (default: a temporary folder)")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(a.runs_dir or tmp)
        runs = {name: train(where / name, a.robot, a.demo, a.reward, a.minutes, a.eval_every, extra)
                for name, extra in (("scratch", SCRATCH), ("residual", []))}
        standing = json.loads((where / "residual" / "report.json").read_text())["standing"]["total"]
    prior = prior_only(a.robot, a.demo, 2)
    warm = runs["residual"][0]
    rows = [("scratch", runs["scratch"][-1]), ("prior", {**prior, "env_steps": 0, "wall_time_s": 0.0}),
            ("warm start", warm), ("residual", runs["residual"][-1])]
    print(f"\n{a.robot} {a.demo}, reward {a.reward}, {a.minutes:g} min per learning arm; "
          f"holding the default pose scores {standing:.3f}")
    print(f"{'arm':12s} {'env steps':>10s} {'wall s':>7s} {'score':>6s} {'x stand':>8s} {'speed':>6s} {'falls':>6s}")
    for name, r in rows:
        print(f"{name:12s} {int(r['env_steps']):10,d} {r['wall_time_s']:7.0f} {r['total']:6.3f} "
              f"{r['total'] / standing:8.2f} {r['speed_ratio']:6.2f} {int(r['falls']):6d}")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, key, label in ((axes[0], "env_steps", "env steps"), (axes[1], "wall_time_s", "wall time (s)")):
        for name in ("scratch", "residual"):
            c = runs[name]
            ax.plot([e[key] for e in c], [e["total"] / standing for e in c], marker="o", label=name)
        ax.axhline(prior["total"] / standing, color="gray", ls="--", label="prior only")
        ax.axhline(1.0, color="black", lw=0.8, label="standing")
        ax.plot([warm[key]], [warm["total"] / standing], "k*", ms=12, label="warm start")
        ax.set_xlabel(label)
    axes[0].set_ylabel("ground-truth score / standing")
    axes[1].legend(loc="lower right")
    fig.suptitle(f"{a.robot} {a.demo}, reward {a.reward}, {a.minutes:g} min per learning arm")
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
