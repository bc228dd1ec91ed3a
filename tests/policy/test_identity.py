"""The training env and the policy server give identical joint targets for identical inputs.

A QuadrupedEnv (real PyBullet, nominal robot: no latency, no noise) is driven by an exported
random actor; every state it reaches is also sent, as STATE bytes, to the policy server's
``PolicyRunner`` running the same exported policy. The command's targets must equal the env's
targets for the action it took from its own observation: observation (heading, clock phase,
last action), action clip, trajectory generator, rate limit and joint limits all agree.
"""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import demo as demo_lib
from virl_quad import envs, robots
from virl_quad.motion.gaits import gait_params
from virl_quad.deploy import protocol as P
from virl_quad.deploy.serve import PolicyRunner
from virl_quad.export import export_actor, fresh_actor
from virl_quad.policy_io import load_policy
from virl_quad.training.prior import gait_tg

STEPS = 60


def _state(s) -> P.RobotState:
    st = P.RobotState.zeros(s.q)
    st.dq, st.quat, st.gyro = s.dq.copy(), s.base_quat.copy(), s.base_ang_vel_body.copy()
    return st


@pytest.mark.parametrize("robot,with_tg", [("pupper", True), ("laikago", True), ("pupper", False)])
def test_env_and_server_targets_are_identical(robot: str, with_tg: bool, tmp_path) -> None:
    spec = robots.get(robot)
    tg = gait_tg(spec, gait_params(robot, "trot")) if with_tg else None
    demo = None if with_tg else demo_lib.load("trot", robot)           # without a TG: the demonstration's clock
    env = envs.make(robot, tg=tg, demo=demo, randomize=False, render=False, rsi=False)
    contract = env.unwrapped.contract
    policy = load_policy(export_actor(fresh_actor(contract, seed=5), robot, tmp_path / "p.pt", contract))
    runner = PolicyRunner(policy)
    u = env.unwrapped
    try:
        obs, _ = env.reset(seed=3, options={"demo_step": 0})
        base = u.state.base_quat.copy()
        turned = False
        for k in range(STEPS):
            out, reason = runner.handle(P.encode_state(_state(u.state), k + 1, active=True))
            assert reason == "" and out is not None
            action = policy.act(obs["policy"])
            obs, _, terminated, _, _ = env.step(action)
            np.testing.assert_allclose(P.decode(out).body.q_target, u.last_target, rtol=0, atol=1e-9)
            np.testing.assert_allclose(runner.last_action, u.last_action, rtol=0, atol=1e-9)
            assert runner.phase() == pytest.approx(u.actions.phase, abs=1e-12)
            turned |= abs(float(u.state.base_quat @ base)) < 0.9999        # the heading has something to show
            if terminated:
                break
        assert k > 10 and turned, (k, turned)
        if with_tg:
            assert policy.action_size == 14 and np.abs(runner.last_action[12:]).max() > 0   # modulation in use
    finally:
        env.close()


def test_a_diverging_server_is_caught(tmp_path) -> None:
    """The comparison above can fail: a server whose heading origin is off by 0.3 rad (or whose
    clock runs at another phase) sends other targets for the same states."""
    spec = robots.get("pupper")
    tg = gait_tg(spec, gait_params("pupper", "trot"))
    env = envs.make("pupper", tg=tg, randomize=False, render=False)
    contract = env.unwrapped.contract
    policy = load_policy(export_actor(fresh_actor(contract, seed=5), "pupper", tmp_path / "p.pt", contract))
    u = env.unwrapped
    try:
        for tamper in ("yaw", "phase"):
            runner = PolicyRunner(policy)
            obs, _ = env.reset(seed=3)
            differ = False
            for k in range(10):
                out, _ = runner.handle(P.encode_state(_state(u.state), k + 1, active=True))
                if k == 0 and tamper == "yaw":
                    runner.start_yaw += 0.3
                if k == 0 and tamper == "phase":
                    runner.actions.clock.reset(0.5)
                obs, *_ = env.step(policy.act(obs["policy"]))
                differ |= not np.allclose(P.decode(out).body.q_target, u.last_target, rtol=0, atol=1e-9)
            assert differ, tamper
    finally:
        env.close()
