"""Behaviour cloning of the privileged tracker (virl_quad.distill): learns, exports, fails cleanly."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from virl_quad import demo as demo_lib
from virl_quad import envs
from virl_quad.distill import DistillArgs, main
from virl_quad.export import fresh_actor
from virl_quad.policy_io import load_policy
from virl_quad.training.dagger import fit, gather

ROOT = Path(__file__).resolve().parents[2]


def _mse(actor, obs: np.ndarray, act: np.ndarray) -> float:
    with torch.inference_mode():
        pred = actor(TensorDict({"policy": torch.from_numpy(obs)}, batch_size=[len(obs)])).numpy()
    return float(np.mean((pred - act) ** 2))


def test_gathered_pairs_are_the_tracker_and_the_fit_learns_them() -> None:
    args = DistillArgs(steps=400, epochs=30, randomize=False)
    d = demo_lib.load("trot", "pupper")
    pair = tuple(envs.make("pupper", demo=d, randomize=False, render=False, rsi=r) for r in (False, True))
    try:
        obs, act, stats = gather(pair, None, 1.0, 400, np.random.default_rng(0), args, 0)
    finally:
        for e in pair:
            e.close()
    contract = pair[0].unwrapped.contract
    assert obs.shape == (400, contract.observation_size) and act.shape == (400, 12)
    assert np.all(np.abs(act) <= 2.0) and np.ptp(act, axis=0).max() > 0.1   # clipped, and a gait, not a pose
    assert stats["falls"] == 0
    actor = fresh_actor(contract, seed=0)
    before = _mse(actor, obs, act)
    fit(actor, obs, act, args, torch.Generator().manual_seed(0))
    after = _mse(actor, obs, act)
    print(f"\nBC on 400 tracker steps: mse {before:.4f} -> {after:.4f}")
    assert after < 0.2 * before
    # the normaliser holds the data's statistics (exported with the policy)
    np.testing.assert_allclose(actor.obs_normalizer.mean.numpy(), obs.mean(0), atol=1e-5)


def test_tiny_distillation_exports_a_loadable_policy(tmp_path: Path) -> None:
    out = tmp_path / "bc.pt"
    assert main(DistillArgs(out=str(out), rounds=2, steps=200, epochs=3, randomize=False, quiet=True)) == 0
    policy = load_policy(out)
    meta = json.loads(out.with_suffix(".json").read_text())
    assert "not VIRL" in meta["reward"] and len(meta["distill_rounds"]) == 2
    assert meta["demo"]["num_frames"] == 100 and policy.contract.with_phase and policy.contract.tg is None
    assert policy.contract.phase_hz == 0.5                      # one cycle per 100 frames at 50 Hz
    a = policy.act(np.zeros(policy.obs_size, np.float32))
    assert a.shape == (12,) and np.all(np.isfinite(a))


def test_cli_bad_input_is_one_line_exit_2(tmp_path: Path) -> None:
    for bad in (["--robot", "spot"], ["--rounds", "0"], ["--randomize", "--max-latency", "-1"]):
        r = subprocess.run([sys.executable, "-m", "virl_quad.distill", *bad, "--out", str(tmp_path / "x.pt")],
                           cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert r.returncode == 2, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
