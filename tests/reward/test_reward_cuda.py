"""The distance model on a GPU (``--device cuda``): the same rewards as on the CPU, training there
without repacking warnings, and files the CPU tools read. Skipped where torch sees no CUDA device."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from virl_quad.reward import VARIANTS, RewardConfig, build_reward, load_reward
from virl_quad.reward.reward import from_state_dict

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


@pytest.fixture(autouse=True)
def _full_fp32():
    """Compare at full float32: TensorFloat-32 (cuDNN's default for convolutions and LSTMs on
    Ampere and later) rounds inputs to 10 mantissa bits, a difference from the CPU that is not a
    device bug."""
    keep = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    yield
    torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = keep


def _trained(variant: str, small_cfg, demo, other, agent_episode):
    cfg = RewardConfig.make(**{**small_cfg.to_dict(), "variant": variant})
    rm = build_reward(cfg, demo, [other], seed=3)
    for s in range(3):
        rm.add_episode(*agent_episode(s))
    rm.update(2)
    return rm


def _rollout(T: int = 12, N: int = 3):
    rng = np.random.default_rng(5)
    agent = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    expert = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    dones = np.zeros((T, N), bool)
    dones[6, 1] = True
    return agent, expert, dones


@pytest.mark.parametrize("variant", VARIANTS)
def test_rewards_on_the_gpu_equal_the_cpu_ones(variant, small_cfg, demo, other, agent_episode):
    cpu = _trained(variant, small_cfg, demo, other, agent_episode)
    gpu = from_state_dict(cpu.state_dict(), "cuda")
    agent, expert, dones = _rollout()
    on_cpu = cpu.recompute(agent, expert, dones, cpu.stream_state(3))
    on_gpu = gpu.recompute(agent, expert, dones, gpu.stream_state(3))
    assert on_gpu.device.type == "cuda"
    torch.testing.assert_close(on_gpu.cpu(), on_cpu, atol=1e-4, rtol=1e-4)
    state, streamed = gpu.stream_state(3), []
    reset = np.zeros(3, bool)
    for t in range(len(agent)):                     # streaming agrees with the batch form there too
        r, state = gpu.stream_step(agent[t], expert[t], state, reset)
        streamed.append(r)
        reset = dones[t]
    # cuDNN runs a whole sequence and single steps through different kernels, so the two differ by
    # float32 rounding; the tolerance is the CPU-against-GPU one (the CPU test holds them to 1e-5)
    torch.testing.assert_close(torch.stack(streamed), on_gpu, atol=1e-4, rtol=1e-4)
    assert cpu.d2_scale() == pytest.approx(gpu.d2_scale(), rel=1e-3)


def test_training_on_the_gpu_keeps_the_lstm_packed_and_saves_for_the_cpu(tmp_path: Path, small_cfg, demo, other,
                                                                          agent_episode):
    rm = build_reward(small_cfg, demo, [other], seed=3, device="cuda")
    assert rm.reward_net is not rm.net                       # the slow copy, deep-copied on the GPU
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for s in range(3):
            rm.add_episode(*agent_episode(s))
        logs = rm.update(3)
        agent, expert, dones = _rollout()
        r = rm.recompute(agent, expert, dones, rm.stream_state(3))
    repacked = [str(w.message) for w in seen if "contiguous chunk" in str(w.message)]
    assert not repacked, repacked                            # each call would repack the LSTM's weights
    assert np.isfinite(logs["total"]) and ((r > 0) & (r <= 1)).all()
    rm.save(tmp_path / "reward.pt")
    back = load_reward(tmp_path / "reward.pt")               # on the CPU, as evaluate and the benches load it
    assert next(back.net.parameters()).device.type == "cpu"
    torch.testing.assert_close(back.recompute(agent, expert, dones, back.stream_state(3)), r.cpu(),
                               atol=1e-4, rtol=1e-4)
