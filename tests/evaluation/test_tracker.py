"""The privileged reference tracker: the simulated Pupper can do its built-in trot."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import envs
from virl_quad.demo import render
from virl_quad.evaluation.tracker import tracker_action


def _drive(demo, track: bool, seconds: float = 3.0) -> tuple[bool, float, float]:
    """(fell, forward travel m, mean pose error rad^2) of one episode from the demo's start."""
    env = envs.make("pupper", demo=demo, randomize=False, episode_seconds=seconds)
    u = env.unwrapped
    env.reset(seed=0, options={"demo_step": 0})
    x0, errors, fell = u.state.base_pos[0], [], False
    while True:
        action = tracker_action(env) if track else np.zeros(12)
        _, _, fell, truncated, _ = env.step(action)
        errors.append(np.sum((u.state.q - demo.motion.state_at(u.demo_step / demo.fps).q) ** 2))
        if fell or truncated:
            break
    travel = u.state.base_pos[0] - x0
    env.close()
    return fell, float(travel), float(np.mean(errors))


def test_tracker_trots_forward_and_tracks_better_than_standing(gait_motions):
    motion = gait_motions[("pupper", "trot")]
    demo = render.render_demonstration(motion, "pupper", min_seconds=0.5)
    ref_travel = motion.state_at(3.0).root_pos[0] - motion.state_at(0.0).root_pos[0]   # m
    fell, travel, err = _drive(demo, track=True)
    fell0, travel0, err0 = _drive(demo, track=False)
    assert not fell and not fell0
    assert travel > 0.2 * ref_travel > 0.1, (travel, ref_travel)   # the trot moves it forward
    assert abs(travel0) < 0.05                                      # standing does not
    assert err < 0.5 * err0, (err, err0)


def test_tracker_needs_a_motion():
    from virl_quad.demo.demonstration import Demonstration

    env = envs.make("pupper", demo=Demonstration(frames=np.zeros((5, 48, 48), np.uint8), fps=50.0), randomize=False)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="no reference motion"):
        tracker_action(env)
    env.close()
