"""Evaluate an exported policy against a demonstration with the ground-truth imitation score.

    python -m virl_quad.evaluate --policy policies/pupper_trot.pt --episodes 10 --json out.json

Prints each score term, the total (aligned and at the best phase offset), the
survival fraction and the forward-speed ratio to the demonstration, beside the
same figures for holding the default pose (the baseline the policy must beat).
Episodes start in the demonstration's states (``--start rsi``, how training scores the gait)
or standing, as a HAL hands the robot over (``--start stand``: can the policy start the gait?).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from virl_quad.cli import UserError, opt, parse, run_main
from virl_quad.robots.spec import RAMP_TIME

if TYPE_CHECKING:                                  # torch loads only once the options are good
    from virl_quad.policy_io import LoadedPolicy


def policy_callable(policy: LoadedPolicy):
    """``obs dict -> action`` for the env, from a loaded TorchScript policy."""
    def act(obs: dict) -> np.ndarray:
        return policy.act(obs["policy"])
    return act


def zero_policy(obs: dict) -> np.ndarray:
    """Hold the default pose (the baseline; 12 actions: an env without a trajectory generator)."""
    return np.zeros(12)


#: how an evaluation episode starts (``--start``): the env's ``stand_start``
STARTS = {"rsi": False, "stand": True}


@dataclass
class EvaluateArgs:
    """Options of ``python -m virl_quad.evaluate``."""

    policy: str = opt("", "exported policy (.pt with its .json beside it)", required=True)
    demo: str = opt("", "demonstration (empty: the one the policy learned from)")
    episodes: int = opt(10, "episodes (seeded from --seed)")
    seconds: float = opt(10.0, "s per episode")
    seed: int = opt(0, "first episode seed")
    no_randomize: bool = opt(False, "evaluate without domain randomisation")
    start: str = opt("rsi", "how episodes start: rsi (in the demonstration's states, at random phases: the "
                            "gait itself) or stand (as a HAL hands the robot over: standing in the default "
                            f"pose, held {RAMP_TIME:g} s, phase 0: starting the gait, as on hardware)",
                     choices=tuple(STARTS))
    json: str = opt("", "write the figures to this JSON file")
    video: str = opt("", "write a side-by-side video of the first episode (.mp4)")


def main(argv: list[str] | None = None) -> int:
    """Command line entry."""
    args = parse(EvaluateArgs, argv, __doc__.split("\n\n")[0], "python -m virl_quad.evaluate")
    if args.episodes < 1 or args.seconds <= 0:
        raise UserError("--episodes must be >= 1 and --seconds > 0")
    from virl_quad import demo as demo_lib
    from virl_quad.evaluation.rollout import evaluate
    from virl_quad.policy_io import load_policy

    policy = load_policy(args.policy)
    robot = policy.spec.name
    source = args.demo or policy.meta.get("demo", {}).get("source") or "trot"
    demo = demo_lib.load(source, robot)
    if demo.motion is None:
        raise UserError(f"demonstration {source!r} has no reference motion: the ground-truth score needs one")
    # the policy's own action mapping (its metadata's contract: scale, clip, rate limit, TG),
    # whatever the robot spec's default is now
    actions = policy.contract.env_overrides()
    kwargs = dict(episodes=args.episodes, seed=args.seed, episode_seconds=args.seconds,
                  randomize=not args.no_randomize, stand_start=STARTS[args.start], **actions)
    result = evaluate(policy_callable(policy), robot, demo, **kwargs)
    baseline = evaluate(zero_policy, robot, demo, **{**kwargs, "tg": None})   # the default pose, not a TG
    keys = [k for k, v in result.items() if isinstance(v, (int, float))]
    print(f"{'figure':28s} {'policy':>10s} {'default pose':>13s}")
    for k in keys:
        print(f"{k:28s} {result[k]:10.3f} {baseline.get(k, float('nan')):13.3f}")
    if baseline.get("total", 0) > 0:
        print(f"{'score ratio to default pose':28s} {result['total'] / baseline['total']:10.2f}")
    if args.json:
        tg = policy.contract.tg
        Path(args.json).write_text(json.dumps({"policy": args.policy, "demo": source, **kwargs,
                                               "tg": None if tg is None else tg.to_dict(),
                                               "result": result, "default_pose": baseline}, indent=2, default=float))
    if args.video:
        from virl_quad.training.report import side_by_side_video

        print(f"video: {side_by_side_video(policy_callable(policy), robot, demo, args.video, **actions)}")
    return 0


if __name__ == "__main__":
    run_main(main)
