"""Does a run's learned reward rank physical rollouts as the ground-truth score does? (run by hand)

    python bench/reward_alignment.py RUN_DIR [--seconds 4] [--seeds 2] [--no-randomize]
    python bench/reward_alignment.py --fresh [--variant virl] [--adversarial-weight 1] [--updates 600]

Rollouts of the simulated robot (physics, the training environment) from controllers of
graded quality, all built on the privileged tracker of ``virl_quad.evaluation.tracker``:
the tracker itself, its actions scaled towards the default pose (``alpha``), with
action noise, half a cycle late, tracking another built-in gait, plus standing still
and random actions. For each rollout: the run's learned reward exp(w_d d^2) between
the agent's frames and the demonstration's (the reward a policy would get, frames
10.. of each episode) and the ground-truth score ``total`` the reward never sees.

Prints one row per controller (means over seeds), sorted by score, and Spearman's rank
correlation between reward and score over all rollouts: near 1, following the reward
climbs the score; near 0, the reward gives a policy nothing to climb. A fast check of
a reward design, without a training run.

``--fresh``: instead of a run's model, a new one (``--variant``, ``--adversarial-weight``
as in training, ``--set NAME=VALUE`` for any other distance-model setting) is trained here for
``--updates`` batches on the built-in demonstration, the other built-in gaits as multi-task
clips, and, as agent data, rollouts of the same controllers from other seeds (a diverse
stand-in for a policy's rollouts) or, with ``--agent-policy``, of an exported policy (the
narrow data a training run's distance model sees, arriving over the first half of the
updates); the alignment is then measured on the usual seeds, every ``--probe-every`` updates
with that option (the curve a training run would log, in minutes instead of a run):

    python bench/reward_alignment.py --fresh --agent-policy policies/pupper_trot.pt \
        --adversarial-weight 0.1 --updates 800 --probe-every 100 [--seed 1] \
        [--set latent_norm=false --set view_zoom=0 --set view_shift=0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from virl_quad import demo as demo_lib
from virl_quad.cli import options
from virl_quad.reward.config import RewardConfig
from virl_quad.sim.params import DEFAULT_GROUND, GROUNDS
from virl_quad.reward.reward import build_reward
from virl_quad.training import checkpoint
from virl_quad.training.alignment import alignment, controllers, record, rollout, table

def _settings(pairs: list[str]) -> dict:
    """``NAME=VALUE`` strings -> {name: value} (int, float, true/false or text)."""
    out = {}
    for item in pairs:
        name, _, text = item.partition("=")
        value: object = {"true": True, "false": False}.get(text.lower(), text)
        for conv in (int, float):
            try:
                value = conv(text)
                break
            except ValueError:
                pass
        out[name] = value
    defaults = options(RewardConfig())
    for name, value in out.items():      # a setting keeps its type (a bool stays a bool)
        if name in defaults and isinstance(defaults[name], bool) and not isinstance(value, bool):
            raise ValueError(f"--set {name}: true or false, got {value!r}")
    return out


def _agent_data(a: argparse.Namespace, robot: str, demo, gait: str) -> list:
    """(agent frames, expert frames) episodes: the controllers' (other seeds) or a policy's."""
    if a.agent_policy is None:
        return [rollout(robot, demo, act, seed, a.episode_seconds, not a.no_randomize, a.ground)[:2]
                for act in controllers(robot, float(demo.motion.duration), gait).values()
                for seed in range(1000, 1000 + a.train_seeds)]
    from virl_quad.policy_io import load_policy

    policy = load_policy(a.agent_policy)
    act = lambda env, rng, obs: policy.act(obs["policy"])          # noqa: E731
    return [rollout(robot, demo, act, seed, a.episode_seconds, not a.no_randomize, a.ground,
                    **policy.contract.env_overrides())[:2] for seed in range(1000, 1000 + a.agent_episodes)]


def fresh_model(a: argparse.Namespace, probe=None):
    """A distance model trained here (see the module doc); (model, demo, robot). ``probe(model,
    updates)`` is called every ``--probe-every`` updates when given."""
    from virl_quad.motion.gaits import GAIT_NAMES

    robot, gait = a.robot, a.demo
    demo = demo_lib.load(gait, robot, ground=a.ground)
    clips = [demo_lib.load(g, robot, ground=a.ground).frames for g in GAIT_NAMES if g != gait]
    weights = {} if a.adversarial_weight == 1.0 else {"expert_vs_agent": a.adversarial_weight}
    cfg = RewardConfig.make(**{"variant": a.variant, "clips_cyclic": demo.loop, "pair_weights": weights,
                               **_settings(a.set)})
    rm = build_reward(cfg, demo.frames, clips, a.seed, "cpu")
    episodes = _agent_data(a, robot, demo, gait)
    print(f"training a fresh {a.variant} model on the {a.ground} ground: {a.updates} updates, adversarial "
          f"weight {a.adversarial_weight:g}, {len(episodes)} agent episodes", file=sys.stderr, flush=True)
    step = a.probe_every or 100
    added = 0
    for k in range(0, a.updates, step):
        if a.agent_policy is None:
            want = len(episodes)                                  # the controllers' data all at once
        else:                                                     # a run's data arrives as it trains
            want = min(len(episodes), 1 + (k * len(episodes)) // max(1, a.updates // 2))
        for agent, expert in episodes[added:want]:
            rm.add_episode(agent, expert)
        added = max(added, want)
        info = rm.update(min(step, a.updates - k))
        print(f"  update {min(k + step, a.updates):5d}: loss {info.get('total', float('nan')):.4f}",
              file=sys.stderr, flush=True)
        if probe is not None and a.probe_every:
            probe(rm, min(k + step, a.updates))
    return rm, demo, robot


def main() -> int:
    """Print the table and the rank correlation."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", type=Path, nargs="?", help="training run folder (holds checkpoint.pt and demo.npz)")
    p.add_argument("--seconds", type=float, default=4.0, help="s per rollout")
    p.add_argument("--seeds", type=int, default=2, help="rollouts per controller (seeded start phases)")
    p.add_argument("--no-randomize", action="store_true", help="domain randomisation off")
    p.add_argument("--fresh", action="store_true", help="train a new model here instead of loading a run's")
    p.add_argument("--robot", default="pupper", help="--fresh: robot")
    p.add_argument("--demo", default="trot", help="--fresh: built-in gait to imitate")
    p.add_argument("--variant", default="virl", help="--fresh: reward variant (virl, frame, sequence, no_ae)")
    p.add_argument("--adversarial-weight", type=float, default=1.0, help="--fresh: expert-vs-agent pair weight")
    p.add_argument("--ground", choices=GROUNDS, help="ground of the renders (default: the run's demonstration's, "
                   "else checker; give it for a run whose demonstration does not record it)")
    p.add_argument("--updates", type=int, default=600, help="--fresh: batch updates")
    p.add_argument("--train-seeds", type=int, default=3, help="--fresh: training rollouts per controller")
    p.add_argument("--episode-seconds", type=float, default=6.0, help="--fresh: s per training rollout")
    p.add_argument("--agent-policy", type=Path, help="--fresh: agent data from this exported policy's rollouts")
    p.add_argument("--agent-episodes", type=int, default=16, help="--fresh --agent-policy: training rollouts")
    p.add_argument("--probe-every", type=int, default=0, help="--fresh: rank correlation every N updates (0: at the end)")
    p.add_argument("--seed", type=int, default=0, help="--fresh: the model's seed")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="--fresh: a distance-model setting (RewardConfig field), repeatable")
    a = p.parse_args()
    torch.set_num_threads(1)
    if a.fresh:
        a.ground = a.ground or DEFAULT_GROUND
        fixed = None
        if a.probe_every:
            fixed = record(a.robot, demo_lib.load(a.demo, a.robot, ground=a.ground), a.demo, tuple(range(a.seeds)),
                           a.seconds, not a.no_randomize, a.ground)

        def probe(model, updates: int) -> None:
            rho, rewards = alignment(model, fixed)
            by = {name: r for name, r, _ in table(fixed, rewards)}
            print(f"after {updates:5d} updates: rank correlation {rho:+.2f}, reward of the tracker "
                  f"{by['tracker, alpha 1']:.3f}, of standing still {by['standing still']:.3f}", flush=True)
        try:
            rm, demo, robot = fresh_model(a, probe if fixed is not None else None)
        except (TypeError, ValueError) as e:
            raise SystemExit(f"error: {e}") from None
    elif a.run_dir is None:
        raise SystemExit("error: give a RUN_DIR or --fresh")
    else:
        try:
            rm, demo, _, robot = checkpoint.load_reward_model(a.run_dir)
        except ValueError as e:
            raise SystemExit(f"error: {e}") from None
        a.ground = a.ground or demo.camera.get("ground") or DEFAULT_GROUND
    if demo.motion is None:
        raise SystemExit("error: the run's demonstration has no reference motion (the score needs one)")
    gait = Path(str(demo.source or a.demo)).stem.removeprefix("gait:")
    rollouts = record(robot, demo, gait, tuple(range(a.seeds)), a.seconds, not a.no_randomize, a.ground)
    rho, rewards = alignment(rm, rollouts)
    what = f"a fresh {a.variant} model (adversarial {a.adversarial_weight:g})" if a.fresh else f"run {a.run_dir}"
    what += f", {a.ground} ground"
    print(f"{what}: {robot}, {demo.source}; {a.seeds} rollouts of {a.seconds:g} s per controller, "
          f"randomisation {'off' if a.no_randomize else 'on'}")
    print(f"{'controller':<32}{'reward':>8}{'score':>8}")
    for name, r, s in table(rollouts, rewards):
        print(f"{name:<32}{r:8.3f}{s:8.3f}")
    print(f"Spearman rank correlation reward vs score over {len(rollouts)} rollouts: {rho:+.2f}  (1: aligned, 0: none)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
