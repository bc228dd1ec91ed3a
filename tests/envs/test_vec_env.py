"""The rsl-rl VecEnv: auto-reset, time-out semantics, worker processes."""

from __future__ import annotations

import pytest
import torch
from rsl_rl.env import VecEnv

from virl_quad.envs.vec_env import QuadrupedVecEnv

FOLD = torch.tensor([0.0, -2.0, 2.0] * 4)  # makes Pupper collapse (see test_env)


@pytest.fixture(scope="module")
def venv():
    env = QuadrupedVecEnv("pupper", 4, num_workers=2, seed=0, episode_seconds=0.1, randomize=False)
    yield env
    env.close()


def test_is_rsl_rl_vec_env(venv) -> None:
    assert isinstance(venv, VecEnv)
    obs = venv.get_observations()
    assert set(obs.keys()) >= {"policy", "privileged", "agent_image"}
    assert obs["policy"].shape == (4, 44) and obs["agent_image"].dtype == torch.uint8   # no demo: no phase
    assert venv.num_actions == 12 and venv.contract.tg is None
    assert venv.max_episode_length == 5  # 0.1 s at 50 Hz


def test_time_outs_follow_episode_length_buf(venv) -> None:
    venv.episode_length_buf[:] = torch.tensor([0, 1, 2, 3])  # as a runner randomising start lengths
    seen = []
    for _ in range(5):
        _, rew, dones, extras = venv.step(torch.zeros(4, 12))
        seen.append(extras["time_outs"].clone())
        assert torch.equal(dones, extras["time_outs"] | extras["terminated"])
        assert torch.all(rew == 0)
    seen = torch.stack(seen)  # (step, env)
    # env i times out after 5 - i steps, then restarts from 0
    expected = torch.zeros(5, 4, dtype=torch.bool)
    for i in range(4):
        expected[4 - i, i] = True
    assert torch.equal(seen, expected)
    assert torch.equal(venv.episode_length_buf, torch.tensor([0, 1, 2, 3]))


def test_auto_reset_after_fall() -> None:
    env = QuadrupedVecEnv("pupper", 2, num_workers=0, seed=0, episode_seconds=10.0, randomize=False)
    start = env.get_observations()["privileged"][:, 3].clone()  # base height (m)
    actions = torch.stack([FOLD, torch.zeros(12)])
    for _ in range(200):
        obs, _, dones, extras = env.step(actions)
        if dones[0]:
            break
    assert dones[0] and extras["terminated"][0] and not extras["time_outs"][0]
    assert not dones[1]
    # the returned observation is the new episode's: back at the spawn height
    assert abs(float(obs["privileged"][0, 3]) - float(start[0])) < 0.01
    assert env.episode_length_buf[0] == 0 and env.episode_length_buf[1] > 0
    # the final frame of the finished episode is kept for the reward
    assert extras["final_agent_image"].shape == (2, 48, 48)
    assert not torch.equal(extras["final_agent_image"][0], obs["agent_image"][0])
    env.close()


def test_worker_layout_does_not_change_results() -> None:
    runs = []
    for workers in (0, 2):
        env = QuadrupedVecEnv("pupper", 3, num_workers=workers, seed=11, episode_seconds=0.3)
        torch.manual_seed(0)
        out = [env.step(torch.randn(3, 12))[0]["policy"] for _ in range(20)]
        runs.append(torch.stack(out))
        env.close()
    assert torch.equal(runs[0], runs[1])


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="unknown robot"):
        QuadrupedVecEnv("spot", 2, num_workers=0)
    with pytest.raises(ValueError, match="num_envs"):
        QuadrupedVecEnv("pupper", 0, num_workers=0)
    env = QuadrupedVecEnv("pupper", 2, num_workers=0)
    with pytest.raises(ValueError, match="actions must be"):
        env.step(torch.zeros(3, 12))
    env.close()


