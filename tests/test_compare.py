"""python -m virl_quad.compare on a tiny budget: every reward trained, scored, tabulated and plotted."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: tiny runs; the prior from the reference motion and no alignment probe (both tested on their own,
#: tests/training/test_video_prior.py and test_alignment.py) keep each run to seconds
TINY_TRAIN = ("--train-args=--num-envs 2 --steps-per-env 8 --num-workers 1 --iterations 2 --warm-start-rounds 1 "
              "--reward-pretrain 2 "
              "--warm-start-steps 40 --critic-warmup 1 --eval-episodes 1 --eval-seconds 0.5 --eval-every 1 "
              "--prior-from motion --no-alignment-probe")


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "virl_quad.compare", *args], capture_output=True, text=True,
                          timeout=600)


def test_tiny_comparison_writes_table_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    p = run("--rewards", "oracle,prior", "--minutes", "1", "--episodes", "1", "--seconds", "0.5", "--no-video",
            "--out", str(out), TINY_TRAIN)
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    data = json.loads((out / "results.json").read_text())
    assert set(data["results"]) == {"oracle", "prior"} and data["standing"]["total"] > 0
    for name, r in data["results"].items():
        assert 0 <= r["total"] <= 1 and r["iterations"] == 2, (name, r)
        assert Path(r["policy"]).exists()
    table = (out / "results.md").read_text()
    assert "| oracle |" in table and "| prior |" in table and "x standing" in table
    assert (out / "curves.png").stat().st_size > 1000 and (out / "scores.png").stat().st_size > 1000
    for name in ("oracle", "prior"):                     # each run trained with its own reward
        assert json.loads((out / name / "config.json").read_text())["reward"] == name
    again = run("--rewards", "oracle,prior", "--minutes", "1", "--episodes", "1", "--seconds", "0.5", "--no-video",
                "--out", str(out), TINY_TRAIN)            # an interrupted comparison resumes: finished runs reused
    assert again.returncode == 0 and again.stdout.count("reusing the finished run") == 2, again.stdout[-2000:]


def test_unknown_reward_is_one_error_line(tmp_path: Path) -> None:
    p = run("--rewards", "virl,foo", "--out", str(tmp_path / "x"))
    assert p.returncode == 2
    assert p.stderr.strip() == "error: unknown reward 'foo' in --rewards; choose from: " \
        "virl, frame, sequence, no_ae, gaifo, oracle, prior", p.stderr
    assert not (tmp_path / "x").exists()                # refused before anything was made


def test_tiny_confusion_writes_matrix_and_reuses_finished_runs(tmp_path: Path) -> None:
    out = tmp_path / "conf"
    args = ("--confusion", "trot,pace", "--minutes", "1", "--episodes", "1", "--seconds", "0.5", "--no-video",
            "--out", str(out), TINY_TRAIN)
    p = run(*args)
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    data = json.loads((out / "confusion.json").read_text())
    matrix = data["matrix"]
    assert data["gaits"] == ["trot", "pace"] and len(matrix) == 2 and all(len(row) == 2 for row in matrix)
    assert all(0 < v <= 1 for row in matrix for v in row), matrix
    assert matrix[0] != matrix[1]                        # two policies, two different rows
    for gait in ("trot", "pace"):                        # VIRL trained on each gait's own video
        config = json.loads((out / gait / "config.json").read_text())
        assert config["reward"] == "virl" and config["demo"] == gait, config
    assert "| trot |" in (out / "confusion.md").read_text()
    assert (out / "confusion.png").stat().st_size > 1000
    stamp = (out / "trot" / "checkpoint.pt").stat().st_mtime
    again = run(*args)                                   # finished runs are reused, not trained again
    assert again.returncode == 0 and again.stdout.count("reusing the finished run") == 2, again.stdout[-2000:]
    assert (out / "trot" / "checkpoint.pt").stat().st_mtime == stamp


def test_bad_confusion_lists_are_one_error_line(tmp_path: Path) -> None:
    for gaits, message in (("trot", "two or more distinct"), ("trot,trot", "two or more distinct"),
                           ("trot,foo", "cannot use 'foo' as a demonstration")):
        p = run("--confusion", gaits, "--out", str(tmp_path / "x"))
        assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert p.stderr.startswith("error:") and message in p.stderr, p.stderr
        assert not (tmp_path / "x").exists()


def test_runs_go_at_once_as_ray_tasks(tmp_path: Path) -> None:
    """--workers ray: on a local Ray cluster of this machine's CPUs (2 here), two runs of one CPU
    each are scheduled together, so they overlap in time."""
    pytest.importorskip("ray", reason='needs the cluster extra: pip install -e ".[cluster]"')
    out = tmp_path / "cmp"
    p = run("--rewards", "oracle,prior", "--minutes", "5", "--episodes", "1", "--seconds", "0.5", "--no-video",
            "--out", str(out), "--workers", "ray", "--cpus-per-run", "1", TINY_TRAIN)
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    assert p.stdout.count("a Ray task of 1 CPUs") == 2, p.stdout[-2000:]
    results = json.loads((out / "results.json").read_text())["results"]
    (a0, a1), (b0, b1) = ((results[r]["start"], results[r]["end"]) for r in ("oracle", "prior"))
    assert a0 < b1 and b0 < a1, results                 # the two runs overlapped
    assert all(results[r]["iterations"] == 2 for r in ("oracle", "prior"))


def test_each_run_is_budgeted_by_the_clock_alone(tmp_path: Path) -> None:
    """No arm of a comparison stops at train's default iteration cap before its minutes are up;
    an iteration count in --train-args still wins (it comes later on the command line)."""
    from virl_quad.compare import CompareArgs
    from virl_quad.schedule import ITERATION_CAP, Job, train_argv
    from virl_quad.training.config import TrainArgs

    argv = train_argv(CompareArgs(minutes=3.0), Job("prior", tmp_path / "prior"))
    assert argv[argv.index("--iterations") + 1] == str(ITERATION_CAP)
    assert ITERATION_CAP > 100 * TrainArgs().run.iterations
    argv = train_argv(CompareArgs(train_args="--iterations 2"), Job("prior", tmp_path / "prior"))
    assert argv[len(argv) - 1 - argv[::-1].index("--iterations") + 1] == "2"


def test_a_gait_name_is_passed_on_even_beside_a_folder_of_that_name(tmp_path: Path, monkeypatch) -> None:
    """A run folder named after a gait (``--run-dir trot``) in the working directory does not turn
    ``--demo trot`` into a path; a demonstration file is passed on as an absolute path."""
    from virl_quad.compare import CompareArgs
    from virl_quad.schedule import Job, train_argv

    monkeypatch.chdir(tmp_path)
    (tmp_path / "trot").mkdir()
    (tmp_path / "clip.npz").write_bytes(b"")
    argv = train_argv(CompareArgs(demo="trot"), Job("virl", tmp_path / "virl"))
    assert argv[argv.index("--demo") + 1] == "trot"
    argv = train_argv(CompareArgs(demo="clip.npz"), Job("virl", tmp_path / "virl"))
    assert argv[argv.index("--demo") + 1] == str(tmp_path / "clip.npz")
