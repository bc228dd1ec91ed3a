"""Training options that shape the distance model's data: multi-task clips, adversarial weight."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from virl_quad.train import _other_clips
from virl_quad.training.config import TrainArgs, validate
from virl_quad.training.rewards import LearnedReward


def test_auto_uses_the_other_builtin_gaits_and_is_saved(tmp_path: Path) -> None:
    clips = _other_clips(TrainArgs(demo="trot"), tmp_path)
    assert len(clips) == 4 and all(c.ndim == 3 and c.shape[1:] == (48, 48) for c in clips)
    # a resume reads the saved clips, whatever the option now says
    again = _other_clips(TrainArgs(demo="trot", other_demos="none"), tmp_path)
    assert all(np.array_equal(a, b) for a, b in zip(clips, again)) and len(again) == 4


def test_none_and_explicit_lists(tmp_path: Path) -> None:
    assert _other_clips(TrainArgs(other_demos="none"), tmp_path / "a") == []
    assert len(_other_clips(TrainArgs(other_demos="pace, bound"), tmp_path / "b")) == 2
    with pytest.raises(ValueError, match="cannot use"):
        _other_clips(TrainArgs(other_demos="no_such_clip.xyz"), tmp_path / "c")


def test_adversarial_weight_reaches_the_pair_sampler() -> None:
    frames = np.random.default_rng(0).integers(0, 255, (40, 48, 48), dtype=np.uint8)
    low = LearnedReward("virl", frames, 2, 1, 0, adversarial_weight=0.1)
    assert low.model.cfg.pair_weights == {"expert_vs_agent": 0.1}
    assert LearnedReward("virl", frames, 2, 1, 0).model.cfg.pair_weights == {}
    with pytest.raises(ValueError, match="adversarial-weight"):
        validate(TrainArgs(adversarial_weight=-1.0))


def test_checkpoint_contract_is_the_runs_and_must_match_the_robot() -> None:
    """The action facts come from the run (the env's contract saved in the checkpoint), not from
    today's defaults: a run trained with action scale 0.3 exports with 0.3. A checkpoint without
    them, or trained with other PD gains, is refused."""
    from virl_quad import robots
    from virl_quad.envs import EnvConfig, policy_contract
    from virl_quad.training import checkpoint

    spec = robots.get("pupper")
    contract = policy_contract(spec, EnvConfig(action_scale=0.3, action_clip=1.5), 40)
    data = {"contract": checkpoint.contract_payload(contract, spec)}
    got = checkpoint.contract_of(data, "pupper")
    assert got == contract and got.action_scale == 0.3 != spec.action_scale
    with pytest.raises(ValueError, match="does not record"):
        checkpoint.contract_of({}, "pupper")
    with pytest.raises(ValueError, match="kp"):
        checkpoint.contract_of({"contract": dict(data["contract"], kp=[1.0] * 12)}, "pupper")
    with pytest.raises(ValueError, match="lacks its trajectory generator"):
        checkpoint.contract_of({"contract": dict(data["contract"], action_size=14)}, "pupper")


def test_ground_shift_renders_match_the_demo() -> None:
    from virl_quad import demo as demo_lib
    from virl_quad.demo.demonstration import Demonstration
    from virl_quad.train import _ground_shifts

    d = demo_lib.load("trot", "pupper")
    variants = _ground_shifts(TrainArgs(ground_shifts=2), d)
    assert len(variants) == 2 and all(v.shape == d.frames.shape for v in variants)
    # the robot is the same, only the ground moved: the frames differ, the demo is untouched
    assert all(np.abs(v.astype(int) - d.frames).mean() > 1.0 for v in variants)
    # on the plain ground there is no pattern to shift: no re-renders are made
    plain = demo_lib.load("trot", "pupper", ground="plain")
    assert _ground_shifts(TrainArgs(ground="plain", ground_shifts=2), plain) == []
    with pytest.raises(ValueError, match="ground"):
        validate(TrainArgs(ground="grass"))
    assert _ground_shifts(TrainArgs(ground_shifts=0), d) == []
    no_motion = Demonstration(frames=d.frames, fps=d.fps, robot="pupper", source="video", camera=d.camera,
                              motion=None, loop=True, displacement=None)
    assert _ground_shifts(TrainArgs(ground_shifts=3), no_motion) == []
    with pytest.raises(ValueError, match="ground-shifts"):
        validate(TrainArgs(ground_shifts=-1))


def test_a_frozen_distance_model_stops_learning_and_remembers_when() -> None:
    import torch

    rng = np.random.default_rng(1)
    frames = rng.integers(0, 255, (40, 48, 48), dtype=np.uint8)
    source = LearnedReward("frame", frames, 2, 1, 0, freeze_after=1)
    T, N = 12, 2

    def rollout() -> tuple[torch.Tensor, dict]:
        for _ in range(T):
            agent = torch.from_numpy(rng.integers(0, 255, (N, 48, 48), dtype=np.uint8))
            obs = {"agent_image": agent, "expert_image": torch.from_numpy(frames[:N].copy())}
            final = {"final_agent_image": agent, "final_expert_image": obs["expert_image"]}
            source.observe(obs, torch.zeros(N), torch.zeros(N), final)
        return source.finish()

    def weights() -> list[torch.Tensor]:
        return [p.detach().clone() for p in source.model.net.parameters()]

    before = weights()
    _, info = rollout()                                   # rollout 1: the model still learns
    learned = weights()
    assert "distance/total" in info and any(not torch.equal(a, b) for a, b in zip(before, learned))
    assert source.frozen and len(source.model.dataset.sequences()) > 0
    rewards, info = rollout()                             # rollout 2: frozen, rewards still computed
    assert "distance/total" not in info and rewards.shape == (T, N) and torch.isfinite(rewards).all()
    assert all(torch.equal(a, b) for a, b in zip(learned, weights()))
    again = LearnedReward("frame", frames, 2, 1, 0, freeze_after=1)
    again.load_state_dict(source.state_dict())            # a resumed run stays frozen
    assert again.rollouts == 2 and again.frozen
    with pytest.raises(ValueError, match="freeze"):
        validate(TrainArgs(reward_freeze_after=-1))
