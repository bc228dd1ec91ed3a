"""Does a run's learned reward rank the policy's own neighbours as the score does? (run by hand)

    python bench/local_alignment.py RUN_DIR [RUN_DIR ...] [--seeds 3] [--seconds 4]

``bench/reward_alignment.py`` ranks very different controllers (standing, other gaits, the
tracker at several strengths). PPO sees something else: small changes of the current policy.
This bench rolls out the run's exported policy and its neighbours (Gaussian noise of growing
std on its actions, in action units, and its residual scaled towards the trajectory generator
alone), each from the same seeds with randomisation on, and prints for each variant the run's
learned reward (``exp(w_d d^2)`` from frame 10 on, the reward a policy would get) beside the
ground-truth score, then Spearman's rank correlation over all rollouts: near 1, the reward tells
PPO which small step climbs the score; near 0, PPO follows noise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
from scipy.stats import spearmanr

from virl_quad.evaluate import policy_callable
from virl_quad.export import export
from virl_quad.policy_io import load_policy
from virl_quad.training import checkpoint
from virl_quad.training.alignment import Controller, GradedRollout, rollout, rollout_rewards

NOISE = (0.0, 0.05, 0.1, 0.2, 0.3)   # action units (x the action scale: 0.5 rad on Pupper)
RESIDUAL = (0.5, 0.0)                # the policy's action scaled by this (0: the TG alone)


def variants(act) -> dict[str, Controller]:
    """name -> (env, rng, obs) -> action: the policy and its neighbours."""
    def noisy(sigma: float) -> Controller:
        def fn(env, rng: np.random.Generator, obs: dict) -> np.ndarray:
            x = np.asarray(act(obs))
            return x + rng.normal(0.0, sigma, x.shape)
        return fn

    out = {f"policy + noise {s:g}": noisy(s) for s in NOISE}
    out.update({f"policy x {b:g}": (lambda env, rng, obs, b=b: b * np.asarray(act(obs))) for b in RESIDUAL})
    return out


def record(run_dir: Path, seeds: int, seconds: float) -> tuple[list[GradedRollout], object]:
    """The variants' rollouts (frames and scores) and the run's reward model."""
    rm, demo, _, robot = checkpoint.load_reward_model(run_dir)
    policy = load_policy(export(run_dir, run_dir / "policy.pt"))
    ground = (demo.camera or {}).get("ground") or "checker"
    out = []
    for name, fn in variants(policy_callable(policy)).items():
        for seed in range(seeds):
            agent, expert, score = rollout(robot, demo, fn, seed, seconds, True, ground,
                                           **policy.contract.env_overrides())
            out.append(GradedRollout(name, seed, agent, expert, score))
    return out, rm


def main() -> int:
    """Print each run's table and rank correlation."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dirs", type=Path, nargs="+", help="training run folders (a learned reward)")
    p.add_argument("--seeds", type=int, default=3, help="rollouts per variant")
    p.add_argument("--seconds", type=float, default=4.0, help="s per rollout")
    a = p.parse_args()
    torch.set_num_threads(1)
    for run in a.run_dirs:
        try:
            rollouts, rm = record(run, a.seeds, a.seconds)
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        rewards = rollout_rewards(rm, rollouts)
        scores = [r.score for r in rollouts]
        rho = float(spearmanr(rewards, scores).statistic) if np.ptp(rewards) > 0 else 0.0
        print(f"{run} ({rm.cfg.variant}): {a.seeds} rollouts of {a.seconds:g} s per variant, randomised")
        print(f"  {'variant':<24}{'reward':>10}{'score':>8}")
        for name in dict.fromkeys(r.controller for r in rollouts):
            idx = [i for i, r in enumerate(rollouts) if r.controller == name]
            print(f"  {name:<24}{np.mean([rewards[i] for i in idx]):10.4f}{np.mean([scores[i] for i in idx]):8.3f}")
        print(f"  rank correlation reward vs score over {len(rollouts)} rollouts: {rho:+.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
