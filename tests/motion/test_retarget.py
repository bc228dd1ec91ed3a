"""Retargeting Laikago clips onto Pupper, and the ground-contact table of every shared clip."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from virl_quad import robots
from virl_quad.motion import contacts, motion_io, retarget
from virl_quad.kinematics import Kinematics
from virl_quad.policy.legs import leg_length


def _model_leg_length(kin: Kinematics) -> float:
    """Mean leg length (m) measured on the Pinocchio model: hip pitch joint -> knee joint -> foot frame."""
    pin.framesForwardKinematics(kin.model, kin.data, kin.q_pin(q12=np.zeros(12)))
    total = 0.0
    for leg in range(4):
        hip = kin.data.oMi[int(kin.joint_ids[3 * leg + 1])].translation
        knee = kin.data.oMi[int(kin.joint_ids[3 * leg + 2])].translation
        foot = kin.data.oMf[kin.foot_frame_ids[leg]].translation
        total += np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee)
    return total / 4.0


@pytest.mark.parametrize("robot, expected", [("pupper", 0.19), ("laikago", 0.50)])
def test_leg_length_of_the_spec_matches_the_urdf(robot: str, expected: float) -> None:
    spec = robots.get(robot)
    assert leg_length(spec) == pytest.approx(expected, abs=0.01)
    assert leg_length(spec) == pytest.approx(_model_leg_length(Kinematics(spec)), rel=5e-3)


def test_retarget_to_same_robot_is_identity(gait_motions):
    m = gait_motions[("pupper", "trot")]
    assert retarget.retarget(m, "pupper") is m


def test_dog_trot_on_pupper(motions_dir):
    src = motion_io.read_motion(motions_dir / "dog_trot.txt")
    m, residual = retarget.retarget_with_residual(src, "pupper")
    spec = robots.get("pupper")
    k = leg_length(robots.get("pupper")) / leg_length(robots.get("laikago"))
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
