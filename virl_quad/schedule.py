"""The training runs of a comparison: one after another on this machine, or at once on a Ray cluster.

Each run is one ``python -m virl_quad.train`` subprocess logged to ``<run_dir>.log``. With
``--workers local`` they run one after the other (they would share this machine's cores). With
``--workers ray`` each run is a Ray task reserving ``--cpus-per-run`` CPUs on whichever machine
of the cluster has them, where it trains with that many local env workers: a cluster with room
for all runs finishes them in the time of one. The run folders must then lie on a path every
machine sees (a shared file system). A finished run already in its folder is reused.
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Job:
    """One training run: its reward, folder and demonstration (empty: the comparison's)."""

    reward: str
    run_dir: Path
    demo: str = ""


#: The iteration cap of every run: out of reach, so that the wall clock (``--minutes``) is the one
#: budget and an arm whose iterations are cheap (``prior``: no frames) does not stop early at
#: ``virl_quad.train``'s default cap. ``--train-args "--iterations N"`` still sets one.
ITERATION_CAP = 1_000_000


def train_argv(args, job: Job, num_workers: int | None = None) -> list[str]:
    """The ``virl_quad.train`` options of ``job`` under the comparison's options ``args`` (paths
    absolute: a run on another machine of a cluster starts in another folder)."""
    from virl_quad.motion.gaits import GAIT_NAMES

    demo = job.demo or args.demo
    if demo.removeprefix("gait:") not in GAIT_NAMES and Path(demo).is_file():   # a gait name beats a folder
        demo = str(Path(demo).resolve())
    argv = ["--robot", args.robot, "--demo", demo, "--reward", job.reward, "--minutes", str(args.minutes),
            "--iterations", str(ITERATION_CAP), "--seed", str(args.seed), "--run-dir", str(job.run_dir.resolve()),
            "--video" if args.video else "--no-video"]
    if num_workers is not None:
        argv += ["--num-workers", str(num_workers)]
    return argv + args.train_args.split()


def run_logged(argv: list[str], log_path: str) -> tuple[int, str, float, float]:
    """``python -m virl_quad.train *argv`` (this machine's Python) with its output in ``log_path``:
    (exit code, last log line, start, end time in s since the epoch)."""
    start = time.time()
    with open(log_path, "w") as log:
        code = subprocess.run([sys.executable, "-m", "virl_quad.train", *argv], stdout=log,
                              stderr=subprocess.STDOUT).returncode
    lines = Path(log_path).read_text().strip().splitlines()
    return code, (lines[-1] if lines else "?"), start, time.time()


def _outcome(job: Job, result: tuple[int, str, float, float]) -> dict:
    code, tail, start, end = result
    out = {"start": start, "end": end}
    if code != 0:
        out["error"] = f"training with --reward {job.reward} failed (exit {code}): {tail}"
    return out


def train_all(args, jobs: list[Job]) -> dict[Path, dict]:
    """Train every job whose folder holds no finished run; run folder -> {"start", "end"} times,
    plus "error" (one line) for a run that failed, or {"reused": True}."""
    out: dict[Path, dict] = {}
    todo = []
    for job in jobs:
        if (job.run_dir / "report.json").exists():
            print(f"[{job.run_dir.name}] reusing the finished run in {job.run_dir}", flush=True)
            out[job.run_dir] = {"reused": True}
        else:
            job.run_dir.parent.mkdir(parents=True, exist_ok=True)
            todo.append(job)
    if args.workers == "ray":
        out.update(_on_ray(args, todo))
        return out
    for job in todo:
        argv = train_argv(args, job)
        print(f"[{job.run_dir.name}] virl_quad.train {' '.join(argv)}", flush=True)
        out[job.run_dir] = _outcome(job, run_logged(argv, str(_log_path(job))))
    return out


def _log_path(job: Job) -> Path:
    return job.run_dir.parent / f"{job.run_dir.name}.log"


def _on_ray(args, jobs: list[Job]) -> dict[Path, dict]:
    """Every job as a Ray task of ``args.cpus_per_run`` CPUs, all submitted at once."""
    if not jobs:
        return {}
    from virl_quad.envs.ray_workers import connect

    import ray

    connect(args.ray_address or None)
    task = ray.remote(num_cpus=args.cpus_per_run, max_retries=0)(run_logged)
    refs = []
    for job in jobs:
        argv = train_argv(args, job, num_workers=args.cpus_per_run)
        print(f"[{job.run_dir.name}] a Ray task of {args.cpus_per_run} CPUs: virl_quad.train {' '.join(argv)}",
              flush=True)
        refs.append(task.remote(argv, str(_log_path(job).resolve())))
    out = {}
    for job, ref in zip(jobs, refs):
        try:
            out[job.run_dir] = _outcome(job, ray.get(ref))
        except ray.exceptions.RayError as exc:
            why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            out[job.run_dir] = {"error": f"training with --reward {job.reward} was lost on the cluster: {why}"}
    return out
