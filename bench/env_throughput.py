"""Environment throughput, measured in one run (run by hand: ``python bench/env_throughput.py``).

For each robot it prints:
- env steps/s of one env with rendering (the full ``step``: PD substeps, state, 48x48 frame),
- the raw PyBullet bound for the same robot and substeps (a bare loop of torque commands +
  stepSimulation, no state readout, no rendering) and the ratio env / raw (goal >= 0.6),
- the VecEnv speed-up from 1 to 2 worker processes (goal >= 1.7x on 2 idle cores).
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


def vec_rate(robot: str, workers: int, num_envs: int, steps: int) -> float:
    """Env steps/s (summed over envs) of the VecEnv with ``workers`` processes."""
    env = QuadrupedVecEnv(robot, num_envs, num_workers=workers, seed=0)
    a = torch.zeros(num_envs, 12)
    for _ in range(5):
        env.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    rate = num_envs * steps / (time.perf_counter() - t)
    env.close()
    return rate


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
    args = parser.parse_args()
    main(list(robots.names()) if args.robot == "all" else [args.robot], args.steps, args.num_envs)
