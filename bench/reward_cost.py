"""CPU cost of the VIRL reward beside the environment (run by hand: ``python bench/reward_cost.py``).

For ``--num-envs`` envs (default 64) and rollouts of ``--steps`` steps (default 24) it prints:
- ms per streaming reward step (all envs),
- ms per batch recompute of one rollout [steps, envs],
- ms per distance-model update (``batch_pairs`` = 16 pairs = 32 sequences, EESP windows
  with the default window_max 64 and 500-frame episodes),
- ms to store one rollout in the off-policy dataset,
- the env step time from ``bench/env_throughput.py`` (one env with rendering, measured here,
  or ``--env-steps-per-s``), and the share of an iteration spent on reward + updates
  (goal <= 20 %) for M = ``--updates`` model updates per iteration.
Torch threads default to 1: on a 2-core machine the env workers use the cores, and OpenMP
with 2 threads stalls badly whenever another process is busy. Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from virl_quad.reward import RewardConfig, build_reward


def timed(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in ms after one warm-up call."""
    fn()
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1000)
    return statistics.median(out)


def env_step_rate(robot: str, steps: int) -> float | None:
    """Control steps/s of one env with rendering, via bench/env_throughput.py (None when not available)."""
    path = Path(__file__).with_name("env_throughput.py")
    if not path.is_file():
        return None
    try:
        spec = importlib.util.spec_from_file_location("env_throughput", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return float(mod.env_rate(robot, steps))
    except Exception as exc:  # noqa: BLE001 - the hook must not break the reward figures
        print(f"env throughput hook failed: {type(exc).__name__}: {exc}")
        return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--steps", type=int, default=24, help="rollout length (steps per env per iteration)")
    ap.add_argument("--updates", type=int, default=2, help="model updates per iteration (M) for the goal line")
    ap.add_argument("--variant", default="virl")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--robot", default="pupper")
    ap.add_argument("--env-steps-per-s", type=float, default=None,
                    help="one env's steps/s; default: measured with bench/env_throughput.py")
    ap.add_argument("--env-workers", type=int, default=2, help="env worker processes (cores) for the estimate")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    N, T = args.num_envs, args.steps
    rng = np.random.default_rng(0)
    demo = rng.integers(0, 256, (200, 48, 48), dtype=np.uint8)
    cfg = RewardConfig.make(variant=args.variant)
    rm = build_reward(cfg, demo, None, seed=0)
    for _ in range(20):   # 500-frame episodes: EESP windows up to window_max
        rm.add_episode(rng.integers(0, 256, (500, 48, 48), dtype=np.uint8), demo[np.arange(500) % 200])
    agent = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    expert = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    dones = rng.random((T, N)) < 0.02
    state = rm.stream_state(N)
    mask = np.zeros(N, bool)

    def stream():
        nonlocal state
        _, state = rm.stream_step(agent[0], expert[0], state, mask)

    s0 = rm.stream_state(N)
    ms_stream = timed(stream, args.repeats * 4)
    ms_batch = timed(lambda: rm.recompute(agent, expert, dones, s0), args.repeats)
    rm.update(5)
    windows = []

    def update():
        windows.append(rm.update(1)["window"])

    ms_update = timed(update, args.repeats * 2)
    store = build_reward(cfg, demo, None, seed=0)
    ms_store = timed(lambda: store.add_rollout(agent, expert, dones), 5)
    print(f"variant {args.variant}, {N} envs, {T}-step rollouts, torch threads {args.threads}")
    print(f"  streaming reward step ({N} envs)        : {ms_stream:8.2f} ms   ({ms_stream * 1000 / N:.0f} us/env)")
    print(f"  batch recompute [{T}, {N}]               : {ms_batch:8.2f} ms   "
          f"(vs {T} streaming steps {T * ms_stream:.1f} ms)")
    print(f"  model update ({cfg.pairs.batch_pairs} pairs = {2 * cfg.pairs.batch_pairs} sequences, mean window "
          f"{np.mean(windows):.1f} frames): {ms_update:8.2f} ms")
    print(f"  store one rollout in the dataset        : {ms_store:8.2f} ms "
          f"({store.dataset.bytes_per_frame:.0f} B per stored frame)")
    rate = args.env_steps_per_s or env_step_rate(args.robot, 200)
    env_ms = None if rate is None else N * T / (rate * args.env_workers) * 1000
    if rate is None:
        print("  env step time: bench/env_throughput.py not available; pass --env-steps-per-s for the share")
    else:
        print(f"  env: {rate:.0f} steps/s per env ({1000 / rate:.2f} ms/step) -> {N}x{T} steps on "
              f"{args.env_workers} workers ~ {env_ms:.0f} ms per iteration (estimate: perfect scaling)")
    modes = {"recompute only (Algorithm 1)": ms_batch + ms_store,
             "streaming + recompute": T * ms_stream + ms_batch + ms_store,
             "streaming only (no recompute)": T * ms_stream + ms_store}
    print("  per iteration, reward side = rewards + store + M updates"
          + ("" if env_ms is None else "; share = reward side / (reward side + env time), PPO update not counted"))
    for name, base in modes.items():
        cells = []
        for m in sorted({1, 2, args.updates}):
            total = base + m * ms_update
            cells.append(f"M={m}: {total:5.0f} ms" + ("" if env_ms is None else f" {100 * total / (total + env_ms):4.1f} %"))
        fit = "" if env_ms is None else f" | M fitting in 20 %: {max(0.0, (0.25 * env_ms - base) / ms_update):.1f}"
        print(f"    {name:31s} " + "  ".join(cells) + fit)
    if env_ms is not None:
        total = modes["recompute only (Algorithm 1)"] + args.updates * ms_update
        share = total / (total + env_ms)
        print(f"  goal <= 20 % with Algorithm 1 and M={args.updates}: {100 * share:.1f} % -> "
              f"{'met' if share <= 0.2 else 'NOT met'}")

if __name__ == "__main__":
    main()
