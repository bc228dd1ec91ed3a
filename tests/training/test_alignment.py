"""The alignment probe: a graded set of real rollouts, scored by a real distance model."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import demo as demo_lib
from virl_quad.reward import RewardConfig, build_reward
from virl_quad.training.alignment import AlignmentProbe, alignment, record, table


def test_probe_rollouts_are_graded_and_a_model_ranks_them() -> None:
    demo = demo_lib.load("trot", "pupper")
    rollouts = record("pupper", demo, "trot", seeds=(0,), seconds=1.5)
    names = [r.controller for r in rollouts]
    assert len(names) == len(set(names)) == 11 and "tracking the trot" not in names   # its own gait is no negative
    assert all(r.agent.shape == r.expert.shape and r.agent.shape[1:] == (48, 48) for r in rollouts)
    score = {r.controller: r.score for r in rollouts}
    assert score["tracker, alpha 1"] > score["standing still"] > score["random actions"]   # the set is graded
    model = build_reward(RewardConfig(), demo.frames, [], 0, "cpu")
    rho, rewards = alignment(model, rollouts)
    assert -1.0 <= rho <= 1.0 and len(rewards) == len(rollouts)
    assert all(0.0 <= w <= 1.0 for w in rewards)
    rows = table(rollouts, rewards)
    assert [r[2] for r in rows] == sorted((r[2] for r in rows), reverse=True)   # best score first


def test_a_reward_that_ranks_nothing_aligns_zero() -> None:
    demo = demo_lib.load("trot", "pupper")
    probe = AlignmentProbe.__new__(AlignmentProbe)
    probe.rollouts = record("pupper", demo, "trot", seeds=(0,), seconds=0.5)
    probe.speed_weight, probe.speed, probe._speed_rewards = 0.0, None, None
    for r in probe.rollouts:                    # every rollout shows the demonstration itself: one reward for all
        r.agent = r.expert = np.asarray(demo.frames[:len(r.agent)])
    model = build_reward(RewardConfig(), demo.frames, [], 0, "cpu")
    out = probe.probe(model)
    assert out["reward_alignment"] == 0.0 and out["reward_standing"] == out["reward_best"]


def test_with_the_video_speed_term_the_probe_ranks_the_mixed_reward() -> None:
    from virl_quad.reward.egomotion import VideoSpeedTerm, clip_speed, clip_window, ground_levels
    from virl_quad.training.alignment import rollout_rewards, speed_rewards

    demo = demo_lib.load("trot", "pupper")
    levels = ground_levels(demo.frames)
    window = clip_window(demo.frames, demo.fps, levels)
    term = VideoSpeedTerm(clip_speed(demo.frames, demo.fps, levels, window), demo.fps, levels, 16, window)
    probe = AlignmentProbe.__new__(AlignmentProbe)
    probe.rollouts = record("pupper", demo, "trot", seeds=(0,), seconds=1.5, randomize=False)
    speed = dict(zip((r.controller for r in probe.rollouts), speed_rewards(term, probe.rollouts)))
    assert speed["tracker, alpha 1"] > 0.5 > speed["standing still"]     # the tracker walks, standing does not
    probe.speed_weight, probe.speed, probe._speed_rewards = 0.3, term, np.nan_to_num(list(speed.values()))
    model = build_reward(RewardConfig(), demo.frames, [], 0, "cpu")
    out = probe.probe(model)
    assert out["distance_alignment"] == alignment(model, probe.rollouts)[0]
    alone = dict(zip((r.controller for r in probe.rollouts), rollout_rewards(model, probe.rollouts)))
    assert out["reward_standing"] == pytest.approx(alone["standing still"] * (0.7 + 0.3 * speed["standing still"]))
    assert -1.0 <= out["reward_alignment"] <= 1.0
