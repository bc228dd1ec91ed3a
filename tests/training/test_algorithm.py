"""VirlPPO's critic warm-up: while the actor is frozen an update moves the critic alone and
leaves the learning rate where it was."""

from __future__ import annotations

import contextlib
import io

import torch
from tensordict import TensorDict

from virl_quad.training.algorithm import VirlPPO
from virl_quad.training.config import TrainArgs, rsl_rl_config


class _Env:
    """The smallest VecEnv rsl-rl's PPO constructor reads (no simulation is stepped here)."""

    num_envs, num_actions, device = 4, 3, "cpu"

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.zeros(4, 5), "privileged": torch.zeros(4, 2)}, batch_size=[4])


def _ppo() -> VirlPPO:
    cfg = rsl_rl_config(TrainArgs.make(hidden="8"))
    cfg["algorithm"]["class_name"] = VirlPPO
    cfg["multi_gpu"] = None
    env = _Env()
    with contextlib.redirect_stdout(io.StringIO()):
        alg = VirlPPO.construct_algorithm(env.get_observations(), env, cfg, "cpu")
    return alg


def _fill(alg: VirlPPO, steps: int = 8) -> None:
    gen = torch.Generator().manual_seed(0)
    alg.train_mode()
    for _ in range(steps):
        obs = TensorDict({"policy": torch.randn(4, 5, generator=gen), "privileged": torch.randn(4, 2, generator=gen)},
                         batch_size=[4])
        with torch.inference_mode():
            alg.act(obs)
            PPO_step = super(VirlPPO, alg).process_env_step
            PPO_step(obs, torch.randn(4, generator=gen), torch.zeros(4), {"time_outs": torch.zeros(4)})
    with torch.inference_mode():
        super(VirlPPO, alg).compute_returns(obs)


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
    cfg = rsl_rl_config(args)
    cfg["algorithm"]["class_name"] = VirlPPO
    cfg["multi_gpu"] = None
    gen = torch.Generator().manual_seed(0)

    class Env:
        num_envs, num_actions, device = 16, 14, "cpu"

        def get_observations(self) -> TensorDict:
            return TensorDict({"policy": torch.zeros(16, 48), "privileged": torch.zeros(16, 8)}, batch_size=[16])

    env = Env()
    with contextlib.redirect_stdout(io.StringIO()):
        alg = VirlPPO.construct_algorithm(env.get_observations(), env, cfg, "cpu")
    alg.train_mode()
    seen = []
    for _ in range(cfg["num_steps_per_env"]):
        obs = TensorDict({"policy": torch.randn(16, 48, generator=gen), "privileged": torch.randn(16, 8, generator=gen)},
                         batch_size=[16])
        seen.append(obs["policy"])
        with torch.inference_mode():
            alg.act(obs)
            super(VirlPPO, alg).process_env_step(obs, torch.randn(16, generator=gen), torch.zeros(16),
                                                 {"time_outs": torch.zeros(16)})
    with torch.inference_mode():
        super(VirlPPO, alg).compute_returns(obs)
    batch = TensorDict({"policy": torch.cat(seen)}, batch_size=[len(seen) * 16])
    with torch.no_grad():
        alg.actor(batch, stochastic_output=True)
        before = [p.clone() for p in alg.actor.output_distribution_params]
    alg.update()
    with torch.no_grad():
        alg.actor(batch, stochastic_output=True)
        kl = alg.actor.get_kl_divergence(tuple(before), alg.actor.output_distribution_params).mean()
    assert abs(float(before[1].mean()) - args.ppo.init_std) < 1e-6
    assert kl < 0.3, f"KL of the first update {float(kl):.3g}"