def test_a_trajectory_generator_takes_14_actions() -> None:
    from virl_quad import robots
    from virl_quad.motion.gaits import gait_params
    from virl_quad.training.prior import gait_tg

    tg = gait_tg(robots.get("pupper"), gait_params("pupper", "trot"))
    env = QuadrupedVecEnv("pupper", 2, num_workers=0, seed=0, episode_seconds=0.1, randomize=False, render=False, tg=tg)
    try:
        assert env.num_actions == 14 and env.contract.tg == tg and env.cfg["tg"] == tg.to_dict()
        assert env.get_observations()["policy"].shape == (2, 48)       # 14 last actions, the TG's phase
        env.step(torch.zeros(2, 14))
        with pytest.raises(ValueError, match="14"):
            env.step(torch.zeros(2, 12))
    finally:
        env.close()


def test_the_robot_spec_object_reaches_the_workers() -> None:
    """A RobotSpec is passed whole, not looked up again by name: a spec the registry does not
    know (another name, a shorter episode) builds and steps in a worker process."""
    import dataclasses

    from virl_quad import robots

    spec = dataclasses.replace(robots.get("pupper"), name="pupper-variant", episode_seconds=0.5)
    env = QuadrupedVecEnv(spec, 2, num_workers=1, render=False)
    try:
        assert env.max_episode_length == 25 and env.cfg["robot"] == "pupper-variant"
        obs, _, _, _ = env.step(torch.zeros(2, env.num_actions))
        assert torch.isfinite(obs["policy"]).all()
    finally:
        env.close()


def test_an_env_worker_does_not_load_torch(tmp_path) -> None:
    """A spawned worker unpickles its arguments (a demonstration, a trajectory generator) and
    steps its envs without torch: importing it would cost every worker about 2 s at start."""
    import pickle
    import subprocess
    import sys

    from virl_quad import demo as demo_lib
    from virl_quad import robots
    from virl_quad.motion.gaits import gait_params
    from virl_quad.training.prior import gait_tg

    spec = robots.get("pupper")
    overrides = {"demo": demo_lib.load("trot", "pupper"), "tg": gait_tg(spec, gait_params("pupper", "trot")),
                 "randomize": True}
    args = tmp_path / "args.pkl"
    args.write_bytes(pickle.dumps(("pupper", [0, 1], 0, overrides)))
    code = ("import pickle, sys\nimport numpy as np\nfrom virl_quad.envs.workers import Slice\n"
            f"s = Slice(*pickle.loads(open({str(args)!r}, 'rb').read()))\n"
            "s.reset_all()\ns.step(np.zeros((2, 14)), np.zeros(2, bool))\nprint('torch' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_two_groups_step_the_same_envs_as_one() -> None:
    torch.manual_seed(0)
    actions = torch.randn(20, 5, 12)
    runs = []
    for workers in (0, 2):     # in this process: one group; two worker processes: two groups
        env = QuadrupedVecEnv("pupper", 5, num_workers=workers, seed=4, episode_seconds=0.2)
        assert len(env.groups) == (2 if workers else 1)
        out = []
        for a in actions:
            obs, rew, dones, extras = env.step(a)
            out.append(torch.cat([obs["policy"].flatten(), obs["agent_image"].flatten().float(), dones.float(),
                                  extras["final_agent_image"].flatten().float(), rew]))
        runs.append(torch.stack(out))
        if workers:   # a group stepped on its own: only its envs move, in its own env order
            lo, hi = env.groups[1]
            before = env.get_observations()["policy"].clone()
            env.step_async(torch.zeros(hi - lo, 12), 1)
            obs, _, dones, _ = env.step_wait(1)
            assert obs.batch_size == torch.Size([hi - lo]) and dones.shape == (hi - lo,)
            after = env.get_observations()["policy"]
            assert torch.equal(after[:lo], before[:lo]) and not torch.equal(after[lo:], before[lo:])
            with pytest.raises(RuntimeError, match="out of order"):
                env._workers.gather(0)
        env.close()
    assert torch.equal(runs[0], runs[1])
