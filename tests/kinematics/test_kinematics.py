"""Pinocchio kinematics: joint mapping, FK against PyBullet, continuous joints, leg IK."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.kinematics import Kinematics, joint_limit_violation, laikago_clip_root_to_zup, quat_to_matrix
from virl_quad.quiet import quiet_fd
from virl_quad.kinematics.frames import quat_from_euler, random_quat
from virl_quad.sim.world import World

NAMES = ["pupper", "laikago"]
MOTIONS = Path(__file__).resolve().parents[3] / "shared" / "motions"


@pytest.fixture(scope="module", params=NAMES)
def setup(request):
    spec = robots.get(request.param)
    with quiet_fd(1):
        world = World(spec)
    yield spec, Kinematics(spec), world
    world.close()


def _random_q(spec, rng, n=None):
    return rng.uniform(spec.joint_lower, spec.joint_upper, size=None if n is None else (n, 12))


def test_fk_matches_pybullet(setup):
    spec, kin, world = setup
    rng = np.random.default_rng(3)
    fixed = Kinematics(spec, floating_base=False)
    for _ in range(25):
        pos, quat, q = rng.uniform([-1, -1, 0], [1, 1, 1]), random_quat(rng), _random_q(spec, rng)
        world.set_pose(pos, quat, q)  # both robots: PyBullet base pose = URDF base frame
        feet = kin.foot_positions(pos, quat, q)
        assert feet.shape == (4, 3)
        assert np.abs(feet - world.foot_positions()).max() < 1e-6
        assert np.abs(fixed.foot_positions(pos, quat, q) - feet).max() < 1e-12
        body = kin.foot_positions_body(q)
        assert np.allclose(feet, body @ quat_to_matrix(quat).T + pos, atol=1e-12)


def test_mapping_by_name_single_joint(setup):
    """Moving canonical joint i moves only leg i // 3's foot, the same way in Pinocchio and PyBullet."""
    spec, kin, world = setup
    base = ([0.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0])
    q0 = spec.default_pose.copy()
    world.set_pose(*base, q0)
    ref_pb, ref_pin = world.foot_positions(), kin.foot_positions(*base, q0)
    for i in range(12):
        q = q0.copy()
        q[i] = spec.joint_lower[i] + 0.3 * (spec.joint_upper[i] - spec.joint_lower[i])
        world.set_pose(*base, q)
        d_pb = world.foot_positions() - ref_pb
        d_pin = kin.foot_positions(*base, q) - ref_pin
        assert np.abs(d_pb - d_pin).max() < 1e-6
        moved = np.linalg.norm(d_pin, axis=1) > 1e-6
        assert moved.tolist() == [leg == i // 3 for leg in range(4)], (i, moved)


def test_batch_fk(setup):
    spec, kin, _ = setup
    rng = np.random.default_rng(4)
    q = _random_q(spec, rng, 7)
    pos = rng.uniform(-1, 1, (7, 3))
    quat = random_quat(rng, 7)
    batch = kin.foot_positions_batch(q, pos, quat)
    single = np.stack([kin.foot_positions(p, r, a) for p, r, a in zip(pos, quat, q)])
    assert batch.shape == (7, 4, 3) and np.abs(batch - single).max() < 1e-12


def test_ik_round_trip(setup):
    """FK -> IK -> FK within 1e-4 m (solver tol 1e-6 m) for reachable targets, limits respected."""
    spec, kin, _ = setup
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(60):
        q_true = _random_q(spec, rng)
        pos, quat = rng.uniform([-1, -1, 0.1], [1, 1, 0.6]), random_quat(rng)
        targets = kin.foot_positions(pos, quat, q_true)
        q, residual = kin.leg_ik(targets, pos, quat)  # from the default pose
        assert q.shape == (12,) and residual.shape == (4,)
        assert kin.within_limits(q, tol=0.0)
        assert np.abs(joint_limit_violation(spec, q)).max() == 0.0
        err = np.linalg.norm(kin.foot_positions(pos, quat, q) - targets, axis=1)
        assert np.allclose(err, residual, atol=1e-12)
        worst = max(worst, err.max())
    assert worst < 1e-4


def test_ik_body_frame_and_unreachable(setup):
    spec, kin, _ = setup
    feet = kin.foot_positions_body(spec.default_pose)
    q, res = kin.leg_ik(feet, frame="body", q_init=np.clip(spec.default_pose + 0.2, spec.joint_lower,
                                                           spec.joint_upper))
    assert res.max() < 1e-6 and np.abs(q - spec.default_pose).max() < 1e-4
    # FR target far out of reach: a finite residual, the closest point in limits, other legs exact
    far = feet.copy()
    far[0] += [0.0, 0.0, -5.0]
    q, res = kin.leg_ik(far, frame="body")
    assert res[0] > 4.0 and res[1:].max() < 1e-6 and kin.within_limits(q, tol=0.0)
    with pytest.raises(ValueError):
        kin.leg_ik(feet)  # world frame needs a base pose
    with pytest.raises(ValueError):
        kin.leg_ik(feet[:3], frame="body")


def test_ik_trajectory_fast_and_exact(setup):
    spec, kin, _ = setup
    n = 500
    t = np.arange(n) / 50.0
    phase = np.array([0.0, np.pi, np.pi, 0.0]).repeat(3)
    amp = np.tile([0.08, 0.3, 0.3], 4)
    q_true = spec.clip_to_limits(spec.default_pose + amp * np.sin(2 * np.pi * 2 * t[:, None] + phase))
    pos = np.stack([0.4 * t, 0.02 * np.sin(t), spec.spawn_height + 0.01 * np.sin(5 * t)], axis=1)
    quat = np.array([quat_from_euler(0.05 * np.sin(a), 0.05 * np.cos(a), 0.3 * a) for a in t])
    targets = kin.foot_positions_batch(q_true, pos, quat)
    t0 = time.perf_counter()
    q, res = kin.ik_trajectory(targets, pos, quat)
    elapsed = time.perf_counter() - t0
    assert q.shape == (n, 12) and res.shape == (n, 4)
    assert res.max() < 1e-6 and np.abs(q - q_true).max() < 1e-3
    assert elapsed < 4.0, f"{n} frames took {elapsed:.2f} s"


def test_laikago_continuous_joints():
    spec = robots.get("laikago")
    kin = Kinematics(spec)
    assert kin.nq.tolist() == [2] * 12 and kin.model.nq == 7 + 24 and kin.model.nv == 6 + 12
    # Pinocchio orders legs FL, FR, RL, RR: its indices are not the canonical order
    assert kin.idx_q.tolist() != sorted(kin.idx_q.tolist())
    q = spec.default_pose.copy()
    q[1] = 3.3                     # FR hip beyond pi: stored as (cos, sin), read back unwrapped
    q[4] = -1.2
    qp = kin.q_pin([0.1, 0.2, 0.5], [0, 0, 0, 1], q)
    i = kin.idx_q[1]
    assert np.allclose(qp[i:i + 2], [np.cos(3.3), np.sin(3.3)])
    assert np.allclose(np.hypot(qp[7::2], qp[8::2]), 1.0)
    assert np.allclose(kin.q12(qp), q, atol=1e-12)
    base_pos, base_quat = kin.base_pose(qp)
    assert np.allclose(base_pos, [0.1, 0.2, 0.5]) and np.allclose(base_quat, [0, 0, 0, 1])
    with quiet_fd(1):
        world = World(spec)
    try:
        world.set_pose([0.1, 0.2, 0.5], [0, 0, 0, 1], q)
        assert np.abs(world.foot_positions() - kin.foot_positions([0.1, 0.2, 0.5], [0, 0, 0, 1], q)).max() < 1e-6
    finally:
        world.close()


def test_pupper_revolute_joints():
    kin = Kinematics(robots.get("pupper"))
    assert kin.nq.tolist() == [1] * 12 and kin.model.nq == 19
    q = np.linspace(-0.5, -0.3, 12)
    assert np.allclose(kin.q12(kin.q_pin(q12=q)), q)
    with pytest.raises(ValueError):
        Kinematics(robots.get("pupper"), floating_base=False).q_pin([0, 0, 1], None, q)


@pytest.mark.skipif(not (MOTIONS / "dog_pace.txt").is_file(), reason="shared motions folder absent")
def test_laikago_clip_root_conversion_on_real_clip():
    """motion_imitation clip roots, converted, stand the z-up Laikago upright with toes near the ground."""
    spec = robots.get("laikago")
    kin = Kinematics(spec)
    frames = np.array(json.loads((MOTIONS / "dog_pace.txt").read_text())["Frames"])
    pos, quat = laikago_clip_root_to_zup(frames[:, :3], frames[:, 3:7])
    up = quat_to_matrix(quat)[:, 2, 2]
    assert up.min() > 0.9                                      # base z axis points up
    feet = kin.foot_positions_batch(frames[:, 7:], pos, quat)
    lowest = feet[:, :, 2].min(axis=1) - spec.foot_radius      # lowest toe bottom per frame
    assert np.abs(lowest).max() < 0.03, lowest
    assert (joint_limit_violation(spec, frames[:, 7:]) < 0.05).all()
