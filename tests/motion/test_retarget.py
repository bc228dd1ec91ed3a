"""Retargeting Laikago clips onto Pupper, and the ground-contact table of every shared clip."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.motion import contacts, motion_io, retarget
from virl_quad.kinematics import Kinematics


def test_leg_lengths():
    assert retarget.leg_length(Kinematics(robots.get("pupper"))) == pytest.approx(0.19, abs=1e-6)
    assert retarget.leg_length(Kinematics(robots.get("laikago"))) == pytest.approx(0.50, abs=0.01)


def test_retarget_to_same_robot_is_identity(gait_motions):
    m = gait_motions[("pupper", "trot")]
    assert retarget.retarget(m, "pupper") is m


def test_dog_trot_on_pupper(motions_dir):
    src = motion_io.read_motion(motions_dir / "dog_trot.txt")
    m, residual = retarget.retarget_with_residual(src, "pupper")
    spec = robots.get("pupper")
    k = 0.19 / retarget.leg_length(Kinematics(robots.get("laikago")))
    assert m.robot == "pupper" and m.loop == src.loop and m.duration == pytest.approx(src.duration)
    assert residual.max() < 2e-3                                           # feet placed
    assert np.all(m.q >= spec.joint_lower - 1e-9) and np.all(m.q <= spec.joint_upper + 1e-9)
    np.testing.assert_allclose(m.cycle_displacement[:2], k * src.cycle_displacement[:2], atol=1e-9)
    assert np.mean(m.root_pos[:, 2]) == pytest.approx(0.15, abs=0.03)    # Pupper-sized base height
    s = contacts.ground_contact(m)
    assert s.ok and s.max_penetration < 0.01


def test_contact_table_every_clip_both_robots(motions_dir):
    rows = contacts.contact_table(motions_dir)
    files = contacts.motion_files(motions_dir)
    assert len(rows) == 2 * len(files) and len(files) >= 10
    table = contacts.format_table(rows)
    assert "dog_trot.txt" in table and "pupper" in table
    bad = [(r.clip, r.robot) for r in rows if not r.ok]
    assert not bad, table
    for r in rows:
        assert r.max_penetration <= contacts.SINK and r.median_low <= contacts.TOUCH


def test_missing_motion_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="motion folder not found"):
        contacts.motion_files(tmp_path / "nope")
