"""Throughput of the whole training loop and the share of each phase (run by hand).

    python bench/train_throughput.py [--robot pupper] [--reward virl] [--iterations 5] [--repeats 3]

Prints env steps/s of Algorithm 1 (rollout + distance-model updates + reward
recomputation + PPO update), each phase's share of the iteration, and the
ratio to the bare VecEnv throughput (same envs and workers, zero actions, no
learning), for the physics and rendering of before the implicit PD and the numpy
ground (:data:`BEFORE`) and for today's defaults, in the same run, alternating (``--repeats``), and the ratio of the two loops. The warm start
(minutes before the first iteration) is left out.
"""

from __future__ import annotations

import argparse
import functools
import statistics
import tempfile
import time
from pathlib import Path

import torch

from virl_quad.envs import vec_env as vec_env_mod
from virl_quad.envs.vec_env import QuadrupedVecEnv
from virl_quad.train import build
from virl_quad.training.config import TrainArgs


#: the env of the training loop before the implicit PD and the numpy ground: explicit torque PD
#: (Pupper at 1 kHz), TinyRenderer drawing the ground; its learning ran on one torch thread
BEFORE = {"pupper": {"pd": "explicit", "sim_dt": 0.001, "substeps": 20, "ground_renderer": "tiny"},
          "laikago": {"pd": "explicit", "ground_renderer": "tiny"}}


def bare_vec_env_rate(args: TrainArgs, demo, workers: int, steps: int, physics: dict) -> float:
    """Env steps/s of the VecEnv alone (zero actions), same configuration as training."""
    env = QuadrupedVecEnv(args.robot, args.num_envs, num_workers=workers, seed=1, demo=demo,
                          randomize=args.randomize, **physics)
    a = torch.zeros(args.num_envs, env.num_actions)
    env.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    rate = args.num_envs * steps / (time.perf_counter() - t)
    env.close()
    return rate


def measure(args: TrainArgs, iterations: int, physics: dict, one_thread: bool = False
            ) -> tuple[float, float, dict[str, float]]:
    """(training-loop env steps/s, bare VecEnv env steps/s, seconds per iteration of each phase)
    with the envs built with the ``physics`` overrides (``{}``: the defaults); ``one_thread``:
    the distance model and PPO learn on one torch thread, as before (default: every core)."""
    vec_env_mod.QuadrupedVecEnv = functools.partial(QuadrupedVecEnv, **physics)   # what build() constructs
    try:
        with tempfile.TemporaryDirectory() as tmp:
            demo, env, runner = build(args, Path(tmp), None)
    finally:
        vec_env_mod.QuadrupedVecEnv = QuadrupedVecEnv
    if one_thread:
        runner.alg.learn_threads = None
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
    rate = iterations * args.num_envs * args.steps_per_env / total
    bare = bare_vec_env_rate(args, demo, args.num_workers, args.steps_per_env * 2, physics)
    return rate, bare, {k: v / iterations for k, v in phases.items()}


def main(robot: str, reward: str, iterations: int, num_envs: int, steps_per_env: int, workers: int,
         repeats: int) -> None:
    """Measure the loop with the physics of before and with today's defaults, in one run, the two
    alternating ``repeats`` times (this machine's speed drifts between minutes); print."""
    torch.set_num_threads(1)
    args = TrainArgs(robot=robot, reward=reward, num_envs=num_envs, steps_per_env=steps_per_env,
                     num_workers=workers, warm_start_rounds=0)
    print(f"{robot}, reward {reward}: {num_envs} envs x {steps_per_env} steps, {workers} worker(s), "
          f"{iterations} iterations per configuration, {repeats} repeat(s)")
    rates: dict[str, list[float]] = {"before": [], "now": []}
    for r in range(repeats):
        for name, physics in (("before", BEFORE.get(robot, {})), ("now", {})):
            rate, bare, phases = measure(args, iterations, physics, one_thread=name == "before")
            rates[name].append(rate)
            print(f"[{r + 1}/{repeats}] {name} ({physics or 'defaults'}"
                  f"{', learning on one torch thread' if name == 'before' else ''}):")
            print(f"  training loop       : {rate:8.1f} env steps/s")
            print(f"  bare VecEnv         : {bare:8.1f} env steps/s   (loop / bare {rate / bare:.2f})")
            total = sum(phases.values())
            for phase, sec in phases.items():
                print(f"  {phase:22s}: {sec:6.2f} s/iteration  {100 * sec / total:5.1f} %")
        print(f"[{r + 1}/{repeats}] training loop now / before: {rates['now'][-1] / rates['before'][-1]:.2f}")
    ratios = [n / b for n, b in zip(rates["now"], rates["before"])]
    print(f"training loop now / before: median {statistics.median(ratios):.2f} "
          f"(each repeat: {', '.join(f'{x:.2f}' for x in ratios)})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="pupper")
    parser.add_argument("--reward", default="virl")
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--steps-per-env", type=int, default=64)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3, help="before/now pairs, alternating")
    a = parser.parse_args()
    main(a.robot, a.reward, a.iterations, a.num_envs, a.steps_per_env, a.workers, a.repeats)
