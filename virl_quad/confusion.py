"""A gait confusion matrix: is it the video, not the prior, that chooses the gait?

    python -m virl_quad.compare --robot pupper --confusion trot,pace,bound --minutes 20

Trains VIRL on each gait's video (``python -m virl_quad.train --demo <gait>``, the main job's
defaults otherwise), then records each policy's episodes once (``--episodes`` seeded episodes,
randomisation on, in its own demonstration's env) and scores them against every gait's reference
motion. A cell is the ground-truth total at the best constant phase shift of that reference
(``total_best_offset``): a policy's clock follows its own video, so the comparison with another
gait must not charge it for phase. Each row should peak on its diagonal.

Writes into ``--out``: ``confusion.md``, ``confusion.json`` and ``confusion.png``, beside each
gait's run folder. A finished run already in the folder is reused, so an interrupted matrix
picks up where it stopped.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from virl_quad.cli import UserError


def parse_gaits(text: str, robot: str) -> dict[str, object]:
    """The comma-separated demonstrations, checked (at least two, distinct, each with a reference
    motion): {name: its reference motion}."""
    from virl_quad import demo as demo_lib

    names = [g.strip() for g in text.split(",") if g.strip()]
    if len(names) < 2 or len(set(names)) != len(names):
        raise UserError(f"--confusion needs two or more distinct demonstrations, got {text!r}")
    motions = {}
    for name in names:
        try:
            demo = demo_lib.load(name, robot)
        except (ValueError, FileNotFoundError) as e:
            raise UserError(str(e)) from None
        if demo.motion is None:
            raise UserError(f"--confusion: {name!r} has no reference motion to score against")
        motions[name] = demo.motion
    return motions


def record(policy, robot: str, demo, episodes: int, seconds: float) -> list[tuple]:
    """``episodes`` seeded, randomised episodes of ``policy`` in ``demo``'s env: (trajectory, times) each."""
    from virl_quad.evaluation.rollout import evaluate
    from virl_quad.evaluate import policy_callable

    rollouts: list[tuple] = []
    evaluate(policy_callable(policy), robot, demo, episodes=episodes, seed=0, episode_seconds=seconds,
             randomize=True, trajectories=rollouts, **policy.contract.env_overrides())
    return rollouts


def score_against(rollouts: list[tuple], motion, robot: str, kin) -> float:
    """Ground-truth total at the best phase shift of ``motion``, averaged over steps of all rollouts."""
    from virl_quad.evaluation.score import score_trajectory

    totals = [score_trajectory(traj, motion, times, robot, kin=kin)["total_best_offset"] for traj, times in rollouts]
    return float(np.average(totals, weights=[len(traj) for traj, _ in rollouts]))


def matrix_markdown(robot: str, gaits: list[str], matrix: np.ndarray, episodes: int, minutes: float) -> str:
    """Rows: the video a policy learned from; columns: the reference it is scored against."""
    wins = sum(int(np.argmax(matrix[i]) == i) for i in range(len(gaits)))
    lines = [f"# {robot}: gait confusion, VIRL at {minutes:g} min per gait", "",
             f"Ground-truth score at the best phase shift, {episodes} randomised episodes per policy. "
             f"Rows: the video the policy learned from; columns: the reference scored against. "
             f"Rows peaking on their own gait: {wins} of {len(gaits)}.", "",
             "| learned from \\ scored against | " + " | ".join(gaits) + " |",
             "|---|" + "---|" * len(gaits)]
    for i, g in enumerate(gaits):
        cells = [f"**{v:.3f}**" if j == np.argmax(matrix[i]) else f"{v:.3f}" for j, v in enumerate(matrix[i])]
        lines.append(f"| {g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def matrix_plot(path: Path, gaits: list[str], matrix: np.ndarray) -> None:
    """The matrix as an annotated heat map (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.3 * len(gaits) + 2.5, 1.1 * len(gaits) + 1.5))
    im = ax.imshow(matrix, cmap="viridis")
    for i in range(len(gaits)):
        for j in range(len(gaits)):
            ax.text(j, i, f"{matrix[i, j]:.3f}", ha="center", va="center",
                    color="white" if matrix[i, j] < matrix.mean() else "black",
                    fontweight="bold" if j == np.argmax(matrix[i]) else "normal")
    ax.set_xticks(range(len(gaits)), gaits)
    ax.set_yticks(range(len(gaits)), gaits)
    ax.set_xlabel("scored against the reference of")
    ax.set_ylabel("VIRL policy learned from the video of")
    fig.colorbar(im, ax=ax, label="ground-truth score (best phase)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def run_confusion(args, out: Path) -> int:
    """Train (or reuse) VIRL on each gait of ``args.confusion``, score each against each, write the matrix."""
    from virl_quad.compare import refuse_unfinished

    motions = parse_gaits(args.confusion, args.robot)     # bad lists refused before the heavy imports
    gaits = list(motions)
    refuse_unfinished([out / Path(g).stem for g in gaits])

    from virl_quad import demo as demo_lib
    from virl_quad import robots
    from virl_quad.export import export
    from virl_quad.kinematics import Kinematics
    from virl_quad.policy_io import load_policy
    from virl_quad.schedule import Job, train_all

    out.mkdir(parents=True, exist_ok=True)
    print(f"confusion of {', '.join(gaits)} on {args.robot}, VIRL at {args.minutes:g} min each; "
          f"results in {out}", flush=True)
    runs = train_all(args, [Job("virl", out / Path(g).stem, demo=g) for g in gaits])
    failed = [(run, r["error"]) for run, r in runs.items() if "error" in r]
    if failed:
        run, error = failed[0]
        raise UserError(f"{error} (its log: {run.parent / (run.name + '.log')})")
    kin = Kinematics(robots.get(args.robot))
    matrix = np.zeros((len(gaits), len(gaits)))
    for i, g in enumerate(gaits):
        run = out / Path(g).stem
        policy = load_policy(export(run, run / "policy.pt"))
        rollouts = record(policy, args.robot, demo_lib.load(str(run / "demo.npz"), args.robot),
                          args.episodes, args.seconds)
        matrix[i] = [score_against(rollouts, motions[h], args.robot, kin) for h in gaits]
        print(f"[{g}] " + ", ".join(f"{h} {v:.3f}" for h, v in zip(gaits, matrix[i])), flush=True)
    table = matrix_markdown(args.robot, gaits, matrix, args.episodes, args.minutes)
    (out / "confusion.md").write_text(table)
    (out / "confusion.json").write_text(json.dumps({"options": vars(args), "gaits": gaits,
                                                    "matrix": matrix.tolist()}, indent=2) + "\n")
    matrix_plot(out / "confusion.png", gaits, matrix)
    print(table)
    print(f"written: {out / 'confusion.md'}, confusion.json, confusion.png")
    return 0
