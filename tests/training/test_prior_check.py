"""The physics check of the video fit's finalists: their warm-start teachers on the real simulator."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.motion.gaits import gait_params
from virl_quad.policy.tg import TGParams, TrajectoryGenerator
from virl_quad.training.prior import gait_tg
from virl_quad.training.prior_check import (MAX_FALL_RATE, STEADY_FALL_RATE, at_speed, nominal_speed, pick_carrying,
                                            slowed_to_carry, teacher_trial, with_variant)

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


def _flying_trot() -> TGParams:
    """A dog's fast trot on Pupper (1.85 Hz, duty 0.4, 0.6 m/s, 2.4x its built-in trot): the teacher falls."""
    return at_speed(dataclasses.replace(_trot(), frequency=1.85, duty=0.4), 0.6)


def test_a_gait_too_fast_to_carry_the_robot_is_slowed_to_its_built_in_trot_speed(demo) -> None:
    lines: list[str] = []
    k, slow, rows = slowed_to_carry(PUPPER, demo, [_trot(), _flying_trot()], STEPS, 0, False, lines.append)
    assert k == 1 and [r["finalist"] for r in rows] == [1]                # the built-in trot is not faster than itself
    assert nominal_speed(slow) == pytest.approx(nominal_speed(_trot()))
    assert (slow.frequency, slow.offsets, slow.duty, slow.swing_height) == (1.85, _trot().offsets, 0.4, 0.03)
    assert rows[0]["fall_rate"] <= MAX_FALL_RATE and "slowed to 0.25 m/s" in lines[0]
    fast = teacher_trial(PUPPER, demo, _flying_trot(), STEPS, 0, False)
    assert fast["fall_rate"] > MAX_FALL_RATE                               # as fast as the video, it falls
    assert slowed_to_carry(PUPPER, demo, [_trot()], STEPS, 0, False, lines.append) == (-1, None, [])


def _video_pace() -> TGParams:
    """The pace as the main job fits it to the built-in pace video (2 Hz, duty 0.5, step 4.7 cm,
    swing 1.5 cm): on the physics robot its teacher drifts backwards."""
    return TGParams(frequency=2.0, offsets=(0.0, 0.5, 0.0, 0.5), duty=0.5, step_length=0.047,
                    swing_height=0.015, stance_height=0.14)


def test_a_variant_moves_the_hind_feet_back_scales_swing_and_step_and_must_stay_in_reach() -> None:
    from virl_quad.training.prior_check import with_variant

    before = TrajectoryGenerator(PUPPER, _trot()).neutral_xy
    moved = with_variant(PUPPER, _trot(), 0.02, 2.0, 1.5)
    after = TrajectoryGenerator(PUPPER, moved).neutral_xy
    assert after[:2] == pytest.approx(before[:2])                        # front feet stay
    assert after[2:, 0] == pytest.approx(before[2:, 0] - 0.02)           # hind feet 2 cm back
    assert after[:, 1] == pytest.approx(before[:, 1])
    assert moved.swing_height == pytest.approx(2.0 * _trot().swing_height)
    assert moved.step_length == pytest.approx(1.5 * _trot().step_length)
    with pytest.raises(ValueError):
        with_variant(PUPPER, _trot(), 0.5, 1.0)                          # hind feet half a metre back
    wide = TrajectoryGenerator(PUPPER, with_variant(PUPPER, _trot(), 0.0, 1.0, 1.0, 1.0, 0.03)).neutral_xy
    assert wide[:, 0] == pytest.approx(before[:, 0])
    assert np.abs(wide[:, 1]) == pytest.approx(np.abs(before[:, 1]) + 0.03)  # every foot 3 cm further out
    assert np.sign(wide[:, 1]) == pytest.approx(np.sign(before[:, 1]))


