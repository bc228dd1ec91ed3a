"""The gait prior fitted to the video alone (analysis by synthesis), on real renders."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.motion.gaits import PHASE_OFFSETS
from virl_quad.policy.tg import TGParams
from virl_quad.training.video_prior import (dark_level, fit_tg_to_video, gait_period, leg_length, relative_offsets,
                                            same_pattern, silhouettes, template, transfer, video_body)

PUPPER = robots.get("pupper")
LAIKAGO = robots.get("laikago")


@pytest.mark.parametrize("gait, frames", [("trot", 25), ("bound", 20), ("walk", 40)])
def test_the_period_of_a_rendered_gait(gait: str, frames: int) -> None:
    video = demo_lib.load(gait, "pupper").frames
    period, periodicity = gait_period(silhouettes(video), PUPPER.control_hz)
    assert period == pytest.approx(frames, abs=0.3) and periodicity > 0.9


def test_silhouettes_paint_sky_and_ground_and_keep_the_robot() -> None:
    video = demo_lib.load("trot", "pupper").frames
    out = silhouettes(video)
    assert (out[:, -2:] == 255).all() and (out[:, :2] == 255).all()
    robot = ~np.isin(video, [89, 140, 255])                  # checker squares and sky
    assert robot.any() and (out[robot] == video[robot]).all()


def test_silhouettes_on_a_textured_ground_keep_what_is_darker_than_it() -> None:
    rng = np.random.default_rng(0)
    video = np.full((20, 48, 48), 250, np.uint8)                              # sky
    video[:, 24:] = rng.integers(90, 141, (20, 24, 48))                       # ground of many levels
    for t in range(20):
        video[t, 20:30, 10 + t:20 + t] = 40                                   # a dark robot walking by
    assert dark_level(video) == 90 - 6 or dark_level(video) == 91 - 6
    out = silhouettes(video)
    assert set(np.unique(out)) == {0, 255} and (out[video == 40] == 0).all() and (out[video != 40] == 255).all()
    flat = np.where(out == 255, 250, 40).astype(np.uint8)                     # a render on a flat ground
    assert dark_level(flat) is None
    assert np.array_equal(silhouettes(flat, video), out)                      # drawn by the video's rule
    noise = rng.integers(0, 256, (20, 48, 48), dtype=np.uint8)                # nothing darker than the "ground"
    assert dark_level(noise) is None and np.array_equal(silhouettes(noise), noise)


def test_a_gait_fitted_on_another_body_is_carried_over_by_leg_length() -> None:
    from virl_quad.policy.tg import TrajectoryGenerator

    fitted = replace(template(LAIKAGO), frequency=1.85, offsets=(0.0, 0.5, 0.5, 0.0), duty=0.4)
    out = transfer(fitted, LAIKAGO, PUPPER)
    k = leg_length(PUPPER) / leg_length(LAIKAGO)
    assert 0.2 < k < 0.6
    assert (out.frequency, out.offsets, out.duty) == (fitted.frequency, fitted.offsets, fitted.duty)
    assert out.step_length == pytest.approx(fitted.step_length * k) and out.swing_height == pytest.approx(
        fitted.swing_height * k)
    assert out.stance_height == template(PUPPER).stance_height
    TrajectoryGenerator(PUPPER, out)                                          # within Pupper's reach
    assert transfer(fitted, LAIKAGO, LAIKAGO) is fitted


def test_the_body_a_video_shows_is_found() -> None:
    from virl_quad.training.synthesis import Synthesizer

    synth = Synthesizer(LAIKAGO, PUPPER.control_hz)                            # a Laikago seen at Pupper's rate
    try:
        laikago_video = synth.render(replace(template(LAIKAGO), frequency=2.0), 60)
    finally:
        synth.close()
    body, costs = video_body(laikago_video, PUPPER.control_hz, [PUPPER, LAIKAGO])
    assert body is LAIKAGO and costs["laikago"] < 0.5 * costs["pupper"]
    body, costs = video_body(demo_lib.load("trot", "pupper").frames[:60], PUPPER.control_hz, [PUPPER, LAIKAGO])
    assert body is PUPPER and costs["pupper"] < 0.5 * costs["laikago"]


@pytest.mark.parametrize("gait", ["trot", "pace"])
def test_a_rendered_gait_fits_its_own_phase_pattern(gait: str) -> None:
    demo = demo_lib.load(gait, "pupper")
    finalists, report, fitted = fit_tg_to_video(demo.frames, demo.fps, PUPPER)
    params = finalists[0]
    assert same_pattern(params.offsets, PHASE_OFFSETS[gait]), relative_offsets(params.offsets)
    others = [g for g in ("trot", "pace", "bound") if g != gait]
    assert not any(same_pattern(params.offsets, PHASE_OFFSETS[g]) for g in others)
    assert params.frequency == pytest.approx(2.0, rel=0.02)
    assert fitted.shape == (len(finalists), *demo.frames.shape) and report["distance"] < 2 / 255
    assert report["finalists"][0]["distance"] == report["distance"]
    assert TGParams.from_dict(report["finalists"][0]["tg"]) == params       # as prior_fit.json records it


def test_a_pool_of_processes_renders_what_one_process_renders() -> None:
    from dataclasses import replace

    from virl_quad.training.synthesis import RenderPool, Synthesizer
    from virl_quad.training.video_prior import template

    trot = template(PUPPER)
    candidates = [trot, replace(trot, duty=0.4, swing_height=0.045), replace(trot, step_length=0.9)]  # last: out of reach
    with RenderPool(PUPPER, workers=2) as pool:
        assert pool.workers == 2
        renders = pool.render_many(candidates, 12)
    synth = Synthesizer(PUPPER)
    try:
        for params, got in zip(candidates[:2], renders):
            assert got.shape == (12, 48, 48) and np.array_equal(got, synth.render(params, 12))
    finally:
        synth.close()
    assert renders[2] is None
    assert not np.array_equal(renders[0], renders[1])


def test_same_pattern_ignores_the_global_phase() -> None:
    assert same_pattern((0.25, 0.75, 0.75, 0.25), PHASE_OFFSETS["trot"])
    assert not same_pattern(PHASE_OFFSETS["pace"], PHASE_OFFSETS["trot"])


def test_videos_with_no_gait_are_refused() -> None:
    still = np.repeat(demo_lib.load("trot", "pupper").frames[:1], 100, axis=0)
    with pytest.raises(ValueError, match="still image"):
        fit_tg_to_video(still, PUPPER.control_hz, PUPPER)
    noise = np.random.default_rng(0).integers(0, 256, (100, 48, 48), dtype=np.uint8)
    with pytest.raises(ValueError, match="no periodic motion"):
        fit_tg_to_video(noise, PUPPER.control_hz, PUPPER)
    with pytest.raises(ValueError, match="too short"):
        fit_tg_to_video(demo_lib.load("trot", "pupper").frames[:12], PUPPER.control_hz, PUPPER)


@pytest.mark.parametrize("kind, message", [("still", "still image"), ("noise", "no periodic motion")])
def test_train_on_a_video_with_no_gait_is_one_error_line(kind: str, message: str, tmp_path: Path) -> None:
    from virl_quad.demo.render import write_mp4

    trot = demo_lib.load("trot", "pupper").frames
    frames = (np.repeat(trot[:1], 100, axis=0) if kind == "still"
              else np.random.default_rng(0).integers(0, 256, (100, 48, 48), dtype=np.uint8))
    video = write_mp4(np.repeat(np.repeat(frames, 5, axis=1), 5, axis=2), PUPPER.control_hz, tmp_path / f"{kind}.mp4")
    p = subprocess.run([sys.executable, "-m", "virl_quad.train", "--demo", str(video), "--iterations", "1",
                        "--run-dir", str(tmp_path / "run"), "--num-envs", "2", "--num-workers", "1"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 2, p.stderr[-2000:]
    assert p.stderr.startswith("error:") and message in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
