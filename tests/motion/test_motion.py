"""Motion model: interpolation, slerp, looping with cycle offsets, time warping, velocities."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from virl_quad.motion.state import MotionState
from virl_quad.motion.motion import Motion, heading


def _line_motion(n: int = 11, dt: float = 0.1, speed: float = 0.5, yaw_rate: float = 0.0, **kw) -> Motion:
    """Root moving at ``speed`` m/s along x, turning at ``yaw_rate`` rad/s, joints ramping at 1 rad/s."""
    t = np.arange(n) * dt
    pos = np.column_stack([speed * t, np.zeros(n), np.full(n, 0.3)])
    quat = Rotation.from_euler("z", yaw_rate * t[:, None]).as_quat()
    q = np.tile(np.linspace(-0.5, 0.5, 12), (n, 1)) + t[:, None]
    return Motion(frame_duration=dt, root_pos=pos, root_quat=quat, q=q, **kw)


def test_keyframes_and_linear_interpolation():
    m = _line_motion(loop=False)
    assert m.duration == pytest.approx(1.0)
    for i in (0, 3, 10):
        pos, quat, q = m.pose_at(i * 0.1)
        np.testing.assert_allclose(pos, m.root_pos[i], atol=1e-12)
        np.testing.assert_allclose(q, m.q[i], atol=1e-12)
    pos, _, q = m.pose_at(0.25)
    np.testing.assert_allclose(pos, [0.125, 0.0, 0.3], atol=1e-12)
    np.testing.assert_allclose(q, m.q[2] + 0.05, atol=1e-12)


def test_root_orientation_is_slerped():
    rots = Rotation.from_euler("xyz", [[0, 0, 0], [0.4, -0.3, 1.2], [0.1, 0.2, -0.5]])
    m = Motion(frame_duration=0.2, root_pos=np.zeros((3, 3)), root_quat=rots.as_quat(), q=np.zeros((3, 12)),
               loop=False)
    ref = Slerp([0.0, 0.2, 0.4], rots)
    for t in (0.05, 0.1, 0.33):
        got = Rotation.from_quat(m.pose_at(t)[1])
        assert (got.inv() * ref([t])[0]).magnitude() < 1e-9


def test_loop_with_position_offset_continues_forward():
    m = _line_motion(loop=True, cycle_offset_position=True)
    for t in (1.0, 1.25, 2.6, -0.4):
        pos = m.pose_at(t)[0]
        assert pos[0] == pytest.approx(0.5 * t, abs=1e-9)   # keeps walking at 0.5 m/s
        assert pos[2] == pytest.approx(0.3)
    # joint angles wrap back to the cycle's start
    np.testing.assert_allclose(m.pose_at(1.25)[2], m.pose_at(0.25)[2], atol=1e-12)


def test_loop_without_offset_jumps_back():
    m = _line_motion(loop=True, cycle_offset_position=False)
    assert m.pose_at(1.25)[0][0] == pytest.approx(0.125)


def test_loop_with_rotation_offset_turns_each_cycle():
    m = _line_motion(n=11, dt=0.1, speed=0.0, yaw_rate=0.5, loop=True, cycle_offset_position=True,
                     cycle_offset_rotation=True)
    assert m.cycle_delta_heading == pytest.approx(0.5)
    for t in (1.0, 1.5, 2.2, 3.7):
        assert heading(m.pose_at(t)[1]) == pytest.approx(np.arctan2(np.sin(0.5 * t), np.cos(0.5 * t)), abs=1e-9)


def test_rotation_offset_carries_the_path_round():
    # walking along x while turning: cycle k starts where cycle k-1 ended, heading included
    m = _line_motion(n=21, dt=0.05, speed=1.0, yaw_rate=0.0, loop=True, cycle_offset_rotation=True)
    m.root_quat = Rotation.from_euler("z", np.linspace(0, 0.3, 21)[:, None]).as_quat()
    m.__post_init__()
    end0 = m.pose_at(m.duration - 1e-9)
    start1 = m.pose_at(m.duration)
    np.testing.assert_allclose(end0[0], start1[0], atol=1e-6)
    assert heading(start1[1]) == pytest.approx(0.3, abs=1e-6)


def test_clamp_holds_the_ends():
    m = _line_motion(loop=False)
    np.testing.assert_allclose(m.pose_at(-1.0)[0], m.root_pos[0])
    np.testing.assert_allclose(m.pose_at(5.0)[0], m.root_pos[-1])
    assert np.all(m.state_at(5.0).root_lin_vel == 0.0)


def test_state_at_velocities_by_finite_differences():
    m = _line_motion(speed=0.5, yaw_rate=0.8, loop=True)
    s = m.state_at(0.42)
    assert isinstance(s, MotionState)
    np.testing.assert_allclose(s.root_lin_vel, [0.5, 0, 0], atol=1e-9)
    np.testing.assert_allclose(s.root_ang_vel, [0, 0, 0.8], atol=1e-6)
    np.testing.assert_allclose(s.dq, np.ones(12), atol=1e-9)
    # clamped clip: one-sided difference at the ends
    c = _line_motion(loop=False)
    np.testing.assert_allclose(c.state_at(0.0).root_lin_vel, [0.5, 0, 0], atol=1e-9)
    np.testing.assert_allclose(c.state_at(1.0).dq, np.ones(12), atol=1e-9)


def test_sample_matches_state_at():
    m = _line_motion(loop=True, yaw_rate=0.3)
    times = np.array([0.0, 0.37, 1.9])
    s = m.sample(times)
    for k, t in enumerate(times):
        st = m.state_at(t)
        for key, arr in s.items():
            np.testing.assert_allclose(arr[k], getattr(st, key), atol=1e-12)


def test_time_warp():
    m = _line_motion(loop=True)
    fast = m.time_warp(2.0)
    assert fast.duration == pytest.approx(0.5)
    np.testing.assert_allclose(fast.pose_at(0.2)[2], m.pose_at(0.4)[2], atol=1e-12)
    assert m.time_warp(0.5).state_at(0.3).root_lin_vel[0] == pytest.approx(0.25)
    for bad in (0.4, 2.5):
        with pytest.raises(ValueError, match=r"\[0.5, 2.0\]"):
            m.time_warp(bad)


def test_resampled_keeps_the_path():
    m = _line_motion(loop=True)
    r = m.resampled(33.0)
    assert r.duration == pytest.approx(m.duration)
    for t in (0.1, 0.55):
        np.testing.assert_allclose(r.pose_at(t)[0], m.pose_at(t)[0], atol=1e-9)


def test_arrays_round_trip():
    m = _line_motion(loop=True, cycle_offset_rotation=True, robot="pupper", name="x")
    back = Motion.from_arrays(m.to_arrays())
    assert (back.loop, back.cycle_offset_position, back.cycle_offset_rotation) == (True, True, True)
    assert back.robot == "pupper" and back.name == "x"
    np.testing.assert_allclose(back.state_at(1.3).root_pos, m.state_at(1.3).root_pos)


@pytest.mark.parametrize("kwargs, message", [
    (dict(root_pos=np.zeros((1, 3)), root_quat=[[0, 0, 0, 1]], q=np.zeros((1, 12))), "at least 2 frames"),
    (dict(root_pos=np.zeros((2, 3)), root_quat=np.zeros((2, 4)), q=np.zeros((2, 12))), "zero quaternion"),
    (dict(root_pos=np.zeros((2, 3)), root_quat=[[0, 0, 0, 1]] * 2, q=np.zeros((2, 11))), r"q must be \(2, 12\)"),
    (dict(root_pos=np.full((2, 3), np.nan), root_quat=[[0, 0, 0, 1]] * 2, q=np.zeros((2, 12))), "NaN"),
])
def test_bad_motion_arrays(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Motion(frame_duration=0.1, **kwargs)
