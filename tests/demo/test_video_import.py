"""Video import: resampling, subject following, round trip against the rendered frames, bad files."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from virl_quad import robots
from virl_quad.demo import checks, render, video_import
from virl_quad.sim.camera import CameraParams


def _write(path, frames, fps, fourcc="mp4v"):
    h, w = frames.shape[1:3]
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
    for f in frames:
        out.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR))
    out.release()
    return path


def test_resample_to_the_control_rate(tmp_path):
    # 30 fps, 45 frames (1.5 s) of a brightness ramp -> 75 frames at Pupper's 50 Hz
    frames = np.repeat(np.linspace(20, 200, 45).astype(np.uint8)[:, None, None], 64, 1).repeat(64, 2)
    d = video_import.import_video(_write(tmp_path / "ramp.avi", frames, 30, "MJPG"), "pupper")
    assert d.fps == 50.0 and d.num_frames == 75 and d.motion is None
    assert d.camera["imported_fps"] == pytest.approx(30.0) and not d.camera["followed"]
    means = d.frames.reshape(len(d.frames), -1).mean(axis=1)
    assert np.all(np.diff(means) >= -1.0)                          # linear interpolation, monotonic
    assert means[0] == pytest.approx(20, abs=3) and means[-1] == pytest.approx(200, abs=8)


def test_large_frames_are_shrunk(tmp_path):
    frames = np.full((3, 720, 1280), 128, np.uint8)
    raw, fps = video_import.read_video(_write(tmp_path / "big.mp4", frames, 25))
    assert raw.shape[1:] == (180, 320) and fps == pytest.approx(25)


def test_bad_videos(tmp_path):
    with pytest.raises(FileNotFoundError):
        video_import.import_video(tmp_path / "none.mp4", "pupper")
    (tmp_path / "junk.mp4").write_bytes(b"not a video at all")
    with pytest.raises(ValueError, match="cannot read video"):
        video_import.import_video(tmp_path / "junk.mp4", "pupper")
    empty = tmp_path / "empty.avi"
    cv2.VideoWriter(str(empty), cv2.VideoWriter_fourcc(*"MJPG"), 30, (64, 64)).release()
    with pytest.raises(ValueError, match="no readable frames"):
        video_import.import_video(empty, "pupper")


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_round_trip_and_forward_progress(robot):
    """render -> mp4 -> import: the 48 px frames preview comes back within 8 gray levels, the larger
    render within 16 (its 48 px downscale differs from the renderer's own 48 px output); the forward
    demo's ground slides past after import, the in-place one's does not."""
    r = checks.progress_visibility(robot, "trot", preview="frames", seconds=1.0)
    assert r["roundtrip_mae_forward"] < 8 and r["roundtrip_mae_in_place"] < 8
    assert r["imported_forward_ground_change"] > 1.0
    assert r["imported_forward_ground_change"] > 20 * max(r["imported_in_place_ground_change"], 1e-3)
    assert r["imported_forward_ground_shift_px"] < -0.2              # ground moves right to left
    assert abs(r["imported_in_place_ground_shift_px"]) < 0.05
    big = checks.roundtrip(robot, "trot", preview="render", seconds=0.5)
    assert big["mae"] < 16 and not big["followed"] and big["imported_frames"] == big["rendered_frames"]


def test_static_camera_video_is_followed(tmp_path, gait_motions):
    """A robot walking across a fixed camera's view: the crop follows it and recentres it."""
    spec = robots.get("laikago")
    m = render.fit_loop(gait_motions[("laikago", "trot")], spec.control_hz)
    n = int(1.5 * spec.control_hz)
    cam = CameraParams.from_spec(spec)
    wide = dataclasses.replace(cam, distance=2.5 * cam.distance)
    end = m.pose_at(n / spec.control_hz)[0]
    _, rgb = render.render_motion(m, "laikago", n, cam=wide, preview_size=160,
                                  fixed_target=np.array([end[0] / 2, 0.0, 0.3]))
    video = render.write_mp4(rgb, spec.control_hz, tmp_path / "static.mp4")
    d = video_import.import_video(video, "laikago")
    assert d.camera["followed"]
    # the dark robot stays near the middle of every frame
    dark = d.frames < 60
    xs = np.array([np.nonzero(f)[1].mean() for f in dark])
    assert np.all(np.abs(xs - 23.5) < 8), xs
    # travel estimate: forward, same order as the truth
    true = m.pose_at((n - 1) / spec.control_hz)[0][0] - m.pose_at(0)[0][0]
    assert 0.4 * true < d.displacement[-1, 0] < 2.0 * true
    forced_off = video_import.import_video(video, "laikago", follow=False)
    xs_off = np.array([np.nonzero(f < 60)[1].mean() for f in forced_off.frames])
    assert np.ptp(xs_off) > 2 * np.ptp(xs)                         # unfollowed, it crosses the frame
