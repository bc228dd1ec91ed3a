"""Ground-truth imitation score: playback scores 1.0, a standing robot far less, phase search works."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.demo import render
from virl_quad.evaluation import rollout, score

TERMS = list(score.TERMS)


def _setup(gait_motions, robot="pupper", gait="trot", seconds=2.0):
    spec = robots.get(robot)
    m = render.fit_loop(gait_motions[(robot, gait)], spec.control_hz)
    times = 0.3 + np.arange(int(seconds * spec.control_hz)) / spec.control_hz
    return spec, m, times


def _hold(spec, n, x):
    root = np.column_stack([x, np.zeros(n), np.full(n, spec.spawn_height)])
    return score.Trajectory(root_pos=root, root_quat=np.tile([0, 0, 0, 1.0], (n, 1)),
                            q=np.tile(spec.default_pose, (n, 1)), dq=np.zeros((n, 12)),
                            root_lin_vel=np.zeros((n, 3)), root_ang_vel=np.zeros((n, 3)))


def test_weights_sum_to_one():
    assert sum(w for w, _ in score.TERMS.values()) == pytest.approx(1.0)
    assert [s for _, s in score.TERMS.values()] == [5, 0.1, 40, 20, 2]


@pytest.mark.parametrize("robot", ["pupper", "laikago"])
def test_playback_scores_one_and_standing_far_less(gait_motions, robot):
    spec, m, times = _setup(gait_motions, robot)
    playback = score.Trajectory(**m.sample(times))
    res = score.score_trajectory(playback, m, times, robot)
    for k in TERMS + ["total", "total_best_offset"]:
        assert res[k] == pytest.approx(1.0, abs=1e-9), k
    assert res["best_offset"] == 0.0
    hold = score.score_trajectory(_hold(spec, len(times), playback.root_pos[:, 0]), m, times, robot)
    assert hold["total"] < 0.5 and hold["pose"] < 0.2 and hold["total_best_offset"] < 0.5


def test_quarter_cycle_shift_is_found(gait_motions):
    spec, m, times = _setup(gait_motions)
    shifted = score.Trajectory(**m.sample(times + m.duration / 4))
    res = score.score_trajectory(shifted, m, times, "pupper")
    assert res["total"] < 0.6
    assert res["total_best_offset"] == pytest.approx(1.0, abs=1e-6)
    assert res["best_offset"] == pytest.approx(m.duration / 4, abs=1e-9)


def test_term_errors_are_what_they_say(gait_motions):
    spec, m, times = _setup(gait_motions, seconds=0.2)
    ref = score.Trajectory(**m.sample(times))
    moved = score.Trajectory(**m.sample(times))
    moved.q = moved.q + 0.1                       # 12 x 0.01 rad^2
    moved.root_pos = moved.root_pos + [5.0, -3.0, 0.02]   # far away in x, y: ignored; 2 cm higher
    from virl_quad.kinematics import Kinematics
    kin = Kinematics(spec)
    e = score.term_errors(moved, score.reference_trajectory(m, times, kin), kin)
    np.testing.assert_allclose(e["pose"], 0.12, atol=1e-9)
    np.testing.assert_allclose(e["root_pose"], 0.02 ** 2, atol=1e-12)
    np.testing.assert_allclose(e["root_velocity"], 0.0, atol=1e-12)
    assert np.all(e["end_effector"] > 0)          # joint change moves the feet relative to the root
    # feet relative to the root in the heading frame: a pure yaw of everything changes nothing
    from scipy.spatial.transform import Rotation
    yaw = Rotation.from_euler("z", 1.0)
    turned = score.Trajectory(root_pos=yaw.apply(ref.root_pos), root_quat=(yaw * Rotation.from_quat(ref.root_quat)).as_quat(),
                              q=ref.q, dq=ref.dq, root_lin_vel=yaw.apply(ref.root_lin_vel),
                              root_ang_vel=yaw.apply(ref.root_ang_vel))
    e2 = score.term_errors(turned, score.reference_trajectory(m, times, kin), kin)
    np.testing.assert_allclose(e2["end_effector"], 0.0, atol=1e-12)
    np.testing.assert_allclose(e2["root_velocity"], 0.0, atol=1e-12)


def test_term_errors_match_rotation_algebra_on_tilted_random_states(gait_motions):
    """The numpy heading and angle algebra gives scipy Rotation's figures for arbitrary (tilted,
    turned) states: headings from the rotated x axis, angles of R_ref^T R."""
    from scipy.spatial.transform import Rotation

    from virl_quad.kinematics import Kinematics

    rng = np.random.default_rng(4)
    kin = Kinematics(robots.get("pupper"))

    def random_traj(n=50):
        return score.Trajectory(root_pos=rng.normal(size=(n, 3)), root_quat=Rotation.random(n, rng=rng).as_quat(),
                                q=rng.normal(size=(n, 12)), dq=rng.normal(size=(n, 12)),
                                root_lin_vel=rng.normal(size=(n, 3)), root_ang_vel=rng.normal(size=(n, 3)),
                                feet=rng.normal(size=(n, 4, 3)))

    a, b = random_traj(), random_traj()
    e = score.term_errors(a, b, kin)

    def unheaded(t, v):
        x = Rotation.from_quat(t.root_quat).apply([1.0, 0.0, 0.0])
        r = Rotation.from_euler("z", -np.arctan2(x[:, 1], x[:, 0])[:, None])
        return np.stack([r.apply(v[:, k]) for k in range(v.shape[1])], axis=1) if v.ndim == 3 else r.apply(v)

    feet = unheaded(a, a.feet - a.root_pos[:, None]) - unheaded(b, b.feet - b.root_pos[:, None])
    angle = (Rotation.from_quat(b.root_quat).inv() * Rotation.from_quat(a.root_quat)).magnitude()
    dv = unheaded(a, a.root_lin_vel) - unheaded(b, b.root_lin_vel)
    dw = unheaded(a, a.root_ang_vel) - unheaded(b, b.root_ang_vel)
    np.testing.assert_allclose(e["end_effector"], np.sum(feet ** 2, axis=(1, 2)), rtol=1e-10)
    np.testing.assert_allclose(e["root_pose"], (a.root_pos[:, 2] - b.root_pos[:, 2]) ** 2 + 0.5 * angle ** 2, rtol=1e-10)
    np.testing.assert_allclose(e["root_velocity"], np.sum(dv ** 2, axis=1) + 0.1 * np.sum(dw ** 2, axis=1), rtol=1e-10)
    assert np.all(angle > 1e-3)                         # the states differ: the test can fail


def test_evaluate_a_policy_in_the_environment(gait_motions, tmp_path):
    demo = render.render_demonstration(gait_motions[("laikago", "trot")], "laikago", min_seconds=0.5)
    res = rollout.evaluate(lambda obs: np.zeros(12), "laikago", demo, episodes=2, seed=3, episode_seconds=1.0,
                         randomize=False, video=str(tmp_path / "eval.mp4"))
    for k in TERMS + ["total", "total_best_offset", "survival_fraction", "speed_ratio"]:
        assert np.isfinite(res[k]), k
    assert 0 < res["total"] < 0.8 and 0 < res["survival_fraction"] <= 1.0
    assert len(res["episodes"]) == 2 and (tmp_path / "eval.mp4").stat().st_size > 0


def test_evaluate_needs_a_motion():
    from virl_quad.demo.demonstration import Demonstration
    d = Demonstration(frames=np.zeros((5, 48, 48), np.uint8), fps=50.0)
    with pytest.raises(ValueError, match="no reference motion"):
        rollout.evaluate(lambda o: np.zeros(12), "pupper", d, episodes=1)
