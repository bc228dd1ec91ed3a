"""The gait prior's parameters: least-squares fit to a reference motion, or the built-in gait."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.motion.gaits import gait_motion, gait_params
from virl_quad.motion.motion import Motion
from virl_quad.policy import TrajectoryGenerator
from virl_quad.training.prior import fit_tg, gait_tg, tg_for_demo


def _phase_gap(a: float, b: float) -> float:
    d = (a - b) % 1.0
    return min(d, 1.0 - d)


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_fit_of_the_builtin_trot_and_pace(robot: str) -> None:
    spec = robots.get(robot)
    for gait in ("trot", "pace"):
        params, report = fit_tg(gait_motion(robot, gait), spec)
        fr, fl, rr, rl = params.offsets
        if gait == "trot":                                       # diagonal pairs, half a cycle apart
            assert _phase_gap(fr, rl) < 0.01 and _phase_gap(fl, rr) < 0.01 and abs(_phase_gap(fr, fl) - 0.5) < 0.01
        else:                                                    # lateral pairs
            assert _phase_gap(fr, rr) < 0.01 and _phase_gap(fl, rl) < 0.01 and abs(_phase_gap(fr, fl) - 0.5) < 0.01
        assert report["rms_m"] < 1e-4 and report["cycles"] == pytest.approx(1.0)
        want = gait_tg(spec, gait_params(robot, gait))
        assert params.frequency == pytest.approx(want.frequency)
        assert params.duty == pytest.approx(want.duty, abs=0.01)
        assert params.step_length == pytest.approx(want.step_length, abs=1e-3)        # m
        assert params.swing_height == pytest.approx(want.swing_height, abs=1e-3)      # m
        assert params.stance_height == pytest.approx(want.stance_height, abs=1e-3)    # m
        TrajectoryGenerator(spec, params)                        # within reach and joint limits


def test_fit_reports_what_a_tg_cannot_draw() -> None:
    """A bound rocks the base: the body-frame feet are not a TG's, and the report says how far."""
    _, report = fit_tg(gait_motion("pupper", "bound"), robots.get("pupper"))
    assert 1e-3 < report["rms_m"] < 0.02


def test_a_loop_holding_two_cycles_fits_the_gait_frequency() -> None:
    m = gait_motion("pupper", "trot")
    twice = Motion(frame_duration=m.frame_duration, root_pos=np.concatenate([m.root_pos[:-1], m.root_pos]),
                   root_quat=np.concatenate([m.root_quat[:-1], m.root_quat]), q=np.concatenate([m.q[:-1], m.q]),
                   loop=True, robot="pupper", name="two trots")
    params, report = fit_tg(twice, robots.get("pupper"))
    assert report["cycles"] == pytest.approx(2.0) and params.frequency == pytest.approx(2.0)
    assert report["rms_m"] < 1e-4


def test_tg_for_a_demonstration() -> None:
    spec = robots.get("pupper")
    trot = demo_lib.load("trot", "pupper")
    params, text = tg_for_demo(trot, spec, "trot")
    assert "fitted to the reference motion" in text and "RMS foot error" in text
    video = dataclasses.replace(trot, motion=None, source="pace.mp4")             # no reference motion
    params, text = tg_for_demo(video, spec, "clips/pace.mp4")
    assert params == gait_tg(spec, gait_params("pupper", "pace")) and "built-in pace" in text
    with pytest.raises(ValueError, match="no built-in gait is named 'dance'"):
        tg_for_demo(video, spec, "dance.mp4")
