"""What does a trained distance model measure: the motion, or nuisances of the picture? (run by hand)

    python bench/distance_invariance.py RUN_DIR [--steps 60]

Loads the distance model of a training run (its ``checkpoint.pt``) and prints the mean
distance d and reward exp(w_d d^2) between the run's demonstration and:

- nuisance changes of the SAME motion, rendered here: the robot shifted along x by a
  fraction of a ground-checker square (the follow camera then sees the ground pattern
  at another phase; on the default plain ground these rows measure d ~0 by construction),
  the camera turned or moved back a little;
- a good imitation done with physics: the simulated robot (no randomisation) following the
  reference with ``virl_quad.evaluation.tracker`` (ground-truth score about 0.7, 1.6x standing);
- real motion differences: the robot standing in its default pose (simulated, no
  randomisation) and the run's multi-task clips (other gaits).

A model that measures motion gives the nuisances a far smaller d than the other motions,
and the tracker's trot a far smaller d than standing still: else its reward cannot lead
a policy from standing to trotting.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

from virl_quad import envs, robots
from virl_quad.demo.render import render_demonstration
from virl_quad.evaluation.tracker import tracker_action
from virl_quad.sim.camera import CameraParams
from virl_quad.sim.params import DEFAULT_GROUND
from virl_quad.training import checkpoint

SQUARE = 0.125  # m, side of a ground-checker square (16 per 2 m texture tile, sim/world.py)


def simulated_frames(robot: str, demo, n: int, track: bool) -> tuple[np.ndarray, np.ndarray]:
    """Agent frames of the simulated robot (no randomisation) holding its default pose, or
    following the reference with the privileged tracker, and the expert frames beside them."""
    env = envs.make(robot, demo=demo, randomize=False)
    obs, _ = env.reset(seed=0, options={"demo_step": 0})
    agent, expert = [obs["agent_image"]], [obs["expert_image"]]
    for _ in range(n - 1):
        obs, *_ = env.step(tracker_action(env) if track else np.zeros(12))
        agent.append(obs["agent_image"])
        expert.append(obs["expert_image"])
    env.close()
    return np.array(agent), np.array(expert)


def main() -> None:
    """Print one row per comparison."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", type=Path, help="training run folder (holds checkpoint.pt and demo.npz)")
    p.add_argument("--steps", type=int, default=60, help="frames per sequence (the first 10 are not averaged)")
    a = p.parse_args()
    torch.set_num_threads(1)
    try:
        rm, demo, clips, robot = checkpoint.load_reward_model(a.run_dir)
    except ValueError as e:
        raise SystemExit(f"error: {e}") from None
    if demo.motion is None:
        raise SystemExit("the run's demonstration has no reference motion to re-render")
    n, idx = a.steps, np.arange(a.steps) % demo.num_frames
    expert = demo.frames[idx]

    def row(name: str, agent: np.ndarray, ref: np.ndarray = expert) -> None:
        d = rm.distance(torch.from_numpy(ref[:, None]), torch.from_numpy(agent[:, None]))[10:, 0]
        print(f"{name:<44}{float(d.mean()):8.3f}{float(rm.reward_of(d).mean()):10.4f}")

    def render(motion=None, cam=None) -> np.ndarray:
        return render_demonstration(motion or demo.motion, robot, cam=cam,
                                    ground=demo.camera.get("ground", DEFAULT_GROUND)).frames[idx]

    print(f"run {a.run_dir}: {robot}, {demo.source}, w_d {rm.cfg.reward.w_d:g}; mean over frames 10..{n - 1}")
    print(f"{'demonstration vs':<44}{'d':>8}{'reward':>10}")
    row("itself", expert)
    for frac in (0.25, 0.5, 1.0, 2.0):
        m = demo.motion
        shifted = dataclasses.replace(m, root_pos=m.root_pos + np.array([frac * SQUARE, 0.0, 0.0]))
        row(f"itself, {frac:g} checker square ({frac * SQUARE * 100:.1f} cm) ahead", render(shifted))
    cam = CameraParams.from_spec(robots.get(robot))
    row("itself, camera turned 3 deg", render(cam=cam.jittered(0.0, 0.0, 3.0)))
    row("itself, camera 3 % farther", render(cam=cam.jittered(0.03 * cam.distance, 0.0, 0.0)))
    agent, ref = simulated_frames(robot, demo, n, track=True)
    row("the privileged tracker's trot (simulated)", agent, ref)
    agent, ref = simulated_frames(robot, demo, n, track=False)
    row("the robot standing still (simulated)", agent, ref)
    for k, c in enumerate(clips):
        row(f"multi-task clip {k} (another gait)", c[np.arange(n) % len(c)])


if __name__ == "__main__":
    sys.exit(main())
