"""The paper's comparison in one command: rewards trained at the same budget, scored by the truth.

    python -m virl_quad.compare --robot pupper --demo trot --rewards virl,frame,gaifo,oracle,prior --minutes 20

Each reward is one ``python -m virl_quad.train`` run (same robot, demonstration, seed and
wall-clock budget; one after the other, as they share this machine's cores, or at once on a Ray
cluster with ``--workers ray``: see :mod:`virl_quad.schedule`), exported and then
evaluated with the ground-truth imitation score (``--episodes`` seeded episodes, domain
randomisation on) beside holding the default pose. ``prior`` trains the gait prior and warm
start with a survival reward only: a learned reward that does not beat it adds nothing.
Writes into ``--out``: ``results.md`` and ``results.json`` (the table), ``curves.png`` (score
against env steps and wall time, from each run's evaluations), ``scores.png`` (a bar chart),
and each run's folder with its policy and side-by-side video (demonstration | agent). A finished
run already in ``--out`` is reused, so an interrupted comparison picks up where it stopped.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from virl_quad.cli import UserError, dataclass_from_args, opt, parser_from_dataclass, run_main
from virl_quad.schedule import Job, train_all
from virl_quad.training.config import REWARDS, WORKER_KINDS


@dataclass
class CompareArgs:
    """Options of ``python -m virl_quad.compare``."""

    robot: str = opt("pupper", "robot to train")
    demo: str = opt("trot",
        "demonstration (as --demo of virl_quad.train); needs a reference motion for the score")
    rewards: str = opt("virl,frame,gaifo,oracle,prior",
        "comma-separated rewards to compare (see virl_quad.train --reward)")
    minutes: float = opt(20.0, "wall-clock budget of each training run")
    episodes: int = opt(10, "evaluation episodes per policy (seeds 0..N-1, randomisation on)")
    seconds: float = opt(10.0, "s per evaluation episode")
    seed: int = opt(0, "training seed of every run")
    out: str = opt("", "output folder (empty: runs/compare-<robot>-<demo>-<date>, or runs/confusion-<robot>-<date>)")
    video: bool = opt(True, "each run writes its side-by-side video")
    train_args: str = opt("",
        "further options for every training run, written --train-args=\"--num-envs 32 --eval-every 10\"")
    workers: str = opt("local",
        "where the training runs go: local (one after the other on this machine) or ray (at once, as Ray "
        "tasks of --cpus-per-run CPUs on the cluster at --ray-address; --out must be a path every machine "
        "sees)", choices=WORKER_KINDS)
    ray_address: str = opt("", "with --workers ray: the cluster (auto, host:port; empty: start a local one)")
    cpus_per_run: int = opt(2, "with --workers ray: CPUs each run reserves (and its env workers)")
    confusion: str = opt("",
        "instead: comma-separated gaits (e.g. trot,pace,bound), VIRL trained on each video and scored "
        "against each reference (see virl_quad.confusion)")


def parse_rewards(text: str) -> list[str]:
    """The comma-separated reward list, checked (ValueError names an unknown one)."""
    names = [r.strip() for r in text.split(",") if r.strip()]
    if not names:
        raise ValueError("--rewards lists no reward")
    unknown = [r for r in names if r not in REWARDS]
    if unknown:
        raise ValueError(f"unknown reward {unknown[0]!r} in --rewards; choose from: {', '.join(REWARDS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"--rewards lists a reward twice: {text!r}")
    return names


def refuse_unfinished(run_dirs: list[Path]) -> None:
    """UserError when one of ``run_dirs`` holds a run that started and did not finish."""
    for run in run_dirs:
        if (run / "checkpoint.pt").exists() and not (run / "report.json").exists():
            raise UserError(f"{run} holds an unfinished run: resume it with virl_quad.train or give another --out")


def evaluate_run(args: CompareArgs, run_dir: Path) -> dict:
    """Export the run's policy and score it: the evaluation's figures plus iterations and env steps."""
    from virl_quad import demo as demo_lib
    from virl_quad.evaluation.rollout import evaluate
    from virl_quad.evaluate import policy_callable
    from virl_quad.export import export
    from virl_quad.policy_io import load_policy

    path = export(run_dir, run_dir / "policy.pt")
    policy = load_policy(path)
    demo = demo_lib.load(str(run_dir / "demo.npz"), args.robot)
    result = evaluate(policy_callable(policy), args.robot, demo, episodes=args.episodes, seed=0,
                      episode_seconds=args.seconds, randomize=True, **policy.contract.env_overrides())
    report = json.loads((run_dir / "report.json").read_text())
    figures = {k: float(v) for k, v in result.items() if isinstance(v, (int, float))}
    return {**figures, "iterations": report["iterations"], "env_steps": report["env_steps"],
            "wall_time_s": report["wall_time_s"], "policy": str(path)}


def standing_score(args: CompareArgs, demo_path: Path) -> dict:
    """Holding the default pose, evaluated as the policies are."""
    from virl_quad import demo as demo_lib
    from virl_quad.evaluation.rollout import evaluate
    from virl_quad.evaluate import zero_policy

    demo = demo_lib.load(str(demo_path), args.robot)
    result = evaluate(zero_policy, args.robot, demo, episodes=args.episodes, seed=0,
                      episode_seconds=args.seconds, randomize=True)
    return {k: float(v) for k, v in result.items() if isinstance(v, (int, float))}


def table_markdown(args: CompareArgs, results: dict[str, dict], standing: dict) -> str:
    """The results as a markdown table, best score first."""
    lines = [f"# {args.robot} {args.demo}: rewards at {args.minutes:g} min each",
             "", f"Ground-truth score over {args.episodes} randomised episodes of {args.seconds:g} s "
             f"(seeds 0-{args.episodes - 1}); holding the default pose scores {standing['total']:.3f}.", "",
             "| reward | score | x standing | survival | speed ratio | falls | iterations | env steps |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in sorted(results.items(), key=lambda kv: -kv[1].get("total", -1.0)):
        if "error" in r:
            lines.append(f"| {name} | failed: {r['error']} | | | | | | |")
            continue
        lines.append(f"| {name} | {r['total']:.3f} | {r['total'] / standing['total']:.2f} | "
                     f"{r['survival_fraction']:.2f} | {r['speed_ratio']:.2f} | {int(r['falls'])} | "
                     f"{r['iterations']} | {r['env_steps']:,d} |")
    return "\n".join(lines) + "\n"


def plots(out: Path, results: dict[str, dict], standing: dict) -> None:
    """``curves.png`` (each run's evaluations against env steps and wall time) and ``scores.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = standing["total"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for name in results:
        path = out / name / "evaluations.jsonl"
        rows = [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []
        for ax, key in zip(axes, ("env_steps", "wall_time_s")):
            ax.plot([r[key] for r in rows], [r["total"] / base for r in rows], marker="o", label=name)
    for ax, label in zip(axes, ("env steps", "wall time (s)")):
        ax.axhline(1.0, color="black", lw=0.8)
        ax.set_xlabel(label)
    axes[0].set_ylabel("ground-truth score / standing (in-run evaluations)")
    axes[1].legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "curves.png", dpi=100)
    plt.close(fig)
    ok = {k: v for k, v in results.items() if "total" in v}
    fig, ax = plt.subplots(figsize=(1.4 * len(ok) + 2, 4))
    ax.bar(list(ok), [v["total"] / base for v in ok.values()], color="tab:blue")
    ax.axhline(1.0, color="black", lw=0.8, label="standing")
    ax.set_ylabel("ground-truth score / standing")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "scores.png", dpi=100)
    plt.close(fig)


