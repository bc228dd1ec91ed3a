"""The main job end to end, tiny: train -> checkpoint -> resume -> export -> load and act."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from virl_quad.policy_io import load_policy
from virl_quad.training import checkpoint

TINY = ["--num-envs", "4", "--steps-per-env", "8", "--reward-updates", "1", "--reward-pretrain", "2", "--eval-episodes", "1",
        "--eval-seconds", "0.5", "--no-video", "--num-workers", "1", "--save-every", "1",
        "--warm-start-rounds", "1", "--warm-start-steps", "40", "--critic-warmup", "1", "--no-alignment-probe",
        "--prior-from", "motion"]   # the video fit (~20 s) and its physics check: the Laikago run and the --tg test


def run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=timeout)


#: Pupper also runs with the plain ground; Laikago with the reward's alignment probe and the prior fitted to the video.
EXTRA = {"pupper": ["--ground", "plain"],
         "laikago": ["--alignment-probe", "--eval-every", "2", "--prior-from", "video"]}

#: Options of retired features, with their old defaults, as checkpoints of older versions hold them.
RETIRED = {"speed_strip": False, "speed_shift_weight": 0.25, "reward_warmup": 0, "reward_freeze_after": 0,
           "ground_shifts": 7}


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_tiny_run_resume_export(robot: str, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    p = run("virl_quad.train", "--robot", robot, "--iterations", "2", "--run-dir", str(run_dir), *TINY, *EXTRA[robot])
    assert p.returncode == 0, p.stderr[-2000:]
    assert "it     2/2" in p.stdout
    data = checkpoint.load(run_dir)
    # two iterations and the rollout the distance model pretrains on, all counted
    assert data["iteration"] == 2 and data["env_steps"] == (2 + 1) * 4 * 8
    assert data["config"]["ground"] == ("plain" if robot == "pupper" else "checker")
    net2 = data["reward"]["net"]
    report = json.loads((run_dir / "report.json").read_text())
    assert 0 <= report["evaluation"]["total"] <= 1
    # the run folder says how it was made and what it printed; the progress line reads as a person needs
    assert json.loads((run_dir / "config.json").read_text())["robot"] == robot
    log = (run_dir / "train.log").read_text()
    assert "it     2/2" in log and "holding the default pose scores" in log
    assert report["standing"]["total"] > 0 and "x standing, speed" in p.stdout, p.stdout[-2000:]
    # the video speed term needs a patterned ground: on with the checker, off with a line on plain
    assert ("video speed term off" in log) == (robot == "pupper")
    assert "distance model: 2 updates on the demonstration, the other clips and one rollout" in log
    assert ("video speed term: up to 0.3 of the reward" in log) == (robot == "laikago")
    if robot == "laikago":   # the probe: at the start, at every evaluation (the curve) and in the report
        assert "alignment probe: 22 graded rollouts" in p.stdout, p.stdout[-2000:]
        assert "reward-score rank corr" in p.stdout
        align = report["reward_alignment"]
        assert -1 <= align["reward_alignment"] <= 1 and 0 <= align["reward_standing"] <= 1
        assert [row[0] for row in align["curve"]] == [0, 2], align["curve"]   # warm start, iteration 2
    # resume continues from iteration 2, also from a checkpoint that holds options of retired features
    # (in the training options and the distance model's config): they are dropped
    data["config"].update(RETIRED)
    data["reward"]["config"].update(speed_strip=False, pair_weights={**data["reward"]["config"]["pair_weights"],
                                                                     "speed_shift": 0.25, "ground_shift": 1.0})
    data["reward"]["rollouts"] = 2
    assert data.pop("speed_term") == "gate"   # as before the gate: the run says its reward changes form
    checkpoint.save(run_dir / checkpoint.LATEST, data)
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", "3")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "resumed at iteration 2" in p.stdout and "it     3/3" in p.stdout
    assert ("continues with the term as a gate" in p.stdout) == (robot == "laikago"), p.stdout[-2000:]
    data = checkpoint.load(run_dir)
    assert data["speed_term"] == "gate"
    assert data["iteration"] == 3 and data["config"]["ground"] == ("plain" if robot == "pupper" else "checker")
    assert not set(RETIRED) & set(data["config"]) and "speed_strip" not in data["reward"]["config"]
    assert not {"speed_shift", "ground_shift"} & set(data["reward"]["config"]["pair_weights"])
    assert not all(torch.equal(net2[k], v) for k, v in data["reward"]["net"].items())   # it learns all run long
    # export, load, act
    out = tmp_path / "policy.pt"
    p = run("virl_quad.export", str(run_dir), "--out", str(out))
    assert p.returncode == 0, p.stderr[-2000:]
    policy = load_policy(out)
    assert policy.spec.name == robot and policy.meta["iterations"] == 3
    action = policy.act(np.zeros(policy.meta["observation"]["size"], np.float32))
    assert action.shape == (14,) and policy.action_size == 14 and np.all(np.isfinite(action))   # TG by default
    # a run whose demonstration was rendered otherwise (an older renderer) is not resumed
    import dataclasses

    from virl_quad import demo as demo_lib
    from virl_quad.demo.render import save_npz

    saved = demo_lib.load(str(run_dir / "demo.npz"), robot)
    save_npz(dataclasses.replace(saved, frames=255 - saved.frames), run_dir / "demo.npz")
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", "4")
    assert p.returncode == 2 and "renders" in p.stderr and "Traceback" not in p.stderr, p.stderr[-2000:]


def test_tiny_tg_run_exports_and_serves(tmp_path: Path) -> None:
    """--tg: the policy is a residual on the trajectory generator fitted to the demonstration video; the
    run, its resume, its export and the policy server all use that TG (14 actions)."""
    from virl_quad import robots
    from virl_quad.motion.gaits import gait_params
    from virl_quad.deploy import protocol as P
    from virl_quad.deploy.serve import PolicyRunner
    from virl_quad.policy.tg import TGParams
    from virl_quad.training.prior import gait_tg
    from virl_quad.training.prior_check import VARIANT_KEYS, with_variant

    run_dir = tmp_path / "run"
    p = run("virl_quad.train", "--robot", "pupper", "--tg", "--reward", "oracle", "--iterations", "1",
            "--run-dir", str(run_dir), *TINY, "--prior-from", "video")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "trajectory generator: fitted to the video" in p.stdout, p.stdout[-2000:]
    fit = json.loads((run_dir / "prior_fit.json").read_text())
    assert (run_dir / "prior_fit.png").is_file() and fit["tg"]
    assert "physics check, finalist 0" in p.stdout and fit["physics_check"][0]["episodes"] >= 1
    kept = TGParams.from_dict(fit["finalists"][fit["kept_finalist"]]["tg"])
    if fit["variant"] is not None:   # its teacher went against the video's ground, or too slowly: a variant
        kept = with_variant(robots.get("pupper"), kept, *(fit["variant"][k] for k in VARIANT_KEYS))
        assert "hind feet" in p.stdout and any(r.get("kept") for r in fit["travel_check"])
    assert TGParams.from_dict(fit["tg"]) == kept
    # the oracle's run has no anchor (pull 0): a pull typed on resume has nothing to pull towards
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", "2", "--prior-pull", "0.05")
    assert p.returncode == 2 and "keeps no warm start" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", "2")
    assert p.returncode == 0 and "resumed at iteration 1" in p.stdout, p.stderr[-2000:]
    out = tmp_path / "tg.pt"
    p = run("virl_quad.export", str(run_dir), "--out", str(out))
    assert p.returncode == 0, p.stderr[-2000:]
    policy = load_policy(out)
    spec = robots.get("pupper")
    want = gait_tg(spec, gait_params("pupper", "trot"))
    tg = policy.contract.tg
    assert policy.action_size == 14 and tg.offsets == want.offsets and tg.duty == pytest.approx(want.duty)
    runner = PolicyRunner(policy)
    cmd, reason = runner.handle(P.encode_state(P.RobotState.standing(spec), 1, active=True))
    assert reason == "" and np.all(np.isfinite(P.decode(cmd).body.q_target))
    assert runner.last_action.shape == (14,)


def test_resume_keeps_the_anchor_and_takes_a_typed_pull(tmp_path: Path) -> None:
    """The warm start's weights travel in the checkpoint; --prior-pull typed on resume changes the pull only."""
    run_dir = tmp_path / "run"
    p = run("virl_quad.train", "--robot", "pupper", "--reward", "prior", "--iterations", "1",
            "--run-dir", str(run_dir), *TINY)
    assert p.returncode == 0, p.stderr[-2000:]
    saved = checkpoint.load(run_dir)["anchor"]
    assert saved["pull"] == pytest.approx(0.01) and saved["weights"]
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", "2", "--prior-pull", "0.1")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "pull 0.1 per PPO update (the checkpoint's: 0.01)" in p.stdout
    anchor = checkpoint.load(run_dir)["anchor"]
    assert anchor["pull"] == pytest.approx(0.1)
    assert all(torch.equal(a, b) for a, b in zip(anchor["weights"], saved["weights"]))


def test_kill_9_loses_at_most_one_checkpoint_interval(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "virl_quad.train", "--robot", "pupper", "--iterations", "200",
           "--run-dir", str(run_dir), *TINY]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 240
        while time.time() < deadline:
            ck = run_dir / checkpoint.LATEST
            if ck.exists() and checkpoint.load(run_dir)["iteration"] >= 3:
                break
            time.sleep(0.5)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    saved = checkpoint.load(run_dir)["iteration"]  # the file is whole: it was written atomically
    assert saved >= 3
    assert not list(run_dir.glob(".*.tmp")) or True  # a temp file may be left; it is never read
    p = run("virl_quad.train", "--resume", str(run_dir), "--iterations", str(saved + 1))
    assert p.returncode == 0, p.stderr[-2000:]
    assert f"resumed at iteration {saved}" in p.stdout


@pytest.mark.parametrize("args, message", [
    (["--robot", "spot"], "unknown robot"),
    (["--demo", "/nonexistent/walk.mp4"], "walk.mp4"),
    (["--demo", "moonwalk"], "moonwalk"),
    (["--init-std", "0"], "--init-std"),
    (["--init-std", "nan"], "--init-std"),
    (["--warm-start-rounds", "-1"], "--warm-start-rounds"),
    (["--warm-start-steps", "0"], "--warm-start-steps"),
    (["--critic-warmup", "-2"], "--critic-warmup"),
    (["--prior-pull", "1"], "--prior-pull"),
    (["--oracle-speed-weight", "1.5"], "--oracle-speed-weight"),
    (["--oracle-speed-weight", "nan"], "--oracle-speed-weight"),
    (["--video-speed-weight", "-0.1"], "--video-speed-weight"),
    (["--video-speed-weight", "nan"], "--video-speed-weight"),
    (["--reward-pretrain", "-1"], "--reward-pretrain"),
])
def test_bad_input_one_line_exit_2(args: list[str], message: str, tmp_path: Path) -> None:
    p = run("virl_quad.train", *TINY, "--iterations", "1", "--run-dir", str(tmp_path / "r"), *args)   # args last: they win
    assert p.returncode == 2
    assert message in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_bad_resume_and_corrupt_checkpoint(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    p = run("virl_quad.train", "--resume", str(empty))
    assert p.returncode == 2 and "no checkpoint" in p.stderr and "Traceback" not in p.stderr
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / checkpoint.LATEST).write_bytes(b"PK\x03\x04 this is not a checkpoint")
    p = run("virl_quad.train", "--resume", str(bad))
    assert p.returncode == 2 and "cannot be read" in p.stderr and "Traceback" not in p.stderr
    p = run("virl_quad.export", str(bad), "--out", str(tmp_path / "x.pt"))
    assert p.returncode == 2 and "Traceback" not in p.stderr


def test_reward_choice_is_checked() -> None:
    p = run("virl_quad.train", "--reward", "bogus")
    assert p.returncode == 2 and "invalid choice" in p.stderr
    assert p.stderr.startswith("error: ") and len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_ctrl_c_checkpoints_without_a_traceback(tmp_path: Path, wait_for_checkpoint) -> None:
    """A real SIGINT to the whole process group, as a terminal's Ctrl-C sends it: the env worker
    stays quiet, the trainer writes its checkpoint and exits 130 with one line."""
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "virl_quad.train", "--robot", "pupper", "--iterations", "500",
           "--run-dir", str(run_dir), *TINY]
    # SIGINT as a terminal leaves it (a shell ignores it in background jobs, and children inherit that)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        wait_for_checkpoint(proc, run_dir, 2)
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, (out[-1500:], err[-1500:])
    assert "Traceback" not in out + err and "KeyboardInterrupt" not in out + err, err[-3000:]
    assert err.strip() == "interrupted", err
    assert "interrupted: checkpoint written at iteration" in out
    assert checkpoint.load(run_dir)["iteration"] >= 2


def test_torchrun_is_refused_in_one_line(tmp_path: Path) -> None:
    """Under torchrun (WORLD_SIZE > 1) every rank would learn its own distance model: refused."""
    p = subprocess.run([sys.executable, "-m", "virl_quad.train", "--run-dir", str(tmp_path / "run")],
                       capture_output=True, text=True, timeout=120, env={**os.environ, "WORLD_SIZE": "2"})
    assert p.returncode == 2 and p.stderr.startswith("error: multi-GPU training"), p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and not (tmp_path / "run").exists()
