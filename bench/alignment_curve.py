"""A run's learned-reward alignment and ground-truth score against env steps (run by hand).

    python bench/alignment_curve.py RUN_DIR [--out RUN_DIR/alignment.png] [--bar 0.6]

Reads the run's ``evaluations.jsonl`` (written at every evaluation of ``python -m
virl_quad.train`` with a learned reward and ``--alignment-probe``, the default): prints one row
per evaluation (iteration, env steps, wall time, score as a multiple of standing, speed ratio,
the reward's rank correlation with the score on the alignment probe, its reward for the best
controller and for standing still) and whether every probe reached ``--bar``; writes a PNG of
the score and the rank correlation against env steps.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)


def main() -> int:
    """Print the table, write the PNG."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", type=Path, help="training run folder")
    p.add_argument("--out", type=Path, default=None, help="PNG to write (default: alignment.png in the run folder)")
    p.add_argument("--bar", type=float, default=0.6, help="rank correlation every probe should reach")
    a = p.parse_args()
    out = a.out or a.run_dir / "alignment.png"
    path = a.run_dir / "evaluations.jsonl"
    if not path.exists():
        print(f"error: {path} not found", file=sys.stderr)
        return 2
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    rows = [r for r in rows if "reward_alignment" in r]
    if not rows:
        print(f"error: no evaluation in {path} probed the reward (oracle reward, or --no-alignment-probe)",
              file=sys.stderr)
        return 2
    print(f"{'iter':>5} {'env steps':>10} {'wall s':>7} {'x stand':>8} {'speed':>6} {'align':>6} "
          f"{'r(best)':>8} {'r(stand)':>8}")
    for r in rows:
        print(f"{r['iteration']:5d} {r['env_steps']:10,d} {r['wall_time_s']:7.0f} "
              f"{r.get('score_vs_standing', float('nan')):8.2f} {r.get('speed_ratio', float('nan')):6.2f} "
              f"{r['reward_alignment']:+6.2f} {r['reward_best']:8.3f} {r['reward_standing']:8.3f}")
    low = [r["iteration"] for r in rows if r["reward_alignment"] < a.bar]
    print(f"{len(rows)} probes, rank correlation {min(r['reward_alignment'] for r in rows):+.2f} .. "
          f"{max(r['reward_alignment'] for r in rows):+.2f}; "
          + (f"below {a.bar:g} at iterations {low}" if low else f"every probe >= {a.bar:g}"))
    fig, ax = plt.subplots(figsize=(8, 4))
    steps = [r["env_steps"] for r in rows]
    ax.plot(steps, [r["reward_alignment"] for r in rows], "o-", label="reward-score rank correlation (probe)")
    if any("distance_alignment" in r for r in rows):     # the reward mixes in the video speed term
        ax.plot(steps, [r.get("distance_alignment", float("nan")) for r in rows], "^:",
                label="the distance model's alone")
        dist = [r["distance_alignment"] for r in rows if "distance_alignment" in r]
        print(f"the distance model alone: {min(dist):+.2f} .. {max(dist):+.2f}, "
              f"{sum(d >= a.bar for d in dist)} of {len(dist)} probes >= {a.bar:g}")
    ax.plot(steps, [r.get("score_vs_standing", float("nan")) for r in rows], "s-", label="score / standing")
    ax.axhline(a.bar, color="gray", ls="--", label=f"bar {a.bar:g}")
    ax.axhline(1.0, color="black", lw=0.8)
    ax.set_xlabel("env steps")
    ax.legend(loc="center right", fontsize="small")
    ax.set_title(f"{a.run_dir.name}: learned reward alignment and ground-truth score")
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
