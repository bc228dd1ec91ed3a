"""Environment throughput, measured in one run (run by hand: ``python bench/env_throughput.py``).

For each robot it prints:
- env steps/s of one env with rendering (the full ``step``: PD substeps, state, 48x48 frame),
- the raw PyBullet bound for the same robot and substeps (a bare loop of torque commands +
  stepSimulation, no state readout, no rendering) and the ratio env / raw (goal >= 0.6),
- the VecEnv speed-up from 1 to 2 worker processes (goal >= 1.7x on 2 idle cores).

``--workers ray`` measures instead, for each robot, the VecEnv with 2 Ray actors on a local
Ray cluster of 2 CPUs against 2 local worker processes, alternating in one run (goal >= 0.9x),
and Ray's overhead per vector step (ms). Needs ``pip install -e ".[cluster]"``.
Figures depend on what else the machine is doing: run it on an idle machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pybullet
import torch

from virl_quad import robots
from virl_quad.envs import make
from virl_quad.envs.vec_env import QuadrupedVecEnv
from virl_quad.sim.world import World


def env_rate(robot: str, steps: int) -> float:
    """Control steps/s of one env with rendering and domain randomisation."""
    env = make(robot)
    env.reset(seed=0)
    a = np.zeros(12)
    for _ in range(10):
        env.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    rate = steps / (time.perf_counter() - t)
    env.close()
    return rate


def raw_rate(robot: str, steps: int) -> float:
    """Control periods/s of a bare loop: torque command + stepSimulation per substep."""
    spec = robots.get(robot)
    with World(spec) as w:
        w.reset()
        tau = [0.0] * 12
        t = time.perf_counter()
        for _ in range(steps):
            for _ in range(spec.substeps):
                w.bc.setJointMotorControlArray(w.robot, w.joint_ids, pybullet.TORQUE_CONTROL, forces=tau)
                w.bc.stepSimulation()
        return steps / (time.perf_counter() - t)


def vec_rate(robot: str, workers: int, num_envs: int, steps: int, kind: str = "local") -> float:
    """Env steps/s (summed over envs) of the VecEnv with ``workers`` workers of ``kind``."""
    env = QuadrupedVecEnv(robot, num_envs, num_workers=workers, seed=0, workers_kind=kind)
    a = torch.zeros(num_envs, 12)
    for _ in range(5):
        env.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    rate = num_envs * steps / (time.perf_counter() - t)
    env.close()
    return rate


def ray_comparison(robot: str, num_envs: int, steps: int, repeats: int = 3) -> None:
    """2 Ray actors against 2 local processes, alternating ``repeats`` times; prints each pair."""
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
    vec_steps = steps // num_envs * 2
    ratios, local, remote = [], [], []
    for k in range(repeats):
        local.append(vec_rate(robot, 2, num_envs, vec_steps))
        remote.append(vec_rate(robot, 2, num_envs, vec_steps, kind="ray"))
        ratios.append(remote[-1] / local[-1])
        print(f"  {robot}, repeat {k + 1}: 2 local workers {local[-1]:7.1f} env steps/s, 2 Ray actors "
              f"{remote[-1]:7.1f}: {ratios[-1]:.2f}x", flush=True)
    lo, rr = float(np.median(local)), float(np.median(remote))
    overhead_ms = (num_envs / rr - num_envs / lo) * 1e3
    print(f"{robot}: {num_envs} envs, median of {repeats}: Ray / local {float(np.median(ratios)):.2f}x "
          f"(goal >= 0.9x); Ray's overhead {overhead_ms:+.2f} ms per vector step "
          f"({num_envs / lo * 1e3:.2f} ms locally)")


def main(robot_names: list[str], steps: int, num_envs: int) -> None:
    """Measure and print every figure for each robot."""
    torch.set_num_threads(1)
    for name in robot_names:
        spec = robots.get(name)
        env_r = env_rate(name, steps)
        raw_r = raw_rate(name, steps)
        v1 = vec_rate(name, 1, num_envs, steps // num_envs * 2)
        v2 = vec_rate(name, 2, num_envs, steps // num_envs * 2)
        print(f"{name}: {spec.substeps} substeps of {spec.sim_dt * 1e3:.1f} ms per control step")
        print(f"  one env with rendering : {env_r:8.1f} steps/s")
        print(f"  raw PyBullet bound     : {raw_r:8.1f} steps/s")
        print(f"  ratio env / raw        : {env_r / raw_r:8.2f}   (goal >= 0.6)")
        print(f"  VecEnv {num_envs} envs, 1 worker : {v1:8.1f} steps/s")
        print(f"  VecEnv {num_envs} envs, 2 workers: {v2:8.1f} steps/s")
        print(f"  speed-up 1 -> 2 workers: {v2 / v1:8.2f}x  (goal >= 1.7x)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="all", choices=["all", *robots.names()])
    parser.add_argument("--steps", type=int, default=400, help="control steps per measurement")
    parser.add_argument("--num-envs", type=int, default=8, help="envs in the VecEnv measurement")
    parser.add_argument("--workers", default="local", choices=["local", "ray"],
                        help="ray: 2 Ray actors against 2 local worker processes (see above)")
    args = parser.parse_args()
    names = list(robots.names()) if args.robot == "all" else [args.robot]
    if args.workers == "ray":
        torch.set_num_threads(1)
        for name in names:
            ray_comparison(name, args.num_envs, args.steps)
        raise SystemExit(0)
    main(names, args.steps, args.num_envs)
