"""The pipelined rollout stores what an in-step rollout would: every transition's observation,
action, log-probability, value, reward and done belong together, in env order."""

from __future__ import annotations

import contextlib
import io

import pytest
import torch
from tensordict import TensorDict

from virl_quad.envs.vec_env import QuadrupedVecEnv
from virl_quad.training.algorithm import VirlPPO
from virl_quad.training.config import TrainArgs, rsl_rl_config
from virl_quad.training.rewards import EnvReward
from virl_quad.training.rollout import rollout

STEPS = 6


class Recording:
    """A real VecEnv that remembers, per group, the actions each step was sent and what it gave."""

    def __init__(self, env: QuadrupedVecEnv) -> None:
        self.env = env
        self.num_envs, self.num_actions, self.device, self.groups = env.num_envs, env.num_actions, env.device, env.groups
        self.sent = [[] for _ in env.groups]
        self.got = [[] for _ in env.groups]

    def get_observations(self) -> TensorDict:
        return self.env.get_observations()

    def step_async(self, actions: torch.Tensor, group: int) -> None:
        self.sent[group].append(actions.clone())
        self.env.step_async(actions, group)

    def step_wait(self, group: int):
        out = self.env.step_wait(group)
        self.got[group].append((out[0]["policy"].clone(), out[2].clone(), out[3]["time_outs"].clone()))
        return out

    def step_of_all(self, k: int) -> tuple[torch.Tensor, ...]:
        """Step k of every env: (actions, next policy observations, dones, time-outs)."""
        return (torch.cat([s[k] for s in self.sent]),
                *(torch.cat([g[k][i] for g in self.got]) for i in range(3)))


def _ppo(env) -> VirlPPO:
    cfg = rsl_rl_config(TrainArgs.make(hidden="8", steps_per_env=STEPS))
    cfg["algorithm"]["class_name"] = VirlPPO
    cfg["multi_gpu"] = None
    with contextlib.redirect_stdout(io.StringIO()):
        alg = VirlPPO.construct_algorithm(env.get_observations(), env, cfg, "cpu")
    alg.attach_reward(EnvReward())
    alg.train_mode()
    return alg


@pytest.mark.parametrize("workers, groups", [(2, 2), (0, 1)])   # worker processes; this process
def test_a_rollout_stores_each_transition_whole_and_in_env_order(workers: int, groups: int) -> None:
    env = QuadrupedVecEnv("pupper", 4, num_workers=workers, seed=3, episode_seconds=0.1, render=False)
    try:
        assert len(env.groups) == groups
        env.episode_length_buf[:] = torch.tensor([0, 1, 2, 3])   # envs time out at different steps
        rec = Recording(env)
        alg = _ppo(rec)
        obs0 = env.get_observations()["policy"].clone()
        ended = []
        last = rollout(alg, rec, env.get_observations(), STEPS, ended.append)
        st = alg.storage
        assert st.step == STEPS and len(ended) == STEPS
        before = obs0
        for k in range(STEPS):
            actions, after, dones, time_outs = rec.step_of_all(k)
            obs_k = TensorDict({key: st.observations[key][k] for key in st.observations.keys()}, batch_size=[4])
            assert torch.equal(obs_k["policy"], before)                     # the observation acted on
            assert torch.equal(st.actions[k], actions)                      # the actions the envs got
            assert torch.equal(st.dones[k].view(-1).bool(), dones) and torch.equal(ended[k], dones)
            with torch.inference_mode():
                values = alg.critic(obs_k)
                alg.actor(obs_k, stochastic_output=True)
                log_prob = alg.actor.get_output_log_prob(actions)
            assert torch.allclose(st.values[k], values)
            assert torch.allclose(st.actions_log_prob[k].view(-1), log_prob.view(-1))
            # no task reward: what is stored is the time-out bootstrap of the env's own value
            assert torch.allclose(st.rewards[k].view(-1), alg.gamma * values.view(-1) * time_outs.float())
            before = after
        assert torch.equal(last["policy"], before)
        assert any(bool(rec.step_of_all(k)[3].any()) for k in range(STEPS))    # time-outs were tested
    finally:
        env.close()