def test_a_crouched_variant_lowers_every_foot_and_stays_in_reach() -> None:
    from virl_quad.training.prior_check import GAIT_VARIANTS, describe_variant, with_variant

    dog = TGParams(frequency=1.85, offsets=(0.0, 0.5, 0.5, 0.0), duty=0.4, step_length=0.054,   # the dog video's
                   swing_height=0.015, stance_height=0.14)                                        # fit, slowed
    crouched = with_variant(PUPPER, dog, 0.01, 2.0, 1.0, 0.8)
    assert crouched.stance_height == pytest.approx(0.8 * dog.stance_height)
    z_before = TrajectoryGenerator(PUPPER, dog).foot_positions(0.0)[:, 2]
    z_after = TrajectoryGenerator(PUPPER, crouched).foot_positions(0.0)[:, 2]
    assert z_after[[0, 3]] == pytest.approx(z_before[[0, 3]] + 0.2 * dog.stance_height)  # stance feet nearer the hips
    for variant in GAIT_VARIANTS:                                        # every variant reaches with these fits' gaits
        for tg in (dog, _video_pace()):
            with_variant(PUPPER, tg, *variant)
    assert describe_variant({"hind_back_m": 0.01, "swing_scale": 2.0, "step_scale": 1.0, "stance_scale": 0.8}) \
        == "hind feet 1.0 cm back, swing x2, step x1, stance x0.8"
    assert "stance" not in describe_variant({"hind_back_m": 0.01, "swing_scale": 2.0, "step_scale": 1.0})
    assert describe_variant({"hind_back_m": 0.02, "swing_scale": 2.0, "step_scale": 1.5, "stance_scale": 0.8,
                             "widen_m": 0.04}).endswith("stance x0.8, feet 4.0 cm wider")
    with pytest.raises(ValueError):
        with_variant(PUPPER, dog, 0.0, 1.0, 1.0, 0.2)                    # feet 3 cm under the hips: out of reach


def test_a_teacher_that_travels_the_video_s_way_fast_enough_keeps_its_gait(demo) -> None:
    from virl_quad.training.prior_check import MIN_SPEED_SHARE, nominal_speed, pick_variant

    fast = MIN_SPEED_SHARE * nominal_speed(_trot()) * 1.05                # m/s, just over the share
    tg, rows = pick_variant(PUPPER, demo, _trot(), {"travel_m": 0.5, "speed_mps": fast}, +1.0, STEPS, 0, False)
    assert tg == _trot() and rows == []                                  # nothing tried


def _video_bound() -> TGParams:
    """The bound as the main job fits it to the built-in bound video (2.5 Hz, duty 0.5, step 5 cm,
    swing 3 cm): its teacher carries the robot at about a fifth of the gait's 0.25 m/s."""
    return TGParams(frequency=2.5, offsets=(0.0, 0.0, 0.5, 0.5), duty=0.5, step_length=0.05,
                    swing_height=0.03, stance_height=0.14)


def test_a_slow_bound_gets_a_variant_that_travels_further() -> None:
    from virl_quad.training.prior_check import MIN_SPEED_SHARE, gait_for_travel, nominal_speed

    bound = demo_lib.load("bound", "pupper")
    trial = teacher_trial(PUPPER, bound, _video_bound(), STEPS, seed=0, randomize=False)
    assert 0 < trial["speed_mps"] < MIN_SPEED_SHARE * nominal_speed(_video_bound()), trial
    report = {"physics_check": [{"finalist": 0, **trial}], "kept_finalist": 0}
    lines: list[str] = []
    tg = gait_for_travel(PUPPER, bound, _video_bound(), report, STEPS, 0, False, lines.append)
    kept = [r for r in report["travel_check"] if r.get("kept")]
    assert len(kept) == 1 and kept[0]["travel_m"] > trial["travel_m"] + 0.2, lines
    assert kept[0]["fall_rate"] <= MAX_FALL_RATE and tg != _video_bound()
    assert "under 0.33 of its gait's" in lines[0]


def test_the_backward_pace_gets_a_variant_that_walks_forwards() -> None:
    from virl_quad.training.prior_check import gait_for_travel

    pace = demo_lib.load("pace", "pupper")                               # its ground slides: forwards
    trial = teacher_trial(PUPPER, pace, _video_pace(), STEPS, seed=0, randomize=False)
    assert trial["travel_m"] < 0, trial                                  # the fitted pace goes backwards
    report = {"physics_check": [{"finalist": 0, **trial}], "kept_finalist": 0}
    lines: list[str] = []
    tg = gait_for_travel(PUPPER, pace, _video_pace(), report, STEPS, 0, False, lines.append)
    kept = [r for r in report["travel_check"] if r.get("kept")]
    assert len(kept) == 1 and report["variant"] is not None, lines
    assert kept[0]["travel_m"] > 0.2 and kept[0]["fall_rate"] <= MAX_FALL_RATE, lines
    steady = [r["travel_m"] for r in report["travel_check"] if r["fall_rate"] <= STEADY_FALL_RATE]
    assert kept[0]["travel_m"] == max(steady)                            # it goes further than the pace's own
    assert tg != _video_pace() and any("hind feet" in line for line in lines)


