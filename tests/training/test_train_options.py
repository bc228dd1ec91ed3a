"""Training options that shape the distance model's data: multi-task clips, adversarial weight."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from virl_quad.training.setup import other_clips
from virl_quad.training.config import TrainArgs, validate
from virl_quad.training.rewards import LearnedReward


def test_auto_uses_the_other_builtin_gaits_and_is_saved(tmp_path: Path) -> None:
    clips = other_clips(TrainArgs.make(demo="trot"), tmp_path)
    assert len(clips) == 4 and all(c.ndim == 3 and c.shape[1:] == (48, 48) for c in clips)
    # a resume reads the saved clips, whatever the option now says
    again = other_clips(TrainArgs.make(demo="trot", other_demos="none"), tmp_path)
    assert all(np.array_equal(a, b) for a, b in zip(clips, again)) and len(again) == 4


def test_none_and_explicit_lists(tmp_path: Path) -> None:
    assert other_clips(TrainArgs.make(other_demos="none"), tmp_path / "a") == []
    assert len(other_clips(TrainArgs.make(other_demos="pace, bound"), tmp_path / "b")) == 2
    with pytest.raises(ValueError, match="cannot use"):
        other_clips(TrainArgs.make(other_demos="no_such_clip.xyz"), tmp_path / "c")


def test_adversarial_weight_reaches_the_pair_sampler() -> None:
    frames = np.random.default_rng(0).integers(0, 255, (40, 48, 48), dtype=np.uint8)
    low = LearnedReward("virl", frames, 2, 1, 0, adversarial_weight=0.1)
    assert low.model.cfg.pairs.pair_weights == {"expert_vs_agent": 0.1}
    assert LearnedReward("virl", frames, 2, 1, 0).model.cfg.pairs.pair_weights == {}
    with pytest.raises(ValueError, match="adversarial-weight"):
        validate(TrainArgs.make(adversarial_weight=-1.0))


def test_pretraining_learns_from_the_observed_rollout_and_rewards_nothing() -> None:
    """``pretrain``: the frames observed so far go to the dataset, the model updates that many
    times, and the next rollout's rewards come from that rollout alone."""
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (40, 48, 48), dtype=np.uint8)
    source = LearnedReward("virl", frames, 2, 1, 0)
    obs = TensorDict({"agent_image": torch.from_numpy(frames[:2]), "expert_image": torch.from_numpy(frames[2:4])},
                     batch_size=[2])
    extras = {"final_agent_image": obs["agent_image"], "final_expert_image": obs["expert_image"]}
    for _ in range(12):
        source.observe(obs, torch.zeros(2), torch.zeros(2), extras)
    info = source.pretrain(3)
    assert source.model.trainer.num_updates == 3 and "distance/d2_ref" in info
    assert source.model.dataset.num_frames == 24
    for _ in range(5):
        source.observe(obs, torch.zeros(2), torch.zeros(2), extras)
    rewards, _ = source.finish()
    assert rewards.shape == (5, 2) and source.model.trainer.num_updates == 4


def test_checkpoint_contract_is_the_runs_and_must_match_the_robot() -> None:
    """The action facts come from the run (the env's contract saved in the checkpoint), not from
    today's defaults: a run trained with action scale 0.3 exports with 0.3. A checkpoint without
    them, or trained with other PD gains, is refused."""
    from virl_quad import robots
    from virl_quad.envs import EnvConfig, policy_contract
    from virl_quad.training import checkpoint

    spec = robots.get("pupper")
    contract = policy_contract(spec, EnvConfig.make(action_scale=0.3, action_clip=1.5), 40)
    data = {"contract": checkpoint.contract_payload(contract, spec)}
    got = checkpoint.contract_of(data, "pupper")
    assert got == contract and got.action_scale == 0.3 != spec.action_scale
    with pytest.raises(ValueError, match="does not record"):
        checkpoint.contract_of({}, "pupper")
    with pytest.raises(ValueError, match="kp"):
        checkpoint.contract_of({"contract": dict(data["contract"], kp=[1.0] * 12)}, "pupper")
    with pytest.raises(ValueError, match="lacks its trajectory generator"):
        checkpoint.contract_of({"contract": dict(data["contract"], action_size=14)}, "pupper")


def test_an_unknown_ground_is_refused() -> None:
    with pytest.raises(ValueError, match="ground"):
        validate(TrainArgs.make(ground="grass"))


