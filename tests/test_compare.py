"""python -m virl_quad.compare on a tiny budget: every reward trained, scored, tabulated and plotted."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TINY_TRAIN = ("--train-args=--num-envs 2 --steps-per-env 8 --num-workers 1 --iterations 2 --warm-start-rounds 1 "
              "--warm-start-steps 40 --critic-warmup 1 --eval-episodes 1 --eval-seconds 0.5 --eval-every 1")


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


def test_unknown_reward_is_one_error_line(tmp_path: Path) -> None:
    p = run("--rewards", "virl,foo", "--out", str(tmp_path / "x"))
    assert p.returncode == 2
    assert p.stderr.strip() == "error: unknown reward 'foo' in --rewards; choose from: " \
        "virl, frame, sequence, no_ae, gaifo, oracle, prior", p.stderr
    assert not (tmp_path / "x").exists()                # refused before anything was made
