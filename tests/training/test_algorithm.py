"""VirlPPO on a synthetic rollout (no simulation is stepped): the critic warm-up moves the critic
alone, the actor's normaliser stays fixed, the anchor pulls the actor back to the warm start, and
the first update at the default rate keeps the policy close; the runner's collapse warning."""

from __future__ import annotations

import contextlib
import io

import torch
from tensordict import TensorDict

from virl_quad.training.algorithm import VirlPPO
from virl_quad.training.config import TrainArgs, rsl_rl_config


class _Env:
    """The smallest VecEnv rsl-rl's PPO constructor reads (no simulation is stepped here)."""

    def __init__(self, envs: int = 4, obs: int = 5, actions: int = 3, privileged: int = 2) -> None:
        self.num_envs, self.num_actions, self.device = envs, actions, "cpu"
        self.sizes = {"policy": obs, "privileged": privileged}

    def get_observations(self) -> TensorDict:
        return TensorDict({k: torch.zeros(self.num_envs, n) for k, n in self.sizes.items()},
                          batch_size=[self.num_envs])


def _ppo(args: TrainArgs | None = None, env: _Env | None = None) -> VirlPPO:
    cfg = rsl_rl_config(args or TrainArgs.make(hidden="8"))
    cfg["algorithm"]["class_name"] = VirlPPO
    cfg["multi_gpu"] = None
    env = env or _Env()
    with contextlib.redirect_stdout(io.StringIO()):
        alg = VirlPPO.construct_algorithm(env.get_observations(), env, cfg, "cpu")
    return alg


def _fill(alg: VirlPPO, steps: int = 8, env: _Env | None = None) -> list[torch.Tensor]:
    """Store a rollout of random observations and rewards (``env``'s sizes, default
    :class:`_Env`'s); its policy observations."""
    gen = torch.Generator().manual_seed(0)
    env = env or _Env()
    n, sizes = env.num_envs, env.sizes
    alg.train_mode()
    seen = []
    for _ in range(steps):
        obs = TensorDict({k: torch.randn(n, m, generator=gen) for k, m in sizes.items()}, batch_size=[n])
        seen.append(obs["policy"])
        with torch.inference_mode():
            alg.act(obs)
            PPO_step = super(VirlPPO, alg).process_env_step
            PPO_step(obs, torch.randn(n, generator=gen), torch.zeros(n), {"time_outs": torch.zeros(n)})
    with torch.inference_mode():
        super(VirlPPO, alg).compute_returns(obs)
    return seen


def test_frozen_update_moves_the_critic_alone_and_keeps_the_learning_rate():
    alg = _ppo()
    _fill(alg)
    actor0 = {k: v.clone() for k, v in alg.actor.state_dict().items()}
    critic0 = {k: v.clone() for k, v in alg.critic.state_dict().items()}
    lr0 = alg.learning_rate
    alg.freeze_actor(1)
    alg.update()
    assert all(torch.equal(actor0[k], v) for k, v in alg.actor.state_dict().items())
    assert any(not torch.equal(critic0[k], v) for k, v in alg.critic.state_dict().items())
    assert alg.learning_rate == lr0 and alg.schedule == "adaptive" and alg.frozen_updates == 0
    assert all(p.requires_grad for p in alg.actor.mlp.parameters())
    _fill(alg)
    alg.update()                                   # unfrozen: the actor learns again
    assert any(not torch.equal(actor0[k], v) for k, v in alg.actor.state_dict().items())


def test_a_fixed_actor_normalizer_keeps_its_statistics():
    alg = _ppo()
    alg.fix_actor_normalizer()
    _fill(alg)
    mean = alg.actor.obs_normalizer._mean.clone()
    alg.update()
    assert torch.equal(alg.actor.obs_normalizer._mean, mean)
    assert not torch.equal(alg.critic.obs_normalizer._mean, torch.zeros_like(alg.critic.obs_normalizer._mean))


def test_the_prior_pull_moves_the_actor_part_of_the_way_back_to_the_warm_start():
    import copy

    alg = _ppo()
    _fill(alg)
    start = [p.detach().clone() for p in alg.actor.parameters()]
    free = copy.deepcopy(alg)
    alg.anchor_actor(0.25)
    torch.manual_seed(1)
    free.update()
    torch.manual_seed(1)
    alg.update()
    for p, q, p0 in zip(alg.actor.parameters(), free.actor.parameters(), start):
        torch.testing.assert_close(p, q + 0.25 * (p0 - q))          # theta <- theta + pull (theta_0 - theta)
    assert any(not torch.equal(p, p0) for p, p0 in zip(alg.actor.parameters(), start))
    alg.anchor_actor(0.0)
    assert alg.anchor is None


def test_a_pull_outside_0_1_is_refused():
    import pytest

    with pytest.raises(ValueError, match="prior pull"):
        _ppo().anchor_actor(1.0)


def test_a_collapsed_distance_model_is_reported_once_after_its_first_100_iterations():
    import types

    from virl_quad.training.runner import COLLAPSED_SPREAD, VirlRunner

    lines: list[str] = []
    runner = types.SimpleNamespace(_collapse_warned=False, _peak_spread=0.0)
    VirlRunner._warn_collapse(runner, 50, 1e-5, lines.append)             # early: not yet
    VirlRunner._warn_collapse(runner, 80, 0.08, lines.append)             # healthy, then ...
    VirlRunner._warn_collapse(runner, 150, 2 * COLLAPSED_SPREAD, lines.append)
    VirlRunner._warn_collapse(runner, 150, None, lines.append)            # no distance model
    assert lines == []
    VirlRunner._warn_collapse(runner, 150, 1e-5, lines.append)            # ... collapsed
    VirlRunner._warn_collapse(runner, 175, 1e-5, lines.append)
    assert len(lines) == 1 and lines[0].startswith("warning: the distance model's frame encoder has collapsed")
    assert "down from 0.08" in lines[0]


def test_an_encoder_that_never_spread_is_not_called_collapsed():
    import types

    from virl_quad.training.runner import VirlRunner

    lines: list[str] = []
    runner = types.SimpleNamespace(_collapse_warned=False, _peak_spread=0.0)
    for it, spread in ((1, 7e-4), (60, 1.6e-3), (120, 3e-4)):         # an untrained encoder's spread
        VirlRunner._warn_collapse(runner, it, spread, lines.append)
    assert len(lines) == 1 and "still encodes the demonstration's frames alike after 120 iterations" in lines[0]
    assert "collapsed" not in lines[0]


def test_the_first_actor_update_at_the_default_rate_keeps_the_policy_close():
    """Adam's first steps move every weight by about the learning rate, whatever the gradient's
    size: at the run's widths and action std (0.05) a rate far above the KL schedule's floor moves
    a warm-started policy's mean by about one std in one update."""
    args = TrainArgs.make()
    env = _Env(envs=16, obs=48, actions=14, privileged=8)
    alg = _ppo(args, env)
    seen = _fill(alg, steps=args.ppo.steps_per_env, env=env)
    seen = torch.cat(seen)
    batch = TensorDict({"policy": seen}, batch_size=[len(seen)])
    with torch.no_grad():
        alg.actor(batch, stochastic_output=True)
        before = [p.clone() for p in alg.actor.output_distribution_params]
    alg.update()
    with torch.no_grad():
        alg.actor(batch, stochastic_output=True)
        kl = alg.actor.get_kl_divergence(tuple(before), alg.actor.output_distribution_params).mean()
    assert abs(float(before[1].mean()) - args.ppo.init_std) < 1e-6
    assert kl < 0.3, f"KL of the first update {float(kl):.3g}"
