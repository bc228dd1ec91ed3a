"""Shared fixtures for the reward tests: small synthetic clips (moving shapes) and a fast config."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from virl_quad.reward import RewardConfig


def _blob_clip(T: int, phase: float = 0.0, speed: float = 1.0, radius: float = 6.0,
              shape: str = "disc") -> np.ndarray:
    """[T, 48, 48] uint8: a bright disc (or square) circling on a dark background."""
    yy, xx = np.mgrid[0:48, 0:48]
    out = np.empty((T, 48, 48), dtype=np.uint8)
    for t in range(T):
        cx = 24 + 12 * np.sin(speed * t * 0.35 + phase)
        cy = 24 + 9 * np.cos(speed * t * 0.35 + phase)
        if shape == "disc":
            on = (xx - cx) ** 2 + (yy - cy) ** 2 < radius ** 2
        else:
            on = (np.abs(xx - cx) < radius) & (np.abs(yy - cy) < radius)
        out[t] = np.where(on, 220, 30)
    return out


@pytest.fixture(autouse=True)
def _threads():
    """Keep the tests light on a 2-core machine."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def demo() -> np.ndarray:
    return _blob_clip(60)


@pytest.fixture
def other() -> np.ndarray:
    return _blob_clip(50, phase=1.0, speed=1.7, shape="square")


@pytest.fixture
def small_cfg() -> RewardConfig:
    """Paper architecture, smaller batches and windows so a test update takes milliseconds."""
    return RewardConfig.make(batch_pairs=8, window_min=4, window_max=10, same_source_max_offset=2, ae_frames=32,
                        paint_background=False)   # synthetic blobs, not renders: frames as they are


def _agent_episode(seed: int, T: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """An 'agent' episode (another speed and phase) with its matching expert frames."""
    rng = np.random.default_rng(seed)
    agent = _blob_clip(T, phase=float(rng.uniform(0, 6)), speed=float(rng.uniform(0.5, 1.5)))
    expert = _blob_clip(T, phase=0.0)
    return agent, expert


@pytest.fixture
def blob_clip():
    """The clip maker: blob_clip(T, phase=0, speed=1, radius=6, shape='disc'|'square')."""
    return _blob_clip


@pytest.fixture
def agent_episode():
    """The agent-episode maker: agent_episode(seed, T=40) -> (agent, expert) uint8 [T, 48, 48]."""
    return _agent_episode


@pytest.fixture
def trained_rm(small_cfg, demo, other):
    """A reward model with a few agent episodes and a few updates (weights no longer at init)."""
    from virl_quad.reward import build_reward

    rm = build_reward(small_cfg, demo, [other], seed=3)
    for s in range(4):
        rm.add_episode(*_agent_episode(s))
    rm.update(3)
    return rm