def main(args: CompareArgs) -> int:
    """Train, evaluate, tabulate and plot every reward (or the gait confusion); exit 2 on bad options."""
    if args.minutes <= 0 or args.episodes < 1 or args.seconds <= 0:
        raise UserError("--minutes and --seconds must be > 0 and --episodes >= 1")
    if args.cpus_per_run < 1:
        raise UserError(f"--cpus-per-run must be >= 1, got {args.cpus_per_run}")
    if args.confusion:
        from virl_quad.confusion import run_confusion

        return run_confusion(args, Path(args.out or f"runs/confusion-{args.robot}-{time.strftime('%Y%m%d-%H%M%S')}"))
    rewards = parse_rewards(args.rewards)
    out = Path(args.out or f"runs/compare-{args.robot}-{Path(args.demo).stem}-{time.strftime('%Y%m%d-%H%M%S')}")
    refuse_unfinished([out / r for r in rewards])
    out.mkdir(parents=True, exist_ok=True)
    print(f"comparing {', '.join(rewards)} on {args.robot} {args.demo}, {args.minutes:g} min each; "
          f"results in {out}", flush=True)
    runs = train_all(args, [Job(r, out / r) for r in rewards])
    results: dict[str, dict] = {}
    for reward in rewards:
        if "error" in runs[out / reward]:
            results[reward] = {"error": runs[out / reward]["error"]}
            print(f"[{reward}] {results[reward]['error']}", flush=True)
            continue
        results[reward] = {**evaluate_run(args, out / reward), **runs[out / reward]}
        r = results[reward]
        print(f"[{reward}] score {r['total']:.3f}, survival {r['survival_fraction']:.2f}, "
              f"speed {r['speed_ratio']:.2f} ({r['env_steps']:,d} env steps)", flush=True)
    done = [r for r in rewards if "total" in results[r]]
    if not done:
        raise UserError(f"every training run failed; their logs are in {out}")
    standing = standing_score(args, out / done[0] / "demo.npz")
    (out / "results.json").write_text(json.dumps({"options": vars(args), "standing": standing,
                                                  "results": results}, indent=2) + "\n")
    (out / "results.md").write_text(table_markdown(args, results, standing))
    plots(out, results, standing)
    print((out / "results.md").read_text())
    print(f"written: {out / 'results.md'}, results.json, curves.png, scores.png")
    return 0


def cli(argv: list[str] | None = None) -> None:
    """Parse the command line and run :func:`main` with one-line errors (exit code 2)."""
    argv = sys.argv[1:] if argv is None else argv
    parser = parser_from_dataclass(CompareArgs, description=__doc__.split("\n\n")[0],
                                   prog="python -m virl_quad.compare")
    ns = parser.parse_args(argv)
    run_main(lambda: main(dataclass_from_args(CompareArgs, ns)))


if __name__ == "__main__":
    cli()
