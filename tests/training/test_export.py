"""Exported policies: TorchScript equals eager, metadata is checked against the robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from virl_quad.export import default_contract, export_actor, fresh_actor
from virl_quad.policy_io import load_policy

C = default_contract("pupper", demo_frames=50)      # 46 observations, 12 actions
N = C.observation_size


def _export(actor, path: Path, **kw) -> Path:
    return export_actor(actor, "pupper", path, C, **kw)


def test_eager_and_torchscript_agree(tmp_path: Path) -> None:
    actor = fresh_actor(C, seed=3)
    # give the normaliser non-trivial statistics, as after training
    actor.obs_normalizer.train()
    actor.update_normalization(TensorDict({"policy": torch.randn(256, N) * 3 + 1}, batch_size=[256]))
    actor.eval()
    policy = load_policy(_export(actor, tmp_path / "p.pt", demo={"num_frames": 50}))
    x = np.random.default_rng(0).normal(size=(32, N)).astype(np.float32)
    with torch.inference_mode():
        eager = actor(TensorDict({"policy": torch.from_numpy(x)}, batch_size=[32])).numpy()
    with torch.inference_mode():
        scripted = np.stack([policy.module(torch.from_numpy(row)[None])[0].numpy() for row in x])
    np.testing.assert_allclose(scripted, eager, atol=1e-6)
    assert np.abs(eager).max() > 0.01
    # the numpy fast path the policy server uses reproduces the TorchScript module
    assert policy.fast is not None
    np.testing.assert_allclose(np.stack([policy.act(row) for row in x]), scripted, atol=1e-5)


def test_fast_path_only_for_the_exported_structure(tmp_path: Path) -> None:
    path = _export(fresh_actor(C), tmp_path / "p.pt")
    assert load_policy(path, numpy_fast_path=False).fast is None

    class Other(torch.nn.Module):   # right sizes, different computation: must stay on torch
        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return torch.tanh(x[:, :12]) * 0.5

    torch.jit.script(Other()).save(str(path))
    policy = load_policy(path)
    assert policy.fast is None
    x = np.linspace(-1, 1, N).astype(np.float32)
    np.testing.assert_allclose(policy.act(x), np.tanh(x[:12]) * 0.5, atol=1e-6)


def test_metadata_mismatch_is_refused(tmp_path: Path) -> None:
    path = _export(fresh_actor(C), tmp_path / "p.pt")
    with pytest.raises(ValueError, match="not 'laikago'"):
        load_policy(path, robot="laikago")
    meta = json.loads(path.with_suffix(".json").read_text())
    for key, value, match in [("joint_names", list(reversed(meta["joint_names"])), "joint order"),
                              ("control_dt", 0.01, "control period"),
                              ("default_pose", [0.0] * 12, "default_pose")]:
        bad = dict(meta, **{key: value})
        path.with_suffix(".json").write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=match):
            load_policy(path)
    path.with_suffix(".json").write_text(json.dumps(meta))
    assert load_policy(path).spec.name == "pupper"


def test_not_torchscript_and_missing(tmp_path: Path) -> None:
    path = _export(fresh_actor(C), tmp_path / "p.pt")
    path.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="not a TorchScript policy"):
        load_policy(path)
    with pytest.raises(ValueError, match="does not exist"):
        load_policy(tmp_path / "none.pt")
    text = tmp_path / "notes.md"               # any other file, with no metadata beside it
    text.write_text("# not a policy\n")
    with pytest.raises(ValueError, match="notes.md is not a TorchScript policy"):
        load_policy(text)


def test_policy_rejects_nan_observation(tmp_path: Path) -> None:
    policy = load_policy(_export(fresh_actor(C), tmp_path / "p.pt"))
    obs = np.zeros(N, np.float32)
    obs[3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        policy.act(obs)


def test_fast_path_for_a_normaliser_with_tiny_std(tmp_path: Path) -> None:
    """An input that barely varies in the data (std 1e-4, as a behaviour-cloned policy's) makes
    the actor's outputs huge far off that scale; the fast path is still taken, and matches on
    the policy's own input scale."""
    actor = fresh_actor(C, seed=1)
    actor.obs_normalizer.train()
    data = torch.randn(512, N) * 0.3
    data[:, 2] = 1e-4 * torch.randn(512) - 1.0          # gravity z: almost constant
    actor.update_normalization(TensorDict({"policy": data}, batch_size=[512]))
    actor.eval()
    policy = load_policy(_export(actor, tmp_path / "p.pt", demo={"num_frames": 50}))
    assert policy.fast is not None
    x = (data[:64] * 1.5).numpy()
    with torch.inference_mode():
        want = policy.module(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(np.stack([policy.act(row) for row in x]), want, rtol=1e-5, atol=1e-5)


def test_shipped_policies_run_on_the_fast_path() -> None:
    shipped = sorted((Path(__file__).resolve().parents[2] / "policies").glob("*.pt"))
    for path in shipped:
        assert load_policy(path).fast is not None, path
