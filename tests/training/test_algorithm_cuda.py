"""VirlPPO on a GPU (``--device cuda``): an update with the anchor and the frozen-actor warm-up runs
there, the in-run evaluations' wrapper feeds it numpy observations, and the actor it trained
exports to a TorchScript policy that the CPU runs with the same actions. Skipped where torch sees
no CUDA device."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from virl_quad.export import default_contract, export_actor, fresh_actor
from virl_quad.policy_io import load_policy
from virl_quad.training.algorithm import VirlPPO
from virl_quad.training.config import TrainArgs, rsl_rl_config
from virl_quad.training.runner import actor_policy

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

C = default_contract("pupper", demo_frames=50)      # the policy contract the export checks against
N_ENVS = 8


class _Env:
    """The smallest VecEnv rsl-rl's PPO constructor reads (no simulation is stepped here)."""

    num_envs, num_actions, device = N_ENVS, C.action_size, "cuda"

    def get_observations(self) -> TensorDict:
        sizes = {"policy": C.observation_size, "privileged": 4}
        return TensorDict({k: torch.zeros(N_ENVS, n, device="cuda") for k, n in sizes.items()},
                          batch_size=[N_ENVS], device="cuda")


def _ppo() -> VirlPPO:
    cfg = rsl_rl_config(TrainArgs.make(hidden="32,16"))
    cfg["algorithm"]["class_name"] = VirlPPO
    cfg["multi_gpu"] = None
    env = _Env()
    with contextlib.redirect_stdout(io.StringIO()):
        return VirlPPO.construct_algorithm(env.get_observations(), env, cfg, "cuda")


def _fill(alg: VirlPPO, steps: int = 16) -> None:
    """Store a rollout of random observations and rewards on the GPU."""
    gen = torch.Generator(device="cuda").manual_seed(0)
    alg.train_mode()
    obs = None
    for _ in range(steps):
        obs = TensorDict({"policy": torch.randn(N_ENVS, C.observation_size, generator=gen, device="cuda"),
                          "privileged": torch.randn(N_ENVS, 4, generator=gen, device="cuda")},
                         batch_size=[N_ENVS], device="cuda")
        with torch.inference_mode():
            alg.act(obs)
            super(VirlPPO, alg).process_env_step(obs, torch.randn(N_ENVS, generator=gen, device="cuda"),
                                                 torch.zeros(N_ENVS, device="cuda"),
                                                 {"time_outs": torch.zeros(N_ENVS, device="cuda")})
    with torch.inference_mode():
        super(VirlPPO, alg).compute_returns(obs)


def test_an_update_on_the_gpu_exports_a_policy_the_cpu_runs(tmp_path: Path) -> None:
    alg = _ppo()
    assert next(alg.actor.parameters()).device.type == "cuda"
    alg.anchor_actor(0.01)
    alg.freeze_actor(1)
    _fill(alg)
    alg.update()                                    # the critic alone
    before = {k: v.clone() for k, v in alg.actor.state_dict().items()}
    _fill(alg)
    alg.update()                                    # then the actor too, pulled towards its start
    assert any(not torch.equal(before[k], v) for k, v in alg.actor.state_dict().items())
    assert all(torch.isfinite(p).all() for p in alg.actor.parameters())

    actor = fresh_actor(C, hidden=(32, 16))          # as the run's end exports it: from the saved weights
    actor.load_state_dict({k: v.cpu() for k, v in alg.actor.state_dict().items()})
    policy = load_policy(export_actor(actor, "pupper", tmp_path / "p.pt", C, demo={"num_frames": 50}))
    x = np.random.default_rng(0).normal(size=(16, C.observation_size)).astype(np.float32)
    alg.actor.eval()
    with torch.inference_mode():
        on_gpu = alg.actor(TensorDict({"policy": torch.from_numpy(x).cuda()}, batch_size=[16])).cpu().numpy()
    on_cpu = np.stack([policy.act(row) for row in x])
    np.testing.assert_allclose(on_cpu, on_gpu, atol=1e-4)
    act = actor_policy(alg.actor)                   # what the in-run evaluations drive the env with
    np.testing.assert_allclose(act({"policy": x[0]}), on_gpu[0], atol=1e-5)
    assert np.abs(on_gpu).max() > 1e-3
