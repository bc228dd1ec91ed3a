"""The physics check of the video fit's finalists: their warm-start teachers on the real simulator."""

from __future__ import annotations

import dataclasses

import pytest

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.motion.gaits import gait_params
from virl_quad.policy.tg import TGParams, TrajectoryGenerator
from virl_quad.training.prior import gait_tg
from virl_quad.training.prior_check import MAX_FALL_RATE, pick_carrying, teacher_trial

PUPPER = robots.get("pupper")
STEPS = 400   # control steps per finalist (8 s)


@pytest.fixture(scope="module")
def demo():
    return demo_lib.load("trot", "pupper")


def _trot() -> TGParams:
    return gait_tg(PUPPER, gait_params("pupper", "trot"))


def _tipping() -> TGParams:
    """The trot with every foot 4 cm further forward: the robot tips backwards within a step or two."""
    feet = TrajectoryGenerator(PUPPER, _trot()).neutral_xy.copy()
    feet[:, 0] += 0.04                                                     # m
    return dataclasses.replace(_trot(), neutral_xy=tuple(map(tuple, feet)))


def test_the_trot_teacher_walks_and_a_tipping_one_falls(demo) -> None:
    walks = teacher_trial(PUPPER, demo, _trot(), STEPS, seed=0, randomize=False)
    assert walks["falls"] == 0 and walks["travel_m"] > 0.2
    tips = teacher_trial(PUPPER, demo, _tipping(), STEPS, seed=0, randomize=False)
    assert tips["fall_rate"] > MAX_FALL_RATE and tips["episodes"] == tips["falls"] + 1   # the last one cut short


def test_the_nearest_finalist_that_carries_the_robot_is_kept(demo) -> None:
    lines: list[str] = []
    kept, rows = pick_carrying(PUPPER, demo, [_tipping(), _trot(), _tipping()], STEPS, 0, False, lines.append)
    assert kept == 1
    assert [r["finalist"] for r in rows] == [0, 1]                       # tried nearest first, stops at the first
    assert "finalist 0" in lines[0] and "fell in" in lines[0] and not any("warning" in l for l in lines)


def test_when_every_finalist_falls_the_least_falling_is_kept_with_a_warning(demo) -> None:
    lines: list[str] = []
    kept, rows = pick_carrying(PUPPER, demo, [_tipping(), _tipping()], STEPS, 0, False, lines.append)
    assert kept == 0 and len(rows) == 2
    assert lines[-1].startswith("warning:") and "cannot carry pupper" in lines[-1]
    with pytest.raises(ValueError):
        pick_carrying(PUPPER, demo, [], STEPS, 0, False, lines.append)
