"""Each pair constructor yields the label and the transformation it claims; batches are built on the fly."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad.reward import NEGATIVE_PAIRS, POSITIVE_PAIRS, RewardConfig, build_reward
from virl_quad.reward import pairs


@pytest.fixture
def x() -> np.ndarray:
    """9 frames (L = 8 plus the spare), each with a distinct constant value, so order is visible."""
    return (np.arange(9, dtype=np.float32)[:, None, None] / 10.0) * np.ones((1, 48, 48), np.float32)


def ids(seq: np.ndarray) -> list[int]:
    """Which frame of ``x`` each frame of ``seq`` is."""
    return [int(round(v * 10)) for v in seq[:, 0, 0]]


def test_gaussian_noise(x):
    rng = np.random.default_rng(0)
    a, b, y = pairs.gaussian_noise(x, rng, sigma=0.05)
    assert y == 1 and a.shape == b.shape == (8, 48, 48)
    assert ids(a) == list(range(8))
    diff = (b - a)[:, 5:40, 5:40]                       # away from the clip at 0 for frame 0
    assert 0.04 < diff[1:].std() < 0.06 and abs(diff[1:].mean()) < 0.01
    assert b.min() >= 0 and b.max() <= 1


def test_out_of_sync(x):
    for seed in range(4):
        a, b, y = pairs.out_of_sync(x, np.random.default_rng(seed))
        assert y == 1 and a.shape[0] == b.shape[0] == 8
        assert sorted([ids(a), ids(b)]) == [list(range(0, 8)), list(range(1, 9))]


def test_duplicate_first_and_last(x):
    for seed in range(4):
        a, b, y = pairs.duplicate_first(x, np.random.default_rng(seed))
        assert y == 1
        assert sorted([ids(a), ids(b)]) == [[0, 0, 1, 2, 3, 4, 5, 6], list(range(8))]
        a, b, y = pairs.duplicate_last(x, np.random.default_rng(seed))
        assert y == 1
        assert sorted([ids(a), ids(b)]) == [[0, 1, 2, 3, 4, 5, 6, 6], list(range(8))]


def test_same_source_and_cross_source():
    w1, w2 = np.zeros((10, 48, 48), np.float32), np.ones((12, 48, 48), np.float32)
    a, b, y = pairs.same_source(w1, w2, 8)
    assert y == 1 and a.shape[0] == b.shape[0] == 8
    a, b, y = pairs.expert_vs_agent(w1, w2, 8)
    assert y == 0 and (a == 0).all() and (b == 1).all()
    a, b, y = pairs.other_clip(w1, w2, 8)
    assert y == 0 and (a == 0).all() and (b == 1).all()


def test_reversed(x):
    a, b, y = pairs.reversed_order(x, np.random.default_rng(0))
    assert y == 0 and ids(a) == list(range(8)) and ids(b) == list(range(7, -1, -1))


def test_frozen_frame(x):
    seen = set()
    for seed in range(20):
        a, b, y = pairs.frozen_frame(x, np.random.default_rng(seed))
        assert y == 0 and ids(a) == list(range(8))
        assert len(set(ids(b))) == 1 and len(ids(b)) == 8
        seen.add(ids(b)[0])
    assert len(seen) > 3                                # the frozen frame is chosen at random


def test_shuffled_one_and_both(x):
    for seed in range(20):
        a, b, y = pairs.shuffled_one(x, np.random.default_rng(seed))
        assert y == 0 and ids(a) == list(range(8))
        assert sorted(ids(b)) == list(range(8)) and ids(b) != list(range(8))
        a, b, y = pairs.shuffled_both(x, np.random.default_rng(seed))
        assert y == 0 and sorted(ids(a)) == sorted(ids(b)) == list(range(8))
        assert ids(a) != list(range(8)) and ids(b) != list(range(8)) and ids(a) != ids(b)


def test_sampler_batches_half_positive_and_every_kind(small_cfg, demo, other, agent_episode):
    rm = build_reward(small_cfg, demo, [other], seed=0)
    rng = np.random.default_rng(0)
    kinds = set()
    batch = rm.sampler.draw(rng)
    assert "expert_vs_agent" not in batch.kinds               # no agent data yet
    for s in range(3):
        rm.add_episode(*agent_episode(s))
    stored = [rm.dataset.episode(i)[0].copy() for i in range(len(rm.dataset))]
    nbytes = rm.dataset.nbytes
    for _ in range(40):
        batch = rm.sampler.draw(rng)
        B = small_cfg.pairs.batch_pairs
        assert batch.a.shape == batch.b.shape and batch.a.shape[1] == B and batch.a.shape[2:] == (48, 48)
        assert small_cfg.pairs.window_min <= batch.a.shape[0] <= small_cfg.pairs.window_max
        assert batch.y.tolist() == [1.0] * (B // 2) + [0.0] * (B // 2)
        assert batch.a.dtype == np.float32 and 0 <= batch.a.min() and batch.a.max() <= 1
        for k, lab in zip(batch.kinds, batch.y):
            assert (k in POSITIVE_PAIRS) == (lab == 1) and (k in NEGATIVE_PAIRS) == (lab == 0)
        kinds |= set(batch.kinds)
    assert kinds == set(POSITIVE_PAIRS) | set(NEGATIVE_PAIRS)
    # augmentations are applied on the fly, never stored
    assert rm.dataset.nbytes == nbytes and len(rm.dataset) == len(stored)
    assert all((rm.dataset.episode(i)[0] == stored[i]).all() for i in range(len(stored)))


def test_other_clip_only_with_clips_and_weights(small_cfg, demo):
    rm = build_reward(small_cfg, demo, None, seed=0)
    pos, neg = rm.sampler.available(8, have_agent=False)
    assert "other_clip" not in neg and "expert_vs_agent" not in neg
    cfg = RewardConfig.make(**{**small_cfg.to_dict(), "pair_weights": {"reversed": 0.0}})
    rm = build_reward(cfg, demo, None, seed=0)
    assert "reversed" not in rm.sampler.available(8, have_agent=True)[1]
    with pytest.raises(ValueError, match="pair_weights"):
        RewardConfig.make(pair_weights={"nope": 1.0}).validate()
