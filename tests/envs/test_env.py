"""The gymnasium env: API conformance, determinism, termination, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from virl_quad import robots
from virl_quad.envs import make

ROBOTS = robots.names()


@pytest.mark.parametrize("robot", ROBOTS)
def test_check_env(robot: str) -> None:
    env = make(robot)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs["agent_image"].dtype == np.uint8 and obs["agent_image"].shape == (48, 48)
    assert obs["agent_image"].std() > 5, "the camera frame should show something"
    env.close()


def _rollout(robot: str, seed: int, steps: int = 40) -> np.ndarray:
    env = make(robot)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs["policy"]]
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-1, 1, 12))
        out.append(np.concatenate([obs["policy"], obs["privileged"], obs["agent_image"].ravel()]))
    env.close()
    return np.concatenate([o.ravel() for o in out])


@pytest.mark.parametrize("robot", ROBOTS)
def test_same_seed_same_trajectory(robot: str) -> None:
    a, b, c = _rollout(robot, 3), _rollout(robot, 3), _rollout(robot, 4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_reset_does_not_depend_on_previous_episode() -> None:
    env = make("laikago")
    first, _ = env.reset(seed=7)
    a = np.ones(12)
    after_one = env.step(a)[0]["policy"]
    for _ in range(20):
        env.step(-a)
    env.reset(seed=7)
    np.testing.assert_array_equal(env.step(a)[0]["policy"], after_one)
    env.close()


def test_collapse_terminates() -> None:
    env = make("pupper", randomize=False)
    env.reset(seed=0)
    folded = np.array([0.0, -2.0, 2.0] * 4)  # hip forward, knee straight: the body drops
    for step in range(200):
        *_, terminated, truncated, _ = env.step(folded)
        if terminated:
            break
    assert terminated and not truncated
    env.close()


def test_time_limit_truncates() -> None:
    env = make("pupper", randomize=False, episode_seconds=0.2)
    env.reset(seed=0)
    flags = [env.step(np.zeros(12))[2:4] for _ in range(10)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])
    env.close()


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="pupper, laikago"):
        make("spot")
    with pytest.raises(ValueError, match="valid options"):
        make("pupper", bogus=1)
    with pytest.raises(ValueError, match="choose from"):
        make("pupper", randomization={"gravity": (0, 1)})
    env = make("pupper")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full(12, np.nan))
    with pytest.raises(ValueError, match="12 entries"):
        env.step(np.zeros(3))
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_pd_holds_default_pose_under_randomisation(robot: str) -> None:
    """DR on, 50 seeds, 5 s each: holding the default pose never falls."""
    env = make(robot, render=False, episode_seconds=5.0)
    fell = []
    for seed in range(50):
        env.reset(seed=seed)
        for _ in range(env.unwrapped.max_steps):
            _, _, terminated, truncated, _ = env.step(np.zeros(12))
            if terminated:
                fell.append(seed)
                break
        assert terminated or truncated
    env.close()
    assert fell == []


def test_targets_move_at_most_the_safety_layers_step() -> None:
    from virl_quad.deploy.safety import SafetyConfig
    from virl_quad.robots.spec import MAX_TARGET_STEP

    assert SafetyConfig().max_step == MAX_TARGET_STEP   # training and robot share the limit
    spec = robots.get("pupper")
    env = make("pupper", randomize=False)
    env.reset(seed=0)
    u = env.unwrapped
    prev = u.last_target.copy()
    jump = np.array([0.0, 2.0, -2.0] * 4)               # 1 rad away for the hip and knee
    for _ in range(3):
        env.step(jump)
        step = np.abs(u.last_target - prev)
        assert step.max() <= MAX_TARGET_STEP + 1e-12 and step.max() > MAX_TARGET_STEP - 1e-9
        prev = u.last_target.copy()
    want = spec.clip_to_limits(spec.default_pose + u.action_scale * jump)
    for _ in range(10):
        env.step(jump)
    np.testing.assert_allclose(u.last_target, want)      # reached after enough steps
    env.close()
    free = make("pupper", randomize=False, max_target_step=None)
    free.reset(seed=0)
    free.step(jump)
    np.testing.assert_allclose(free.unwrapped.last_target, want)
    free.close()


def test_env_draws_the_demonstration_ground_and_refuses_another() -> None:
    from virl_quad import demo as demo_lib

    plain = demo_lib.load("trot", "pupper", ground="plain")
    assert plain.camera["ground"] == "plain"
    env = make("pupper", demo=plain, randomize=False)            # follows the demonstration
    obs, _ = env.reset(seed=0, options={"demo_step": 0})
    assert obs["agent_image"][40:].std() < 2.0                    # bottom rows: uniform ground
    env.close()
    with pytest.raises(ValueError, match="ground"):
        make("pupper", demo=plain, ground="checker")


def test_forward_speed_follows_the_heading_not_the_world_axes() -> None:
    from scipy.spatial.transform import Rotation

    from virl_quad.envs.quadruped import forward_speed, speed_reward

    yaw90 = Rotation.from_euler("z", np.pi / 2).as_quat()
    assert forward_speed(yaw90, np.array([0.0, 0.3, 0.0])) == pytest.approx(0.3)
    assert forward_speed(yaw90, np.array([0.3, 0.0, 0.0])) == pytest.approx(0.0, abs=1e-12)
    pitched = Rotation.from_euler("zy", [np.pi, 0.3]).as_quat()     # turned back, nose down
    assert forward_speed(pitched, np.array([0.2, 0.0, 0.5])) == pytest.approx(-0.2)
    assert speed_reward(0.2, 0.2) == 1.0 and speed_reward(0.0, 0.2) == pytest.approx(np.exp(-1.0))


def test_oracle_reward_mixes_the_score_with_the_forward_speed_term() -> None:
    from virl_quad import demo as demo_lib
    from virl_quad.envs.quadruped import forward_speed, speed_reward
    from virl_quad.evaluation.score import reference_trajectory

    demo = demo_lib.load("trot", "pupper")
    envs = [make("pupper", demo=demo, oracle_reward=True, oracle_speed_weight=w, render=False) for w in (0.0, 0.4)]
    for env in envs:
        env.reset(seed=3)
    for _ in range(15):
        (_, score, *_), (_, mixed, *_) = (env.step(np.zeros(12)) for env in envs)
    env = envs[1]
    ref = reference_trajectory(demo.motion, np.array([env.demo_step / demo.fps]), env._kin)
    s = env.world.state()
    v, v_ref = forward_speed(s.base_quat, s.base_lin_vel), forward_speed(ref.root_quat[0], ref.root_lin_vel[0])
    term = speed_reward(v, v_ref)
    assert mixed == pytest.approx(0.6 * score + 0.4 * term, rel=1e-9)
    assert abs(mixed - score) > 1e-3                      # the term changes the reward
    for env in envs:
        env.close()
    with pytest.raises(ValueError, match="oracle_speed_weight"):
        make("pupper", demo=demo, oracle_reward=True, oracle_speed_weight=1.5)


def test_oracle_reward_is_the_score_against_the_reference_at_each_step() -> None:
    """The env's reference table (sampled once) gives what sampling each step's reference does,
    across a reset and past the end of the demonstration's loop."""
    from virl_quad import demo as demo_lib
    from virl_quad.evaluation.score import Trajectory, reference_trajectory, term_errors, term_rewards

    demo = demo_lib.load("bound", "pupper")
    env = make("pupper", demo=demo, oracle_reward=True, oracle_speed_weight=0.0, render=False, episode_seconds=1.0)
    rng = np.random.default_rng(0)
    checked = 0
    for seed in (1, 2):
        env.reset(seed=seed)
        for _ in range(60):
            _, reward, terminated, truncated, _ = env.step(rng.uniform(-0.2, 0.2, 12))
            s = env.world.state()
            traj = Trajectory(root_pos=s.base_pos[None], root_quat=s.base_quat[None], q=s.q[None], dq=s.dq[None],
                              root_lin_vel=s.base_lin_vel[None], root_ang_vel=s.base_ang_vel[None],
                              feet=env.world.foot_positions()[None])
            ref = reference_trajectory(demo.motion, np.array([env.demo_step / demo.fps]), env._kin)
            assert reward == pytest.approx(float(term_rewards(term_errors(traj, ref, env._kin))["total"][0]), abs=1e-12)
            checked += 1
            if terminated or truncated:
                break
    assert checked > 60 and env.demo_step > demo.num_frames // 2
    env.close()


