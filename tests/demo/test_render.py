"""Rendering demonstrations: every gait on both robots to .npz and .mp4, npz round trip, contact sheet."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from virl_quad import robots
from virl_quad.demo import render, sheet
from virl_quad.motion import gaits
from virl_quad.demo.demonstration import Demonstration
from virl_quad.sim.world import World


def _decoded_frames(path) -> tuple[int, tuple[int, int]]:
    cap = cv2.VideoCapture(str(path))
    n, shape = 0, (0, 0)
    while True:
        ok, f = cap.read()
        if not ok:
            break
        n, shape = n + 1, f.shape[:2]
    cap.release()
    return n, shape


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_every_gait_renders_to_npz_and_mp4(tmp_path, gait_motions, robot):
    spec = robots.get(robot)
    for gait in gaits.GAIT_NAMES:
        video = tmp_path / f"{robot}_{gait}.mp4"
        d = render.render_demonstration(gait_motions[(robot, gait)], robot, min_seconds=0.0, video=video,
                                        preview_size=64, preview="render")
        assert isinstance(d, Demonstration) and d.fps == pytest.approx(spec.control_hz)
        assert d.frames.shape[1:] == (48, 48) and d.frames.dtype == np.uint8
        # one whole cycle of control steps, the motion warped to fit it exactly
        assert d.num_frames == pytest.approx(d.motion.duration * spec.control_hz, abs=1e-6)
        assert d.frames.std() > 10                                   # not blank
        n, shape = _decoded_frames(video)
        assert n == d.num_frames and shape == (64, 64)
        back = render.load_npz(render.save_npz(d, tmp_path / f"{robot}_{gait}.npz"))
        np.testing.assert_array_equal(back.frames, d.frames)


def test_frames_match_the_environment_camera(gait_motions):
    """A demo frame is exactly what World.render shows for the same pose (same camera, same renderer)."""
    spec = robots.get("pupper")
    m = render.fit_loop(gait_motions[("pupper", "trot")], spec.control_hz)
    frames, _ = render.render_motion(m, "pupper", 3)
    with World(spec) as w:
        pos, quat, q = m.pose_at(2 / spec.control_hz)
        w.set_pose(pos, quat, q)
        np.testing.assert_array_equal(w.render(), frames[2])


def test_loop_fit_and_duration(gait_motions):
    from virl_quad.motion.motion_io import read_laikago_recording

    m = render.fit_loop(gait_motions[("laikago", "trot")], 50.0)    # 0.51 s cycle -> 25 or 26 frames at 50 Hz
    assert (m.duration * 50.0) == pytest.approx(round(m.duration * 50.0), abs=1e-9)
    assert render.frame_count(m, 50.0, min_seconds=2.0) >= 100
    clip = read_laikago_recording()
    assert render.fit_loop(clip, 50.0) is clip                        # clamped: untouched
    assert render.frame_count(clip, 10.0) == round(clip.duration * 10) + 1


def test_npz_keeps_the_motion_and_metadata(tmp_path, gait_motions):
    d = render.render_demonstration(gait_motions[("laikago", "pace")], "laikago", source="gait:pace",
                                    min_seconds=0.5)
    back = render.load_npz(render.save_npz(d, tmp_path / "d.npz"))
    assert back.robot == "laikago" and back.source == "gait:pace" and back.fps == pytest.approx(d.fps)
    assert back.camera == d.camera and back.camera["distance"] == pytest.approx(1.6)
    np.testing.assert_allclose(back.displacement, d.displacement)
    assert back.displacement[-1, 0] > 0.1                            # it walked forward
    for t in (0.0, 0.37, 3.3):
        a, b = d.motion.state_at(t), back.motion.state_at(t)
        np.testing.assert_allclose(a.root_pos, b.root_pos)
        np.testing.assert_allclose(a.q, b.q)
        np.testing.assert_allclose(a.dq, b.dq)


def test_npz_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        render.load_npz(tmp_path / "none.npz")
    (tmp_path / "x.npz").write_text("not a zip")
    with pytest.raises(ValueError, match="not a demonstration .npz"):
        render.load_npz(tmp_path / "x.npz")
    np.savez(tmp_path / "y.npz", a=np.zeros(3))
    with pytest.raises(ValueError, match="needs 'frames' and 'fps'"):
        render.load_npz(tmp_path / "y.npz")


def test_rendering_refuses_another_robots_motion(gait_motions):
    with pytest.raises(ValueError, match="retarget it first"):
        render.render_demonstration(gait_motions[("laikago", "trot")], "pupper")


def test_contact_sheet(tmp_path):
    frames = np.random.default_rng(0).integers(0, 255, (40, 48, 48), dtype=np.uint8)
    img = sheet.contact_sheet(frames, columns=8, max_frames=16, scale=2, gap=2)
    assert img.shape == (2 * (96 + 2) + 2, 8 * (96 + 2) + 2)
    d = Demonstration(frames=frames, fps=50.0, source="gait:trot")
    path = sheet.save_contact_sheet(d, tmp_path / "s.png")
    titled = sheet.contact_sheet(frames, fps=50.0, title="gait:trot")
    np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), titled)
    assert titled.shape[0] == sheet.contact_sheet(frames).shape[0] + sheet.TITLE_PX
    assert (titled[:sheet.TITLE_PX] < 128).any()         # the title is written in its band
    by_index = sheet.contact_sheet(frames, max_frames=16, scale=2)
    by_time = sheet.contact_sheet(frames, max_frames=16, scale=2, fps=50.0)
    assert not np.array_equal(by_index, by_time)         # tiles labelled with their time, not index