def test_a_checkpoint_with_retired_reward_settings_still_loads(tmp_path: Path) -> None:
    """Checkpoints of older versions hold settings of retired features in the distance model's
    config (speed_strip, speed_shift and ground_shift pair weights) and a rollout count: a resumed
    run's reward source and load_reward_model (the benches') drop them and restore the model's weights."""
    import torch

    from virl_quad import demo as demo_lib
    from virl_quad.demo.render import save_npz
    from virl_quad.reward import RewardConfig
    from virl_quad.training import checkpoint

    demo = demo_lib.load("trot", "pupper")
    source = LearnedReward("frame", demo.frames, 2, 1, 0, adversarial_weight=0.1)
    old = source.state_dict()
    old["config"] = {**old["config"], "speed_strip": True,
                     "pair_weights": {**old["config"]["pair_weights"], "speed_shift": 0.25, "ground_shift": 1.0}}
    old["rollouts"] = 7
    with pytest.raises(TypeError):
        RewardConfig.make(**old["config"])                     # not settings of today's config

    def same_weights(model) -> bool:
        mine = model.net.state_dict()
        return all(torch.equal(mine[k], v) for k, v in source.model.net.state_dict().items())

    resumed = LearnedReward("frame", demo.frames, 2, 1, 5, adversarial_weight=0.1)   # another seed: other weights
    assert not same_weights(resumed.model)
    resumed.load_state_dict(old)
    assert same_weights(resumed.model)
    checkpoint.save(tmp_path / checkpoint.LATEST, {"actor_state_dict": {}, "iteration": 0,
                                                   "config": {"robot": "pupper"}, "reward": old})
    save_npz(demo, tmp_path / "demo.npz")
    rm, _, _, robot = checkpoint.load_reward_model(tmp_path)
    assert robot == "pupper" and rm.cfg.pairs.pair_weights == {"expert_vs_agent": 0.1} and same_weights(rm)


def test_options_are_sections_by_concern_saved_flat_and_read_back() -> None:
    """Sections in code and help, one flat {name: value} on disk (the command line's names), and
    a saved config read back whole; an option the code no longer has is dropped, a new one
    takes its default."""
    from virl_quad.training.config import from_dict, to_dict

    args = TrainArgs.make(robot="laikago", num_envs=4, reward_lr=3e-4, init_std=0.1, eval_every=5)
    assert (args.run.robot, args.env.num_envs, args.distance.reward_lr, args.ppo.init_std,
            args.eval.eval_every) == ("laikago", 4, 3e-4, 0.1, 5)
    saved = to_dict(args)
    assert saved["num_envs"] == 4 and all(not isinstance(v, dict) for v in saved.values())
    assert from_dict(saved) == args
    older = {k: v for k, v in saved.items() if k != "critic_warmup"} | {"retired_option": 1}
    assert from_dict(older) == TrainArgs.make(**{**saved, "critic_warmup": TrainArgs().ppo.critic_warmup})
    with pytest.raises(TypeError, match="no_such_option"):
        TrainArgs.make(no_such_option=1)


def test_the_anchor_pull_by_default_guards_every_reward_but_the_exact_one():
    from virl_quad.training.config import prior_pull

    assert prior_pull(TrainArgs()) == 0.01
    assert prior_pull(TrainArgs.make(reward="prior")) == 0.01
    assert prior_pull(TrainArgs.make(reward="oracle")) == 0.0
    assert prior_pull(TrainArgs.make(reward="oracle", prior_pull=0.05)) == 0.05
    assert prior_pull(TrainArgs.make(prior_pull=0.0)) == 0.0


def test_runs_made_before_the_oracle_speed_term_resume_with_the_score_alone() -> None:
    from virl_quad.train import LEGACY
    from virl_quad.training.config import from_dict, to_dict

    old = {k: v for k, v in to_dict(TrainArgs.make(reward="oracle")).items() if k != "oracle_speed_weight"}
    assert from_dict({**LEGACY, **old}).run.oracle_speed_weight == 0.0      # what resume reads back
    new = to_dict(TrainArgs.make(reward="oracle"))
    assert from_dict({**LEGACY, **new}).run.oracle_speed_weight == 0.3      # a new run keeps its own


def test_runs_made_before_the_video_speed_term_resume_without_it() -> None:
    from virl_quad.train import LEGACY
    from virl_quad.training.config import from_dict, to_dict

    old = {k: v for k, v in to_dict(TrainArgs()).items() if k != "video_speed_weight"}
    assert from_dict({**LEGACY, **old}).distance.video_speed_weight == 0.0
    assert from_dict({**LEGACY, **to_dict(TrainArgs())}).distance.video_speed_weight == 0.3
