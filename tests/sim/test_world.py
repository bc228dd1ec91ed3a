"""The PyBullet world: PD torque limits, per-command gains, camera, ghost rendering."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.sim.camera import CameraParams
from virl_quad.sim.pd import pd_torque
from virl_quad.sim.world import World


def test_pd_torque_saturates() -> None:
    tau = pd_torque(np.full(12, 10.0), np.zeros(12), np.zeros(12), np.full(12, 4.0), np.full(12, 0.4),
                    np.full(12, 1.7))
    np.testing.assert_allclose(tau, 1.7)
    tau = pd_torque(np.zeros(12), np.zeros(12), np.full(12, 1.0), np.full(12, 4.0), np.full(12, 0.4),
                    np.full(12, 1.7))
    np.testing.assert_allclose(tau, -0.4)


@pytest.mark.parametrize("robot", robots.names())
def test_applied_torques_respect_limits(robot: str) -> None:
    spec = robots.get(robot)
    with World(spec) as w:
        w.reset()
        w.step(spec.default_pose + 1.0)  # far target: saturates
        assert np.all(np.abs(w.state().tau) <= spec.torque_limit + 1e-9)
        assert np.any(np.isclose(np.abs(w.state().tau), spec.torque_limit))


def test_zero_gains_let_the_robot_sag() -> None:
    spec = robots.get("pupper")
    with World(spec) as held, World(spec) as limp:
        held.reset()
        limp.reset()
        for _ in range(25):
            held.step(spec.default_pose)
            limp.step(spec.default_pose, kp=np.zeros(12), kd=np.zeros(12))
        assert limp.state().base_pos[2] < held.state().base_pos[2] - 0.02


def test_camera_frames_and_ghost_one_at_a_time() -> None:
    spec = robots.get("pupper")
    with World(spec, ghost=True) as w:
        w.reset()
        empty_ghost = w.render(body="ghost")  # ghost parked far away: nothing but ground and sky
        w.set_pose([0.0, 0.0, spec.spawn_height], [0, 0, 0, 1], spec.default_pose, body="ghost")
        agent, ghost = w.render(), w.render(body="ghost")
        assert agent.shape == (48, 48) and agent.dtype == np.uint8
        np.testing.assert_array_equal(agent, ghost)  # same pose, same place: the same picture
        assert np.abs(agent.astype(int) - empty_ghost).mean() > 3
        assert w.state().base_pos[2] > 0.1  # parking and restoring left the agent in place
        rgb = w.render(size=96, rgb=True, cam=CameraParams.from_spec(spec).jittered(0.1, 0.0, 10.0))
        assert rgb.shape == (96, 96, 3)
        with pytest.raises(ValueError, match="unknown body"):
            w.render(body="other")


def test_ground_choices_render_differently_and_unknown_is_refused() -> None:
    import numpy as np
    import pytest

    from virl_quad import robots
    from virl_quad.sim.world import World

    spec = robots.get("pupper")
    with World(spec, ground="plain") as w:
        plain = w.render().astype(int)
    with World(spec, ground="checker") as w:
        checker = w.render().astype(int)
    assert np.abs(plain - checker).mean() > 5.0
    lower = plain[40:]                          # bottom rows: ground only
    assert lower.std() < 2.0 and checker[40:].std() > 10.0
    with pytest.raises(ValueError, match="unknown ground"):
        World(spec, ground="grass")


def test_speed_strip_draws_a_bar_from_the_centre_continuous_in_the_speed() -> None:
    from virl_quad.sim.strip import STRIP_ROWS, stamp_speed

    frames = np.full((3, 48, 48), 120, np.uint8)
    out = stamp_speed(frames, np.array([0.0, 0.25, -0.5]), full_speed=0.5)
    np.testing.assert_array_equal(out[:, :-STRIP_ROWS], frames[:, :-STRIP_ROWS])   # the image above is kept
    assert frames[0, -1, 0] == 120                                                   # input untouched
    assert not out[0, -STRIP_ROWS:].any()                                            # no travel: all black
    assert (out[1, -1, 24:36] == 255).all() and not out[1, -1, :24].any() and not out[1, -1, 36:].any()
    assert (out[2, -1, :24] == 255).all() and not out[2, -1, 24:].any()              # backwards, full scale
    lit = [int(stamp_speed(frames[0], v, 0.5)[-1].astype(int).sum()) for v in np.linspace(0.0, 0.5, 41)]
    assert all(b > a for a, b in zip(lit, lit[1:]))                                  # grows with the speed
    assert int(stamp_speed(frames[0], 9.0, 0.5)[-1].sum()) == 24 * 255               # clipped at full scale
    with pytest.raises(ValueError):
        stamp_speed(frames, np.nan, 0.5)
    with pytest.raises(ValueError):
        stamp_speed(np.zeros((4, 4), np.uint8), 0.1, 0.5)
