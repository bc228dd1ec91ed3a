"""Throughput of the whole training loop against an earlier revision's, in one run (by hand).

    python bench/train_throughput.py [--against REV] [--repeats 3] [--iterations 10] [--robot pupper]

Env steps/s of Algorithm 1 (rollout + distance-model updates + reward recomputation + PPO
update) with today's defaults, each phase's share of the iteration and the ratio to the bare
VecEnv (same envs and workers, zero actions, no learning); and the same loop of revision
``--against`` (default: the code before the gait prior, the implicit PD, the numpy ground and
the multi-threaded learning phase), measured by that revision's own copy of this bench in a
temporary git worktree. The two alternate ``--repeats`` times, each in a fresh process (this
machine's speed drifts from minute to minute), and the ratio of each pair and their median are
printed. The warm start (minutes before the first iteration) is left out.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from virl_quad.envs.vec_env import QuadrupedVecEnv
from virl_quad.train import build
from virl_quad.training.config import TrainArgs


#: the revision the loop is compared with by default: the code the training-throughput issue was filed on
BASELINE_REV = "712ff41"
_RATE = re.compile(r"training loop\s*:\s*([0-9.]+) env steps/s")


def bare_vec_env_rate(args: TrainArgs, demo, workers: int, steps: int) -> float:
    """Env steps/s of the VecEnv alone (zero actions), same configuration as training."""
    env = QuadrupedVecEnv(args.run.robot, args.env.num_envs, num_workers=workers, seed=1, demo=demo,
                          randomize=args.env.randomize)
    a = torch.zeros(args.env.num_envs, env.num_actions)
    env.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    rate = args.env.num_envs * steps / (time.perf_counter() - t)
    env.close()
    return rate


def measure(args: TrainArgs, iterations: int) -> tuple[float, float, dict[str, float]]:
    """(training-loop env steps/s, bare VecEnv env steps/s, seconds per iteration of each phase)."""
    with tempfile.TemporaryDirectory() as tmp:
        demo, env, runner = build(args, Path(tmp), None)
    phases = {"rollout": 0.0, "distance-model updates": 0.0, "reward recompute": 0.0, "PPO update": 0.0}
    obs = env.get_observations()
    runner.alg.train_mode()
    runner._rollout(obs)  # warm-up iteration (not timed)
    with torch.inference_mode():
        runner.alg.compute_returns(env.get_observations())
    runner.alg.update()
    t_all = time.perf_counter()
    for _ in range(iterations):
        t0 = time.perf_counter()
        obs = runner._rollout(env.get_observations())
        t1 = time.perf_counter()
        with torch.inference_mode():
            runner.alg.compute_returns(obs)
        t2 = time.perf_counter()
        runner.alg.update()
        t3 = time.perf_counter()
        upd = runner.alg.last_reward_info.get("time/distance_update_s", 0.0)
        phases["rollout"] += t1 - t0
        phases["distance-model updates"] += upd
        phases["reward recompute"] += (t2 - t1) - upd
        phases["PPO update"] += t3 - t2
    total = time.perf_counter() - t_all
    env.close()
    rate = iterations * args.env.num_envs * args.ppo.steps_per_env / total
    bare = bare_vec_env_rate(args, demo, args.env.num_workers, args.ppo.steps_per_env * 2)
    return rate, bare, {k: v / iterations for k, v in phases.items()}


def measure_here(a: argparse.Namespace) -> None:
    """Measure this tree's loop with its defaults; print the rate and the phases."""
    torch.set_num_threads(1)
    args = TrainArgs.make(robot=a.robot, reward=a.reward, num_envs=a.num_envs, steps_per_env=a.steps_per_env,
                          num_workers=a.workers, warm_start_rounds=0)
    rate, bare, phases = measure(args, a.iterations)
    print(f"  training loop       : {rate:8.1f} env steps/s")
    print(f"  bare VecEnv         : {bare:8.1f} env steps/s   (loop / bare {rate / bare:.2f})")
    total = sum(phases.values())
    for phase, sec in phases.items():
        print(f"  {phase:22s}: {sec:6.2f} s/iteration  {100 * sec / total:5.1f} %")


def _run(cmd: list[str], cwd: Path, pythonpath: Path) -> float:
    """Run one measurement process; its output's training-loop rate (env steps/s)."""
    env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    found = _RATE.search(p.stdout)
    if p.returncode != 0 or not found:
        raise SystemExit(f"error: measurement failed in {cwd}: {(p.stderr or p.stdout).strip().splitlines()[-1:]}")
    print("\n".join(line for line in p.stdout.splitlines() if line.startswith("  ")), flush=True)
    return float(found.group(1))


def main(a: argparse.Namespace) -> None:
    """Alternate the revision's loop and today's, print each rate, each pair's ratio and the median."""
    here = Path(__file__).resolve().parents[1]
    common = ["--robot", a.robot, "--reward", a.reward, "--iterations", str(a.iterations), "--num-envs",
              str(a.num_envs), "--steps-per-env", str(a.steps_per_env), "--workers", str(a.workers)]
    print(f"{a.robot}, reward {a.reward}: {a.num_envs} envs x {a.steps_per_env} steps, {a.workers} worker(s), "
          f"{a.iterations} iterations per measurement, against {a.against}, {a.repeats} repeat(s)", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "baseline"
        subprocess.run(["git", "-C", str(here), "worktree", "add", "--detach", "-q", str(old), a.against], check=True)
        try:
            ratios = []
            for r in range(a.repeats):
                print(f"[{r + 1}/{a.repeats}] {a.against}:", flush=True)
                before = _run([sys.executable, str(old / "bench" / "train_throughput.py"), *common], old, old)
                print(f"[{r + 1}/{a.repeats}] today's defaults:", flush=True)
                now = _run([sys.executable, str(Path(__file__).resolve()), "--here", *common], here, here)
                ratios.append(now / before)
                print(f"[{r + 1}/{a.repeats}] training loop today / {a.against}: {ratios[-1]:.2f}", flush=True)
        finally:
            subprocess.run(["git", "-C", str(here), "worktree", "remove", "--force", str(old)], check=False)
    print(f"training loop today / {a.against}: median {statistics.median(ratios):.2f} "
          f"(each repeat: {', '.join(f'{x:.2f}' for x in ratios)})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="pupper")
    parser.add_argument("--reward", default="virl")
    parser.add_argument("--iterations", type=int, default=10, help="timed iterations per measurement")
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps-per-env", type=int, default=64)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3, help="revision/today pairs, alternating")
    parser.add_argument("--against", default=BASELINE_REV, help="git revision to compare with")
    parser.add_argument("--here", action="store_true", help="measure this tree once and print (used by the pairs)")
    ns = parser.parse_args()
    measure_here(ns) if ns.here else main(ns)