def test_standing_start_hands_over_as_the_hal_does() -> None:
    """stand_start: the robot stands at rest in (about) the default pose after the hold, the clock
    at phase 0, under randomisation; without it the same seeds start from the demonstration."""
    from virl_quad import demo as demo_lib
    from virl_quad.policy.observation import policy_block

    spec = robots.get("pupper")
    demo = demo_lib.load("trot", "pupper")
    for stand in (True, False):
        env = make("pupper", demo=demo, render=False, stand_start=stand, stand_seconds=2.0)   # randomised
        u = env.unwrapped
        phase = policy_block("phase_sin_cos", action_size=u.contract.action_size)
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            s = u.world.state()
            if not stand:       # RSI: mid-stride, somewhere in the demonstration
                assert u.world.time == 0.0 and np.abs(s.dq).max() > 0.5
                continue
            assert u.demo_step == 0 and u.world.time == pytest.approx(2.0)
            np.testing.assert_allclose(obs["policy"][phase], [0.0, 1.0], atol=1e-6)
            assert np.abs(s.dq).max() < 0.1 and np.abs(s.base_lin_vel).max() < 0.02      # rad/s, m/s: at rest
            assert np.abs(s.q - spec.default_pose).max() < 0.2 and s.base_pos[2] > spec.min_base_height
        env.close()
    with pytest.raises(ValueError, match="stand_seconds"):
        make("pupper", stand_start=True, stand_seconds=-1.0)
