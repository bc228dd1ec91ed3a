"""A run's learned-reward alignment and ground-truth score against env steps (run by hand).

    python bench/alignment_curve.py RUN_DIR [--out RUN_DIR/alignment.png] [--bar 0.6]
    python bench/alignment_curve.py RUN_DIR RUN_DIR ... --out runs.png

Reads each run's ``evaluations.jsonl`` (written at every evaluation of ``python -m
virl_quad.train`` with a learned reward and ``--alignment-probe``, the default). With one run:
prints one row per evaluation (iteration, env steps, wall time, score as a multiple of standing,
speed ratio, the reward's rank correlation with the score on the alignment probe, its reward for
the best controller and for standing still) and whether every probe reached ``--bar``; writes a
PNG of the score and the rank correlation against env steps. With several: prints one row per
run (probes, lowest and highest rank correlation of the training reward and of the distance
model alone, whether every probe reached the bar) and writes their alignment curves in one PNG.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)


def load(run_dir: Path) -> list[dict]:
    """The run's evaluations that probed the reward; raises ``ValueError`` with the reason if none."""
    path = run_dir / "evaluations.jsonl"
    if not path.exists():
        raise ValueError(f"{path} not found")
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = [r for r in rows if "reward_alignment" in r]
    if not rows:
        raise ValueError(f"no evaluation in {path} probed the reward (oracle reward, or --no-alignment-probe)")
    return rows


def span(values: list[float], bar: float) -> str:
    """'lo .. hi, k of n probes >= bar' for a list of rank correlations."""
    return (f"{min(values):+.2f} .. {max(values):+.2f}, "
            f"{sum(v >= bar for v in values)} of {len(values)} probes >= {bar:g}")


def one_run(run_dir: Path, rows: list[dict], bar: float, out: Path) -> None:
    """Print the run's table; plot its alignment and score against env steps."""
    print(f"{'iter':>5} {'env steps':>10} {'wall s':>7} {'x stand':>8} {'speed':>6} {'align':>6} "
          f"{'r(best)':>8} {'r(stand)':>8}")
    for r in rows:
        print(f"{r['iteration']:5d} {r['env_steps']:10,d} {r['wall_time_s']:7.0f} "
              f"{r.get('score_vs_standing', float('nan')):8.2f} {r.get('speed_ratio', float('nan')):6.2f} "
              f"{r['reward_alignment']:+6.2f} {r['reward_best']:8.3f} {r['reward_standing']:8.3f}")
    low = [r["iteration"] for r in rows if r["reward_alignment"] < bar]
    print(f"{len(rows)} probes, rank correlation {min(r['reward_alignment'] for r in rows):+.2f} .. "
          f"{max(r['reward_alignment'] for r in rows):+.2f}; "
          + (f"below {bar:g} at iterations {low}" if low else f"every probe >= {bar:g}"))
    fig, ax = plt.subplots(figsize=(8, 4))
    steps = [r["env_steps"] for r in rows]
    ax.plot(steps, [r["reward_alignment"] for r in rows], "o-", label="reward-score rank correlation (probe)")
    dist = [r["distance_alignment"] for r in rows if "distance_alignment" in r]
    if dist:     # the reward mixes in the video speed term
        ax.plot(steps, [r.get("distance_alignment", float("nan")) for r in rows], "^:",
                label="the distance model's alone")
        print(f"the distance model alone: {span(dist, bar)}")
    ax.plot(steps, [r.get("score_vs_standing", float("nan")) for r in rows], "s-", label="score / standing")
    ax.axhline(bar, color="gray", ls="--", label=f"bar {bar:g}")
    ax.axhline(1.0, color="black", lw=0.8)
    ax.set_xlabel("env steps")
    ax.legend(loc="center right", fontsize="small")
    ax.set_title(f"{run_dir.name}: learned reward alignment and ground-truth score")
    fig.tight_layout()
    fig.savefig(out, dpi=100)


def many_runs(runs: dict[str, list[dict]], bar: float, out: Path) -> None:
    """Print one row per run; plot every run's training-reward alignment against env steps."""
    fig, ax = plt.subplots(figsize=(8, 4))
    colours = plt.get_cmap("tab20" if len(runs) > 10 else "tab10").colors   # one colour per run up to 20
    for i, (name, rows) in enumerate(runs.items()):
        align = [r["reward_alignment"] for r in rows]
        dist = [r["distance_alignment"] for r in rows if "distance_alignment" in r]
        verdict = "held" if min(align) >= bar else "BELOW"
        print(f"{name}: {verdict}; reward {span(align, bar)}" + (f"; distance model alone {span(dist, bar)}" if dist else ""))
        ax.plot([r["env_steps"] for r in rows], align, ".-", label=name, color=colours[i % len(colours)])
    held = sum(min(r["reward_alignment"] for r in rows) >= bar for rows in runs.values())
    print(f"every probe >= {bar:g} in {held} of {len(runs)} runs")
    ax.axhline(bar, color="gray", ls="--", label=f"bar {bar:g}")
    ax.set_ylim(min(0.0, ax.get_ylim()[0]), 1.0)
    ax.set_xlabel("env steps")
    ax.set_ylabel("reward-score rank correlation (probe)")
    ax.legend(loc="lower right", fontsize="x-small", ncol=2)
    ax.set_title(f"learned reward alignment, {len(runs)} runs")
    fig.tight_layout()
    fig.savefig(out, dpi=100)


def main() -> int:
    """Print the table(s), write the PNG."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dirs", type=Path, nargs="+", help="training run folder(s)")
    p.add_argument("--out", type=Path, default=None,
                   help="PNG to write (default: alignment.png in the run folder; required with several runs)")
    p.add_argument("--bar", type=float, default=0.6, help="rank correlation every probe should reach")
    a = p.parse_args()
    if len(a.run_dirs) > 1 and a.out is None:
        print("error: --out is required with several runs", file=sys.stderr)
        return 2
    runs: dict[str, list[dict]] = {}
    for d in a.run_dirs:
        try:
            runs[str(d).rstrip("/")] = load(d)
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
    out = a.out or a.run_dirs[0] / "alignment.png"
    if len(runs) == 1:
        one_run(a.run_dirs[0], next(iter(runs.values())), a.bar, out)
    else:
        many_runs(runs, a.bar, out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
