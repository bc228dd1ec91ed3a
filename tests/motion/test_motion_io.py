"""Motion files: motion_imitation JSON and the Laikago recording; the frame convention, proven by contacts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from virl_quad import robots
from virl_quad.motion import contacts, motion_io
from virl_quad.motion.motion import Motion, heading

MOTOR_OFFSETS = np.array([0.0, -0.6, 0.66] * 4)  # motion_imitation's motor angle - URDF angle, rad


def _clip(rows: list, **extra) -> str:
    data = {"LoopMode": "Wrap", "FrameDuration": 0.02, "EnableCycleOffsetPosition": True,
            "EnableCycleOffsetRotation": False, "Frames": rows}
    data.update(extra)
    return json.dumps(data)


def _row() -> list:
    return [0.0, 0.0, 0.45, 0.5, 0.5, 0.5, 0.5] + list(robots.get("laikago").default_pose)


def test_laikago_root_converted_to_z_up():
    m = motion_io.parse_motion_json(_clip([_row(), _row()]))
    # (0.5, 0.5, 0.5, 0.5) is Euler(pi/2, 0, pi/2): the limits URDF standing upright = z-up identity
    np.testing.assert_allclose(m.root_quat[0], [0, 0, 0, 1], atol=1e-12)
    assert m.robot == "laikago" and m.loop and m.cycle_offset_position and not m.cycle_offset_rotation


@pytest.mark.parametrize("robot", ["laikago", "pupper"])
def test_json_round_trip(tmp_path, robot):
    rng = np.random.default_rng(0)
    n = 6
    m = Motion(frame_duration=1 / 60, root_pos=rng.normal(size=(n, 3)),
               root_quat=Rotation.random(n, random_state=1).as_quat(), q=rng.normal(size=(n, 12)),
               loop=False, cycle_offset_position=False, cycle_offset_rotation=True, robot=robot)
    back = motion_io.read_motion_json(motion_io.write_motion_json(m, tmp_path / "clip.txt"))
    assert back.robot == robot and back.loop is False and back.cycle_offset_rotation is True
    np.testing.assert_allclose(back.root_pos, m.root_pos, atol=1e-6)
    np.testing.assert_allclose(back.q, m.q, atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(back.root_quat * m.root_quat, axis=1)), 1.0, atol=1e-9)


@pytest.mark.parametrize("text, message", [
    (_clip([_row()[:17], _row()]), "frame 0 has 17 numbers, expected 19"),
    (_clip([_row(), _row() + [1.0]]), "frame 1 has 20 numbers, expected 19"),
    (json.dumps({"LoopMode": "Wrap", "Frames": [_row(), _row()]}), "missing key.*FrameDuration"),
    (json.dumps({"FrameDuration": 0.1}), "missing key.*LoopMode, Frames"),
    (_clip([_row(), _row()], LoopMode="Bounce"), "LoopMode must be one of Wrap, Clamp"),
    (_clip([_row(), _row()], FrameDuration=-1), "FrameDuration must be positive"),
    (_clip([_row()]), "at least 2 rows"),
    (_clip([["a"] * 19, _row()]), "only numbers"),
    ("{not json", "not valid JSON"),
    ("[1, 2]", "expected a JSON object"),
])
def test_bad_json_one_line_errors(text, message):
    with pytest.raises(ValueError, match=message) as e:
        motion_io.parse_motion_json(text, name="bad.txt")
    assert "\n" not in str(e.value)


def test_missing_and_unrecognised_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        motion_io.read_motion(tmp_path / "nope.txt")
    (tmp_path / "junk.txt").write_text("hello world")
    with pytest.raises(ValueError, match="neither a motion_imitation JSON clip nor a Laikago recording"):
        motion_io.read_motion(tmp_path / "junk.txt")


def test_laikago_recording():
    m = motion_io.read_laikago_recording()
    spec = robots.get("laikago")
    assert not m.loop and m.robot == "laikago"
    assert m.duration == pytest.approx(4.99, abs=0.05)                # ~2500 rows at 500 Hz
    np.testing.assert_allclose(m.root_pos[:, 2], spec.spawn_height)   # no root trajectory: fixed
    # first row of data1.txt: 0.037199, 0.660252, -1.200187 (FR, SDK convention) -> URDF
    np.testing.assert_allclose(m.q[0, :3], [-0.037199, 0.660252 - 0.7, -1.200187 + 0.7], atol=2e-3)
    assert np.all(spec.joint_lower - 1e-9 <= m.q) and np.all(m.q <= spec.joint_upper + 1e-9)
    stats = contacts.ground_contact(m)
    assert stats.median_low < 0.02 and stats.max_penetration < 0.05  # standing on the ground, roughly


def test_recording_wrong_width():
    with pytest.raises(ValueError, match="line 2 has 13 numbers, expected 14"):
        motion_io.parse_laikago_recording("1 2 " + "0 " * 12 + "\n1 2 " + "0 " * 11, 0.48)


# -- the convention, proven with forward kinematics on every shared clip -------------------------
def test_every_shared_clip_touches_the_ground_on_laikago(motions_dir):
    for path in contacts.motion_files(motions_dir):
        s = contacts.ground_contact(motion_io.read_motion(path), "laikago")
        assert s.ok, (path.name, s)
        assert s.max_penetration <= 0.02 and s.median_low <= 0.02, (path.name, s)


def test_wrong_conventions_fail_the_contact_check(motions_dir):
    """The chosen conversion is the only one of the candidates whose feet meet the ground."""
    m = motion_io.read_motion(motions_dir / "dog_trot.txt")
    raw_quat = motion_io._zup_quat_to_clip(m.root_quat)          # file quaternion used as is
    as_is = Motion(m.frame_duration, m.root_pos, raw_quat, m.q, robot="laikago")
    motor = Motion(m.frame_duration, m.root_pos, m.root_quat, m.q + MOTOR_OFFSETS, robot="laikago")
    assert contacts.ground_contact(as_is).median_low > 0.2        # feet float ~30 cm high
    assert contacts.ground_contact(motor).max_penetration > 0.06  # motor angles: feet ~9 cm deep


def test_shared_clip_headings_follow_travel(motions_dir):
    """The converted base x axis points the way the forward clips travel (and against the backward ones)."""
    for name, sign in (("dog_trot.txt", 1), ("dog_pace.txt", 1), ("dog_backwards_trot.txt", -1)):
        m = motion_io.read_motion(motions_dir / name)
        yaw = float(np.mean(heading(m.root_quat)))
        travel = m.cycle_displacement[:2]
        assert sign * (travel @ [np.cos(yaw), np.sin(yaw)]) > 0.5 * np.linalg.norm(travel), name