def test_a_steady_variant_is_kept_before_a_faster_one_that_falls_more() -> None:
    from virl_quad.training.prior_check import choose_variant

    def row(falls: int, travel: float) -> dict:
        return {"falls": falls, "episodes": 8, "fall_rate": falls / 8, "travel_m": travel}

    rows = [row(3, 0.9), row(1, 0.5), row(0, 0.4), row(0, -0.6)]
    assert choose_variant(rows, -0.4, +1.0, MAX_FALL_RATE) == 1          # 1 of 8 is steady; 3 of 8 is not
    assert choose_variant(rows, 0.6, +1.0, MAX_FALL_RATE) == 0           # no steady one beats 0.6 m: the loose bar
    assert choose_variant(rows, 1.0, +1.0, MAX_FALL_RATE) is None        # none goes further than the gait itself
    assert choose_variant(rows, 0.3, -1.0, MAX_FALL_RATE) == 3           # a video walking backwards
    assert choose_variant([row(5, 2.0)], 0.0, +1.0, MAX_FALL_RATE) is None   # falls in more than half


def test_a_variant_can_lengthen_the_stance() -> None:
    from virl_quad.training.prior_check import GAIT_VARIANTS, VARIANT_KEYS, VARIANT_NEUTRAL, describe_variant

    longer = with_variant(PUPPER, _video_pace(), 0.02, 1.0, 1.5, 1.0, 0.0, 0.1)
    assert longer.duty == pytest.approx(_video_pace().duty + 0.1)
    assert longer.step_length == pytest.approx(1.5 * _video_pace().step_length)
    assert describe_variant(dict(zip(VARIANT_KEYS, (0.02, 1.0, 1.5, 1.0, 0.0, 0.1)))) \
        == "hind feet 2.0 cm back, swing x1, step x1.5, duty +0.10"
    assert len(VARIANT_NEUTRAL) == len(VARIANT_KEYS) and all(len(v) <= len(VARIANT_KEYS) for v in GAIT_VARIANTS)
    with pytest.raises(ValueError):
        with_variant(PUPPER, _video_pace(), 0.0, 1.0, 1.0, 1.0, 0.0, 0.5)  # duty 1.0: no swing left


def test_a_video_without_a_patterned_ground_keeps_its_gait(demo) -> None:
    from virl_quad.training.prior_check import gait_for_travel

    plain = dataclasses.replace(demo, frames=np.full_like(demo.frames, 128))
    report = {"physics_check": [{"finalist": 0, "travel_m": -1.0, "fall_rate": 0.0}], "kept_finalist": 0}
    assert gait_for_travel(PUPPER, plain, _trot(), report, STEPS, 0, False) == _trot()
    assert report["variant"] is None and "travel_check" not in report


def test_a_crouch_is_kept_only_when_it_walks_clearly_further() -> None:
    from virl_quad.training.prior_check import UPRIGHT_SHARE, choose_variant

    def row(travel: float, stance: float = 1.0, falls: int = 0) -> dict:
        return {"falls": falls, "episodes": 8, "fall_rate": falls / 8, "travel_m": travel, "stance_scale": stance}

    trot = [row(1.26), row(1.41, 0.8), row(1.84, falls=4)]               # a trot's check (seed 3)
    assert choose_variant(trot, 0.78, +1.0, MAX_FALL_RATE) == 0          # upright, 0.89 of the crouch's walk
    dog = [row(0.85, falls=1), row(1.88, 0.8)]                           # the dog video's check
    assert choose_variant(dog, 0.64, +1.0, MAX_FALL_RATE) == 1           # the crouch goes 2.2x as far
    assert choose_variant([row(1.0), row(1.0 / UPRIGHT_SHARE - 0.01, 0.8)], 0.0, +1.0, MAX_FALL_RATE) == 0
    assert choose_variant([row(0.5), row(0.9, 0.8)], 0.6, +1.0, MAX_FALL_RATE) == 1   # upright not further
    assert choose_variant([row(1.0, falls=3), row(1.2, 0.8)], 0.0, +1.0, MAX_FALL_RATE) == 1  # steady first
