"""Train a quadruped to move like one demonstration video (VIRL, Algorithm 1 on rsl-rl PPO).

    python -m virl_quad.train --robot pupper                 # built-in trot demonstration, VIRL reward
    python -m virl_quad.train --robot pupper --demo walk.mp4 # any video
    python -m virl_quad.train --resume runs/pupper-virl-...   # continue a stopped run

Writes into the run folder: ``checkpoint.pt`` (atomic, every --save-every
iterations, on Ctrl-C and at the end), ``demo.npz`` (the demonstration),
``tensorboard/``, and at the end ``report.json`` and ``side_by_side.mp4``.
Export the result with ``python -m virl_quad.export RUN_DIR --out policies/NAME.pt``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from virl_quad.cli import UserError, dataclass_from_args, options, parser_from_dataclass, replace_options, run_main
from virl_quad.training import setup
from virl_quad.training.config import FRAMELESS_REWARDS, TrainArgs, from_dict, prior_pull, rsl_rl_config, to_dict, validate


def _explicit_options(parser: argparse.ArgumentParser, argv: list[str]) -> set[str]:
    """Names of the options the user actually typed (to override a resumed run's config)."""
    probe = argparse.ArgumentParser(add_help=False)
    for action in parser._actions:
        if action.option_strings and action.dest != "help":
            kind = ({"action": action.__class__} if isinstance(action, argparse.BooleanOptionalAction)
                    else {"action": "store_true"} if action.nargs == 0 else {"nargs": action.nargs})
            probe.add_argument(*action.option_strings, dest=action.dest, default=argparse.SUPPRESS, **kind)
    return set(vars(probe.parse_known_args(argv)[0]))


#: Options added after runs were made, with the value that reproduces those runs on resume. Saved
#: options that no longer exist (retired features) are dropped on resume.
LEGACY: dict[str, object] = {"tg": False, "oracle_speed_weight": 0.0, "video_speed_weight": 0.0}


def _resolve(args: TrainArgs, explicit: set[str]) -> tuple[TrainArgs, Path, dict | None]:
    """Apply --resume (saved config + explicitly typed options) and pick the run folder."""
    from virl_quad.training import checkpoint

    if args.run.resume:
        run_dir = Path(args.run.resume)
        if not run_dir.is_dir():
            raise UserError(f"resume folder {run_dir} does not exist")
        data = checkpoint.load(run_dir)
        checkpoint.contract_of(data, data["config"]["robot"])   # ValueError when it cannot continue
        saved = from_dict({**LEGACY, **data["config"]})
        typed = options(args)
        args = replace_options(saved, **{k: typed[k] for k in explicit if k not in ("resume", "run_dir")},
                               resume=str(run_dir), run_dir=str(run_dir))
        return args, run_dir, data
    run_dir = Path(args.run.run_dir or f"runs/{args.run.robot}-{args.run.reward}-{time.strftime('%Y%m%d-%H%M%S')}")
    if (run_dir / checkpoint.LATEST).exists():
        raise UserError(f"{run_dir} already holds a run: use --resume {run_dir} or another --run-dir")
    return args, run_dir, None


def build(args: TrainArgs, run_dir: Path, resume_data: dict | None):
    """Demonstration, VecEnv, reward source, evaluator and runner for these options."""
    from virl_quad import robots
    from virl_quad.envs.vec_env import QuadrupedVecEnv
    from virl_quad.training.rewards import EnvReward, LearnedReward, SurvivalReward
    from virl_quad.training.runner import VirlRunner

    demo = setup.load_demo(args, run_dir)
    oracle = args.run.reward == "oracle"
    if oracle and demo.motion is None:
        raise UserError("--reward oracle needs a demonstration with a reference motion (a gait or motion file)")
    it0 = int(resume_data["iteration"]) if resume_data else 0
    workers = (os.cpu_count() or 1) if args.env.num_workers < 0 else args.env.num_workers
    action_options = setup.action_options(args, demo, resume_data, run_dir)
    env = QuadrupedVecEnv(robots.get(args.run.robot), args.env.num_envs, num_workers=min(workers, args.env.num_envs),
                          workers_kind=args.env.workers, ray_address=args.env.ray_address or None,
                          actor_prefix=f"{run_dir.name}-{os.getpid()}-",
                          seed=args.run.seed + 7919 * it0, device=args.run.device, demo=demo,
                          randomize=args.env.randomize, episode_seconds=args.env.episode_seconds,
                          oracle_reward=oracle, oracle_speed_weight=args.run.oracle_speed_weight,
                          ground=args.env.ground,
                          render=args.run.reward not in FRAMELESS_REWARDS,   # oracle, prior: no frames needed
                          draw_as=setup.drawn_as(run_dir, args.run.robot),
                          **action_options)
    if oracle:
        source = EnvReward()
    elif args.run.reward == "prior":
        source = SurvivalReward()
    else:
        dist = args.distance
        source = LearnedReward(args.run.reward, demo.frames, args.env.num_envs, dist.reward_updates, args.run.seed,
                               args.run.device, lr=dist.reward_lr, cyclic=demo.loop, w_d=dist.reward_wd,
                               other_clips=setup.other_clips(args, run_dir), adversarial_weight=dist.adversarial_weight,
                               fps=demo.fps, video_speed_weight=dist.video_speed_weight)

    actions = env.contract.env_overrides()        # the run's own action facts (TG included)
    runner = VirlRunner(env, rsl_rl_config(args), source, run_dir, to_dict(args),
                        evaluate=(lambda policy: _evaluate(args, demo, policy, actions))
                        if demo.motion is not None else None,   # a video alone: no ground truth to score
                        device=args.run.device)
    if not args.run.device.startswith("cuda"):
        runner.alg.learn_threads = os.cpu_count() or 1   # every core while the env workers wait
    return demo, env, runner


def main(args: TrainArgs, explicit: set[str] = frozenset()) -> int:
    """Train (or resume), then write report.json, the exported policy and the side-by-side video."""
    t_start = time.time()                          # --minutes counts from here: prior fit and warm start included
    validate(args)                                 # the typed options, before torch and the simulator load
    args, run_dir, data = _resolve(args, explicit)
    if data is not None:
        validate(args)                             # a resumed run: its saved options with the typed ones
    reanchor = data is not None and "prior_pull" in explicit
    if reanchor and prior_pull(args) > 0 and (data.get("anchor") or {}).get("weights") is None:
        raise UserError(f"--prior-pull {prior_pull(args):g}: {run_dir} keeps no warm start to pull towards "
                        "(it was trained with --prior-pull 0 or without a warm start)")
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        raise UserError("multi-GPU training (torchrun, WORLD_SIZE > 1) is not supported: each rank would learn "
                        "its own distance model; run one process per GPU (docs/cluster.md)")
    if args.env.workers == "ray":
        from virl_quad.envs.ray_workers import check_address

        check_address(args.env.ray_address)           # at once, not after the prior fit
    import torch

    if args.run.device.startswith("cuda") and not torch.cuda.is_available():
        raise UserError("--device cuda asked for, but torch sees no CUDA device")
    torch.manual_seed(args.run.seed)
    np.random.seed(args.run.seed)
    if not args.run.device.startswith("cuda"):
        # One thread: the env workers own the other cores, and an oversubscribed torch is 10x slower.
        torch.set_num_threads(1)
    demo, env, runner = build(args, run_dir, data)
    from virl_quad.envs.workers import EnvWorkerLost   # loaded by build with the envs
    from virl_quad.training import checkpoint
    from virl_quad.training.report import RunLog

    log = RunLog(run_dir / "train.log")
    log(f"virl_quad.train: robot={args.run.robot} demo={args.run.demo} reward={args.run.reward} "
        f"envs={args.env.num_envs} run_dir={run_dir}")
    (run_dir / "config.json").write_text(json.dumps(to_dict(args), indent=2) + "\n")
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` checkpoints like Ctrl-C
    try:
        if data is not None:
            runner.restore(data)
            log(f"resumed at iteration {runner.current_learning_iteration} ({runner.env_steps:,d} env steps); "
                f"--iterations {args.run.iterations} is the total, so at most "
                f"{max(args.run.iterations - runner.current_learning_iteration, 0)} more")
            if reanchor:
                _reanchor(args, runner, log)
            if getattr(runner.reward_source, "speed", None) is not None and \
                    data.get("speed_term", "sum") != checkpoint.SPEED_TERM_FORM:
                log(f"note: this run was trained with the video speed term added to the distance reward; "
                    f"it continues with the term as a {checkpoint.SPEED_TERM_FORM} (the current form)")
        log(f"demonstration: {demo.source or args.run.demo}, {demo.num_frames} frames at {demo.fps:.1f} fps"
            f"{', with reference motion' if demo.motion is not None else ''}")
        if getattr(runner.reward_source, "speed_note", ""):
            log(runner.reward_source.speed_note)
        if env.cfg.get("draw_as"):
            log(f"the video shows a {env.cfg['draw_as']}: the agent's frames are drawn on its body, so the "
                f"distance model compares motions rather than bodies")
        if not runner.standing and demo.motion is not None:
            from virl_quad.evaluate import zero_policy

            runner.standing = _evaluate(args, demo, zero_policy)
            log(f"holding the default pose scores {runner.standing['total']:.3f} (the bar: 1.00x standing), "
                f"speed {runner.standing['speed_ratio']:.2f}, falls {runner.standing['falls']}")
        _attach_alignment_probe(args, demo, runner, log)
        if data is None:
            _warm_start(args, demo, runner, log)
        left = max(args.run.minutes - (time.time() - t_start) / 60.0, 1e-6) if args.run.minutes else 0.0   # min
        runner.train(args.run.iterations, left, args.run.save_every, args.eval.eval_every, log=log)
    except EnvWorkerLost as e:
        raise UserError(f"{e}; checkpoint written at iteration {runner.current_learning_iteration}: continue "
                        f"with --resume {run_dir}") from None
    finally:
        env.close()
    finish(args, run_dir, demo, runner, log)
    return 0


def _reanchor(args: TrainArgs, runner, log) -> None:
    """A resume with --prior-pull typed: the saved warm start stays the anchor, the pull is the new one."""
    pull = prior_pull(args)
    was = runner.alg.prior_pull
    runner.alg.anchor_actor(pull, runner.alg.anchor)
    log(f"anchor to the warm start: pull {pull:g} per PPO update (the checkpoint's: {was:g})")


def _attach_alignment_probe(args: TrainArgs, demo, runner, log) -> None:
    """With a learned reward and a reference motion: record the alignment probe's graded
    rollouts and measure the untrained reward on them (``--alignment-probe``)."""
    model = getattr(runner.reward_source, "model", None)
    if not args.eval.alignment_probe or model is None or demo.motion is None:
        return
    from virl_quad.training.alignment import AlignmentProbe

    t0 = time.time()
    gait = Path(str(args.run.demo)).stem.removeprefix("gait:")
    source = runner.reward_source
    speed = (source.speed_weight, source.speed) if source.speed is not None else None
    runner.alignment_probe = AlignmentProbe(args.run.robot, demo, gait, randomize=args.env.randomize,
                                            ground=args.env.ground, speed=speed)
    first = runner.alignment_probe.probe(model)
    log(f"alignment probe: {len(runner.alignment_probe.rollouts)} graded rollouts ({time.time() - t0:.0f} s); "
        f"the reward's rank correlation with the score now {first['reward_alignment']:+.2f}"
        + (f" (the distance model's alone {first['distance_alignment']:+.2f})" if "distance_alignment" in first else ""))


def _pretrain_distance(args: TrainArgs, runner, log) -> None:
    """A new run with a learned reward: the distance model's first updates (``--reward-pretrain``),
    on the demonstration's own pairs, the other clips and one rollout of the warm-started
    policy, before the policy learns from its reward."""
    model = getattr(runner.reward_source, "model", None)
    if model is None or args.distance.reward_pretrain == 0:
        return
    t0 = time.time()
    runner.pretrain_reward(args.distance.reward_pretrain)
    runner.wall_time += time.time() - t0
    note = ""
    if runner.alignment_probe is not None:
        note = f"; the reward's rank correlation with the score now {runner.alignment_probe.probe(model)['reward_alignment']:+.2f}"
    log(f"distance model: {args.distance.reward_pretrain} updates on the demonstration, the other clips and one "
        f"rollout of the policy before the policy trains ({time.time() - t0:.0f} s){note}")


def _warm_start(args: TrainArgs, demo, runner, log) -> None:
    """A new run: copy the trajectory generator's tracker into the actor (``--tg``), pretrain the
    distance model on its rollout, evaluate it (the curve's first point), and fit the critic
    alone for the first iterations."""
    from virl_quad import robots
    from virl_quad.training.warm_start import distill_into

    tg = runner.env.contract.tg
    if tg is not None and demo.motion is not None:
        from virl_quad.training.runner import eval_summary

        prior = _evaluate(args, demo, lambda obs: np.zeros(14), runner.env.contract.env_overrides())
        log(f"the gait prior alone (zero residual, no modulation): "
            f"{eval_summary(prior, runner.standing).rsplit(' @', 1)[0]}")
    if tg is not None and args.prior.warm_start_rounds > 0:
        t0 = time.time()
        student = distill_into(runner.alg.actor, robots.get(args.run.robot), demo, tg, args.ppo.hidden, args.run.seed,
                               args.prior.warm_start_rounds, args.prior.warm_start_steps, args.env.randomize, log)
        runner.wall_time += time.time() - t0
        runner.alg.fix_actor_normalizer()
        runner.alg.anchor_actor(prior_pull(args))
        log(f"warm start: {time.time() - t0:.0f} s; the student alone fell in {student['falls']} of "
            f"{student['episodes']} episodes, mean travel {student['travel_m']:+.2f} m")
    _pretrain_distance(args, runner, log)
    if tg is not None and args.prior.warm_start_rounds > 0 and demo.motion is not None:
        from virl_quad.training.runner import eval_summary

        runner.run_evaluation()
        log(f"warm-started policy: {eval_summary(runner.last_eval, runner.standing)}")
    if args.ppo.critic_warmup > 0:
        runner.alg.freeze_actor(args.ppo.critic_warmup)
        log(f"the first {args.ppo.critic_warmup} iterations fit the critic alone (actor frozen)")


def _evaluate(args: TrainArgs, demo, policy, actions: dict | None = None) -> dict:
    """The run's ground-truth evaluation of ``policy`` (obs dict -> action); ``actions``: the env
    options of its action space (the run's contract; None: the defaults, 12 offsets from the
    default pose)."""
    from virl_quad.evaluation.rollout import evaluate

    return evaluate(policy, args.run.robot, demo, episodes=args.eval.eval_episodes, seed=100_000,
                    episode_seconds=args.eval.eval_seconds, randomize=args.env.randomize, ground=args.env.ground,
                    **(actions or {}))


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def finish(args: TrainArgs, run_dir: Path, demo, runner, log=print) -> None:
    """Final evaluation, report.json, the exported policy (policy.pt) and the side-by-side video."""
    from virl_quad.training.report import alignment_curve, side_by_side_video, write_report
    from virl_quad.training.runner import actor_policy, eval_summary

    policy = actor_policy(runner.alg.get_policy().eval())
    actions = runner.env.contract.env_overrides()          # the run's own action facts (TG included)
    if demo.motion is None:
        log("the demonstration is a video alone: no reference motion, so no ground-truth evaluation")
        final = {}
    else:
        log("final evaluation ...")
        final = _evaluate(args, demo, policy, actions)
    report = {"config": to_dict(args), "iterations": runner.current_learning_iteration,
              "env_steps": runner.env_steps, "wall_time_s": runner.wall_time, "evaluation": final,
              "standing": runner.standing}
    model = getattr(runner.reward_source, "model", None)
    if runner.alignment_probe is not None and model is not None:
        report["reward_alignment"] = {**runner.alignment_probe.probe(model),
                                      "curve": alignment_curve(run_dir / "evaluations.jsonl")}
    write_report(run_dir / "report.json", report)
    if final:
        summary = eval_summary({**final, "episodes_run": len(final.get("episodes", [])),
                                "iteration": runner.current_learning_iteration}, runner.standing)
        log(f"report: {run_dir / 'report.json'} ({summary}; survival {final.get('survival_fraction', float('nan')):.2f})")
    else:
        log(f"report: {run_dir / 'report.json'}")
    from virl_quad.export import export

    log(f"policy: {export(run_dir, run_dir / 'policy.pt')} (TorchScript with its contract; serve it with "
        f"python -m virl_quad.deploy.serve --policy {run_dir / 'policy.pt'})")
    if args.run.video:
        out = side_by_side_video(policy, args.run.robot, demo, run_dir / "side_by_side.mp4", ground=args.env.ground,
                                 **actions)
        log(f"video: {out}")


def cli(argv: list[str] | None = None) -> None:
    """Parse the command line and run :func:`main` with one-line errors (exit code 2)."""
    argv = sys.argv[1:] if argv is None else argv
    parser = parser_from_dataclass(TrainArgs, description=__doc__.split("\n\n")[0], prog="python -m virl_quad.train")
    ns = parser.parse_args(argv)
    run_main(lambda: main(dataclass_from_args(TrainArgs, ns), _explicit_options(parser, argv)))


if __name__ == "__main__":
    cli()
