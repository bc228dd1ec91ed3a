"""DAgger: copy a tracker of a motion into a proprioceptive policy (``python -m virl_quad.distill``,
the warm start of :mod:`virl_quad.training.warm_start`).

Round 0 runs the tracker; each later round runs the current student, with the
tracker's action executed with probability ``0.5 ** round``, and every visited observation
is labelled with the tracker's action there. After each round the student is refitted on
everything gathered (mean-squared error, the observation normaliser set to the data's mean
and standard deviation). Half the episodes start from the default pose at phase 0 (as a
HAL does), half by reference state initialisation at a random phase (as training does).

Four choices make the student learnable and sturdier (the figures: docs/experiments.md):
- the teacher feeds back the joint angles of the observation (what the student measures),
  not the simulator's true ones, so a label is a function of the observation;
- the student is blind to the last-action input (first-layer weights held at zero): the
  teacher's previous action predicts its next one so well that a student copies it and
  then drifts on its own actions (causal confusion);
- no domain randomisation by default for ``python -m virl_quad.distill``: under the
  observation latency it draws, the observation-fed tracker itself falls and the student's
  error grows round by round;
- Gaussian noise (std 0.1 action units) on every executed action while gathering: the
  student sees states off the teacher's path and falls less under randomisation.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from tensordict import TensorDict

from virl_quad import demo as demo_lib
from virl_quad import envs
from virl_quad.cli import UserError
from virl_quad.distill import DistillArgs
from virl_quad.evaluation.tracker import tracker_action
from virl_quad.policy.observation import policy_block


def _episode_options(k: int) -> dict | None:
    """Even episodes start at phase 0 (with rsi off: the default pose), odd ones at random phases."""
    return {"demo_step": 0} if k % 2 == 0 else None


def gathering_envs(args: DistillArgs, demo, env_options: dict | None = None) -> tuple:
    """The two envs DAgger gathers in (reference-state initialisation off, on; no frames
    rendered), with ``env_options`` (e.g. the run's trajectory generator) passed to ``envs.make``."""
    ranges = {"latency": (0.0, args.max_latency)} if args.randomize and args.max_latency is not None else None
    return tuple(envs.make(args.robot, demo=demo, randomize=args.randomize, randomization=ranges, render=False,
                           rsi=rsi, episode_seconds=10.0, **(env_options or {})) for rsi in (False, True))


def gather(envs_pair: tuple, actor: torch.nn.Module | None, beta: float, steps: int, rng: np.random.Generator,
           args: DistillArgs, first_episode: int, motion=None) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Run ``steps`` control steps, executing the tracker (of ``motion``, default the
    demonstration's reference) with probability ``beta`` (else the student), and return the
    observations, the tracker's (clipped) actions and statistics."""
    obs_out, act_out, travel, falls, episodes = [], [], [], 0, 0
    q_cols = policy_block("joint_pos_minus_default")
    k = first_episode
    while len(obs_out) < steps:
        env = envs_pair[k % 2]
        obs, _ = env.reset(seed=int(rng.integers(2**31)), options=_episode_options(k))
        u = env.unwrapped
        x0, done = float(u.state.base_pos[0]), False
        clip = u.contract.action_clip
        while not done and len(obs_out) < steps:
            q_meas = obs["policy"][q_cols] + u.robot.default_pose     # rad, as the policy measures it
            teacher = np.clip(tracker_action(env, args.gain, args.lead, motion=motion, q=q_meas), -clip, clip)
            obs_out.append(obs["policy"])
            act_out.append(teacher)
            if actor is None or rng.random() < beta:
                action = teacher
            else:
                with torch.inference_mode():
                    batch = TensorDict({"policy": torch.as_tensor(obs["policy"])[None]}, batch_size=[1])
                    action = actor(batch)[0].numpy()
            if args.noise > 0:
                action = action + rng.normal(0.0, args.noise, size=action.shape)
            obs, _, terminated, truncated, _ = env.step(action)
            falls += int(terminated)
            done = terminated or truncated
        travel.append(float(u.state.base_pos[0]) - x0)
        episodes += 1
        k += 1
    return (np.asarray(obs_out, np.float32), np.asarray(act_out, np.float32),
            {"episodes": episodes, "falls": falls, "travel_m": float(np.mean(travel)), "next_episode": k})


def blind_to(actor: torch.nn.Module, block: str, with_phase: bool = True, action_size: int = 12) -> slice:
    """Zero (and keep at zero) the first layer's weights on one observation block (of the layout
    with ``with_phase`` and ``action_size``), so the policy ignores that input; returns the blocked
    input columns."""
    cols = policy_block(block, with_phase, action_size)
    first = next(m for m in actor.mlp.modules() if isinstance(m, torch.nn.Linear))
    with torch.no_grad():
        first.weight[:, cols] = 0.0
    mask = torch.ones_like(first.weight)
    mask[:, cols] = 0.0
    first.weight.register_hook(lambda g: g * mask)
    return cols


def fit(actor: torch.nn.Module, obs: np.ndarray, act: np.ndarray, args: DistillArgs,
        gen: torch.Generator) -> float:
    """Refit ``actor`` on all pairs; returns the last epoch's mean-squared error."""
    x, y = torch.from_numpy(obs), torch.from_numpy(act)
    norm = actor.obs_normalizer
    norm._mean.copy_(x.mean(0, keepdim=True))
    std = x.std(0, keepdim=True)
    norm._var.copy_(std ** 2)
    norm._std.copy_(std)
    norm.count.fill_(len(x))
    opt = torch.optim.Adam(actor.mlp.parameters(), lr=args.lr)
    steps = args.epochs * -(-len(x) // args.batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)   # decays to 0: no last noisy step
    loss_val = float("nan")
    actor.train()
    for _ in range(args.epochs):
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for i in range(0, len(x), args.batch):
            idx = order[i:i + args.batch]
            pred = actor.mlp(norm(x[idx]))
            loss = torch.nn.functional.mse_loss(pred, y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
        loss_val = total / len(x)
    actor.eval()
    return loss_val


def distil(args: DistillArgs, log=print, demo=None, env_options: dict | None = None,
           motion=None) -> tuple[torch.nn.Module, dict]:
    """Run DAgger; returns the student actor (eval mode) and per-round statistics.

    ``demo``: the demonstration (default: loaded from ``args.demo``); ``env_options``: extra
    ``envs.make`` options (e.g. the run's trajectory generator); ``motion``: what the teacher
    tracks (anything with ``state_at(t).q``; default: the demonstration's reference motion)."""
    from virl_quad.export import fresh_actor

    d = demo if demo is not None else demo_lib.load(args.demo, args.robot)
    if d.motion is None and motion is None:
        raise UserError(f"demonstration {args.demo!r} has no reference motion: the tracker needs one")
    hidden = tuple(int(h) for h in args.hidden.split(","))
    rng, gen = np.random.default_rng(args.seed), torch.Generator().manual_seed(args.seed)
    pair = gathering_envs(args, d, env_options)
    contract = pair[0].unwrapped.contract
    actor = fresh_actor(contract, hidden, seed=args.seed)
    if args.blind_last_action:
        # The teacher's previous action predicts its next one almost perfectly, and a student
        # that learns to copy it drifts on its own (causal confusion): it does not get to see it.
        blind_to(actor, "last_action", contract.with_phase, contract.action_size)
    all_obs, all_act, history, k = [], [], [], 0
    try:
        for r in range(args.rounds):
            t0 = time.monotonic()
            beta = 0.5 ** r
            o, a, stats = gather(pair, None if r == 0 else actor, beta, args.steps, rng, args, k, motion)
            k = stats.pop("next_episode")
            all_obs.append(o)
            all_act.append(a)
            loss = fit(actor, np.concatenate(all_obs), np.concatenate(all_act), args, gen)
            stats.update(round=r, beta=beta, pairs=int(sum(len(x) for x in all_obs)), mse=loss,
                         seconds=time.monotonic() - t0)
            history.append(stats)
            log(f"round {r}: beta {beta:.3f}, {stats['episodes']} episodes ({stats['falls']} fell), "
                f"mean travel {stats['travel_m']:+.2f} m, {stats['pairs']} pairs, mse {loss:.4f}, "
                f"{stats['seconds']:.0f} s")
        _, _, final = gather(pair, actor, 0.0, args.steps, rng, args, k, motion)
        final.pop("next_episode")
        log(f"student alone: {final['episodes']} episodes ({final['falls']} fell), "
            f"mean travel {final['travel_m']:+.2f} m")
    finally:
        for e in pair:
            e.close()
    return actor, {"demo": d, "rounds": history, "student": final, "contract": contract}
