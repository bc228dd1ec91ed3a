"""The off-policy episode store: byte bound, eviction of the oldest, rollout splitting."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad.reward import EpisodeStore

FRAME_BYTES = 2 * 48 * 48


def ep(T: int, value: int) -> tuple[np.ndarray, np.ndarray]:
    return np.full((T, 48, 48), value, np.uint8), np.full((T, 48, 48), 255 - value, np.uint8)


def test_bytes_per_frame_and_bound_with_oldest_evicted():
    store = EpisodeStore(max_bytes=25 * FRAME_BYTES)
    assert store.bytes_per_frame == FRAME_BYTES
    for v in range(5):
        store.add_episode(*ep(10, v))
        assert store.nbytes <= store.max_bytes
    assert len(store) == 2 and store.episodes_evicted == 3
    assert [int(store.episode(i)[0][0, 0, 0]) for i in range(len(store))] == [3, 4]   # newest kept
    assert store.bytes_per_frame == FRAME_BYTES and store.num_frames == 20
    assert store.mean_episode_length == 10.0
    with pytest.raises(ValueError, match="exceeds max_bytes"):
        EpisodeStore(max_bytes=FRAME_BYTES * 5, max_episode_frames=100).add_episode(*ep(6, 0))


def test_add_episode_checks_and_copies():
    store = EpisodeStore(max_bytes=10**7)
    a, e = ep(5, 7)
    store.add_episode(a, e)
    a[:] = 0                                             # the store holds its own copy
    assert store.episode(0)[0][0, 0, 0] == 7
    with pytest.raises(ValueError, match="differ in shape"):
        store.add_episode(*ep(5, 1)[:1], ep(4, 1)[1])
    with pytest.raises(ValueError, match="shape"):
        store.add_episode(np.zeros((5, 32, 32), np.uint8), np.zeros((5, 32, 32), np.uint8))
    store.add_episode(np.full((3, 48, 48), 0.5, np.float32), np.zeros((3, 48, 48), np.float32))
    assert store.episode(1)[0].dtype == np.uint8 and store.episode(1)[0][0, 0, 0] == 128


def test_add_rollout_splits_on_dones_and_joins_across_rollouts():
    store = EpisodeStore(max_bytes=10**8)
    T, N = 6, 3
    t_idx = np.arange(T)[:, None, None, None]
    agent = np.broadcast_to(t_idx * 10 + np.arange(N)[None, :, None, None], (T, N, 48, 48)).astype(np.uint8)
    dones = np.zeros((T, N), bool)
    dones[2, 0] = True                                   # env 0: frames 0-2 end an episode
    dones[5, 1] = True                                   # env 1: the whole rollout is one episode
    assert store.add_rollout(agent, agent, dones) == 2
    assert sorted(store.lengths().tolist()) == [3, 6]
    assert store.num_frames == T * N                     # open pieces (env 0: 3, env 2: 6) are counted
    seqs = store.sequences()                             # open episodes can be sampled already
    assert sorted(a.shape[0] for a, _ in seqs) == [3, 3, 6, 6]
    open_env2 = [a for a, _ in seqs if a.shape[0] == 6 and a[0, 0, 0] == 2]
    assert len(open_env2) == 1 and open_env2[0][:, 0, 0].tolist() == [10 * t + 2 for t in range(T)]
    # the next rollout continues the open episodes of env 0 and env 2
    dones2 = np.zeros((T, N), bool)
    dones2[0, 2] = True
    store.add_rollout(agent, agent, dones2)
    assert sorted(store.lengths().tolist()) == [3, 6, 7]
    store.flush()
    assert sorted(store.lengths().tolist()) == [3, 5, 6, 6, 7, 9]  # env 0: 3+6, env 1: 6, env 2: 5
    with pytest.raises(ValueError, match="dones"):
        store.add_rollout(agent, agent, np.zeros((T, N + 1), bool))


def test_long_episodes_are_cut_and_open_pieces_respect_the_bound():
    store = EpisodeStore(max_bytes=40 * FRAME_BYTES, max_episode_frames=8)
    store.add_episode(*ep(20, 1))
    assert store.lengths().tolist() == [8, 8, 4]
    store = EpisodeStore(max_bytes=10 * FRAME_BYTES, max_episode_frames=100)
    frames = np.zeros((6, 4, 48, 48), np.uint8)
    store.add_rollout(frames, frames, np.zeros((6, 4), bool))   # 24 open frames > budget of 10
    assert store.nbytes <= store.max_bytes


def test_open_episodes_train_the_model_before_any_episode_ends(small_cfg, demo, agent_episode):
    """A first rollout shorter than every episode still gives agent data (incl. expert-vs-agent pairs)."""
    from virl_quad.reward import RewardConfig, build_reward

    agent, expert = agent_episode(0, T=24)
    rollout = np.stack([agent, agent[::-1]], axis=1), np.stack([expert, expert], axis=1)
    for variant in ("virl", "gaifo"):
        rm = build_reward(RewardConfig.make(**{**small_cfg.to_dict(), "variant": variant}), demo, seed=0)
        rm.add_rollout(*rollout, np.zeros((24, 2), bool))
        assert len(rm.dataset) == 0 and len(rm.dataset.sequences()) == 2
        assert rm.update(2)["total"] > 0
    rm = build_reward(small_cfg, demo, seed=0)
    rm.add_rollout(*rollout, np.zeros((24, 2), bool))
    rng = np.random.default_rng(0)
    assert any("expert_vs_agent" in rm.sampler.draw(rng).kinds for _ in range(20))
