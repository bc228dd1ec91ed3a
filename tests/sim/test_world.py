"""The PyBullet world: PD torque limits, per-command gains, camera, ghost rendering."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.sim.camera import CameraParams
import dataclasses

from virl_quad.sim.pd import pd_motor, pd_torque
from virl_quad.sim.world import World


def test_pd_torque_saturates() -> None:
    tau = pd_torque(np.full(12, 10.0), np.zeros(12), np.zeros(12), np.full(12, 4.0), np.full(12, 0.4),
                    np.full(12, 1.7))
    np.testing.assert_allclose(tau, 1.7)
    tau = pd_torque(np.zeros(12), np.zeros(12), np.full(12, 1.0), np.full(12, 4.0), np.full(12, 0.4),
                    np.full(12, 1.7))
    np.testing.assert_allclose(tau, -0.4)


def test_pd_motor_balances_the_pd_torque_against_the_friction() -> None:
    kp, kd, lim = np.full(3, 4.0), np.full(3, 0.4), np.full(3, 1.7)
    # joint errors (rad): 0.01 pulls harder than the friction, 0.004 less (it sticks), -1.0 saturates
    target, force, tau = pd_motor(np.array([0.01, 0.004, -1.0]), np.zeros(3), np.zeros(3), kp, kd, lim, 0.02)
    np.testing.assert_allclose(target, [(0.04 - 0.02) / 0.4, 0.0, -(4.0 - 0.02) / 0.4])   # rad/s
    np.testing.assert_allclose(tau, [0.04, 0.016, -1.7])                                   # N·m, clipped
    np.testing.assert_allclose(force, np.abs(tau) + 0.02)
    target, _, _ = pd_motor(np.ones(1), np.zeros(1), np.zeros(1), np.full(1, 4.0), np.zeros(1), np.full(1, 1.7), 0.0)
    assert target[0] >= 1e3                # kd = 0: a spring, always at the force bound


def test_implicit_pd_is_stable_where_the_explicit_one_is_not() -> None:
    """Pupper at its 2 ms step, a leg swinging in the air: the implicit PD settles on the
    target; the explicit one is past its stability limit (2 I / kd ~ 1.7 ms) there."""
    spec = robots.get("pupper")
    assert spec.sim_dt == 0.002
    target = spec.default_pose.copy()
    target[0:3] += [0.2, 0.4, -0.4]        # FR leg, rad
    settled = {}
    for pd in ("implicit", "explicit"):
        with World(spec, pd=pd) as w:
            w.reset(base_pos=[0.0, 0.0, 1.0])        # high above the ground: 0.4 s of free fall
            for _ in range(20):
                w.step(target)
            q, dq = w.joint_states()
            settled[pd] = (np.abs(q - target)[0:3].max(), np.abs(dq[0:3]).max())
    assert settled["implicit"][0] < 0.05 and settled["implicit"][1] < 1.0       # rad, rad/s
    assert settled["explicit"][1] > 5.0 * settled["implicit"][1] + 1.0


def test_implicit_pd_at_2_ms_follows_the_explicit_one_at_a_fine_step() -> None:
    """The same target steps, the same robot in the air (the PD alone, no contact): joint
    trajectories of the implicit PD at 2 ms and of the explicit PD at 0.25 ms (converged)
    agree within 0.02 rad."""
    spec = robots.get("pupper")
    fine = dataclasses.replace(spec, sim_dt=0.00025, substeps=80)
    rng = np.random.default_rng(0)
    targets = [spec.default_pose + rng.uniform(-0.3, 0.3, 12) for _ in range(10)]   # rad
    runs = []
    for s, pd in ((spec, "implicit"), (fine, "explicit")):
        with World(s, pd=pd) as w:
            w.reset(base_pos=[0.0, 0.0, 2.0])        # 0.4 s of free fall
            qs = []
            for t in targets:
                for _ in range(2):
                    w.step(t)
                    qs.append(w.joint_states()[0])
            runs.append(np.array(qs))
    assert np.abs(runs[0] - runs[1]).max() < 0.02


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
