"""Rewards: streaming == batch, range (0, 1], reproducibility, checkpoints, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from virl_quad.cli import replace_options
from virl_quad.reward import VARIANTS, RewardConfig, build_reward, load_reward


def rollout(seed: int, T: int = 7, N: int = 5):
    rng = np.random.default_rng(seed)
    agent = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    expert = rng.integers(0, 256, (T, N, 48, 48), dtype=np.uint8)
    dones = rng.random((T, N)) < 0.25
    return agent, expert, dones


def make(variant, small_cfg, demo, other, agent_episode, seed=3, updates=2):
    cfg = RewardConfig.make(**{**small_cfg.to_dict(), "variant": variant})
    rm = build_reward(cfg, demo, [other], seed=seed)
    for s in range(3):
        rm.add_episode(*agent_episode(s))
    rm.update(updates)
    return rm


@pytest.mark.parametrize("variant", VARIANTS)
def test_streaming_equals_batch_recompute(variant, small_cfg, demo, other, agent_episode):
    rm = make(variant, small_cfg, demo, other, agent_episode)
    agent, expert, dones = rollout(0)
    T, N = dones.shape
    # warm the state with a few steps so the rollout starts mid-episode for some envs
    state = rm.stream_state(N)
    for t in range(3):
        _, state = rm.stream_step(agent[t], expert[t], state, np.zeros(N, bool))
    start_state, start_reset = state, np.array([True, False, False, True, False])
    streamed, reset = [], start_reset
    for t in range(T):
        r, state = rm.stream_step(agent[t], expert[t], state, reset)
        streamed.append(r)
        reset = dones[t]
    streamed = torch.stack(streamed)
    batch, end = rm.recompute(agent, expert, dones, start_state, start_reset, return_state=True)
    assert batch.shape == (T, N) and batch.dtype == torch.float32
    assert (streamed - batch).abs().max() <= 1e-5
    assert torch.allclose(end.h, state.h, atol=1e-5) and torch.allclose(end.c, state.c, atol=1e-5)
    assert ((batch > 0) & (batch <= 1)).all()
    # a fresh state at the start means "all envs start a new episode"
    s0 = rm.stream_state(N)
    r_fresh = rm.recompute(agent, expert, dones, s0)
    r_mask = rm.recompute(agent, expert, dones, start_state, np.ones(N, bool))
    assert (r_fresh - r_mask).abs().max() <= 1e-5


def test_resets_matter_and_envs_are_independent(trained_rm):
    agent, expert, _ = rollout(1, T=6, N=4)
    no_done = np.zeros((6, 4), bool)
    done = no_done.copy()
    done[2, 1] = True
    s0 = trained_rm.stream_state(4)
    a = trained_rm.recompute(agent, expert, no_done, s0)
    b = trained_rm.recompute(agent, expert, done, s0)
    assert torch.equal(a[:3], b[:3]) and (a[3:, 1] - b[3:, 1]).abs().max() > 1e-6   # env 1 after its reset
    assert (a[:, [0, 2, 3]] - b[:, [0, 2, 3]]).abs().max() <= 1e-6                   # other envs untouched
    # a reset frame gets the reward of a fresh episode starting there
    c = trained_rm.recompute(agent[3:], expert[3:], no_done[3:], trained_rm.stream_state(4))
    assert (b[3:, 1] - c[:, 1]).abs().max() <= 1e-5


def test_rewards_in_unit_interval_even_far_apart(trained_rm):
    black, white = np.zeros((3, 48, 48), np.uint8), np.full((3, 48, 48), 255, np.uint8)
    r, _ = trained_rm.stream_step(black, white, trained_rm.stream_state(3))
    assert ((r > 0) & (r <= 1)).all()
    same, _ = trained_rm.stream_step(black, black, trained_rm.stream_state(3))
    assert torch.allclose(same, torch.ones(3))                    # identical videos: d = 0, r = 1
    tiny = build_reward(RewardConfig.make(w_d=-1e6), trained_rm.demo, seed=0)
    r, _ = tiny.stream_step(black, white, tiny.stream_state(3))
    assert (r == tiny.cfg.reward.reward_floor).all()                    # underflow is floored, never 0


def test_rewards_use_eval_mode(trained_rm):
    agent, expert, dones = rollout(2)
    s0 = trained_rm.stream_state(5)
    trained_rm.net.train()                                        # even if someone left it training
    r1 = trained_rm.recompute(agent, expert, dones, s0)
    r2 = trained_rm.recompute(agent, expert, dones, s0)
    assert torch.equal(r1, r2) and trained_rm.net.training       # no dropout; mode restored


def test_seeded_runs_reproducible(small_cfg, demo, other, agent_episode):
    agent, expert, dones = rollout(3)
    outs = []
    for seed in (11, 11, 12):
        rng_before = torch.get_rng_state()
        rm = make("virl", small_cfg, demo, other, agent_episode, seed=seed, updates=3)
        assert torch.equal(torch.get_rng_state(), rng_before)   # the caller's RNG is left alone
        losses = rm.update(2)
        outs.append((losses, rm.recompute(agent, expert, dones, rm.stream_state(5))))
    assert outs[0][0] == outs[1][0] and torch.equal(outs[0][1], outs[1][1])
    assert outs[0][0] != outs[2][0] and not torch.equal(outs[0][1], outs[2][1])


@pytest.mark.parametrize("variant", ["virl", "gaifo"])
def test_save_load_identical_rewards_and_training(variant, tmp_path, small_cfg, demo, other, agent_episode):
    rm = make(variant, small_cfg, demo, other, agent_episode)
    path = tmp_path / "reward.pt"
    rm.save(path)
    raw = torch.load(path, weights_only=True)                     # plain tensors and python types
    assert raw["config"]["variant"] == variant
    loaded = load_reward(path)
    agent, expert, dones = rollout(4)
    s = rm.stream_state(5)
    assert torch.equal(rm.recompute(agent, expert, dones, s), loaded.recompute(agent, expert, dones, s))
    # optimiser and RNG state travel too: the same data gives the same next update
    for s_ in range(3):
        loaded.add_episode(*agent_episode(s_))
    assert rm.update(2) == loaded.update(2)
    assert torch.equal(rm.recompute(agent, expert, dones, s), loaded.recompute(agent, expert, dones, s))
    other_rm = make(variant, RewardConfig.make(**{**small_cfg.to_dict(), "lr": 5e-4}), demo, other, agent_episode)
    with pytest.raises(ValueError, match="different RewardConfig"):
        other_rm.load_state_dict(torch.load(path, weights_only=True))
    # the pair-sampling weights may change on resume (--adversarial-weight): same network, same rewards
    reweighted = make(variant, RewardConfig.make(**{**small_cfg.to_dict(), "pair_weights": {"expert_vs_agent": 0.0}}),
                      demo, other, agent_episode)
    reweighted.load_state_dict(torch.load(path, weights_only=True))
    fresh = load_reward(path)                                # the saved state, not updated since
    assert torch.equal(fresh.recompute(agent, expert, dones, s), reweighted.recompute(agent, expert, dones, s))
    assert reweighted.cfg.pairs.pair_weights == {"expert_vs_agent": 0.0}
    # so may w_d: the same distances, another reward shape (exp(-1 d^2) = exp(-5 d^2) ** 0.2)
    if variant != "gaifo":
        softer_cfg = RewardConfig.make(**{**small_cfg.to_dict(), "w_d": small_cfg.reward.w_d / 5})
        softer = make(variant, softer_cfg, demo, other, agent_episode)
        softer.load_state_dict(torch.load(path, weights_only=True))
        torch.testing.assert_close(softer.recompute(agent, expert, dones, s),
                                   fresh.recompute(agent, expert, dones, s) ** 0.2)


def test_bad_inputs_raise_one_line_value_errors(trained_rm):
    rm = trained_rm
    s = rm.stream_state(2)
    ok = np.zeros((2, 48, 48), np.uint8)
    bad = {
        "shape": (np.zeros((2, 32, 32), np.uint8), ok),
        "ndim": (np.zeros((48, 48), np.uint8), ok),
        "dtype": (np.zeros((2, 48, 48), np.int64), ok),
        "nan": (np.full((2, 48, 48), np.nan, np.float32), ok),
        "range": (np.full((2, 48, 48), 3.0, np.float32), ok),
        "n mismatch": (np.zeros((3, 48, 48), np.uint8), np.zeros((3, 48, 48), np.uint8)),
        "list": ([[0]], ok),
    }
    for name, (a, e) in bad.items():
        with pytest.raises(ValueError) as info:
            rm.stream_step(a, e, s)
        assert "\n" not in str(info.value), name
    with pytest.raises(ValueError, match="reset_mask"):
        rm.stream_step(ok, ok, s, np.zeros(3, bool))
    with pytest.raises(ValueError, match="empty"):
        rm.recompute(np.zeros((0, 2, 48, 48), np.uint8), np.zeros((0, 2, 48, 48), np.uint8),
                     np.zeros((0, 2), bool), s)
    with pytest.raises(ValueError, match="dones"):
        rm.recompute(np.zeros((4, 2, 48, 48), np.uint8), np.zeros((4, 2, 48, 48), np.uint8),
                     np.zeros((4, 3), bool), s)
    with pytest.raises(ValueError, match="empty"):
        rm.add_episode(np.zeros((0, 48, 48), np.uint8), np.zeros((0, 48, 48), np.uint8))
    with pytest.raises(ValueError, match="variant"):
        build_reward(RewardConfig.make(variant="tcn"), rm.demo)
    with pytest.raises(ValueError, match="demo_frames"):
        build_reward(RewardConfig(), np.zeros((10, 64, 64), np.uint8))
    r, _ = rm.stream_step(torch.zeros(2, 48, 48), torch.zeros(2, 48, 48, dtype=torch.uint8), s)
    assert r.shape == (2,)                                         # torch input, float or uint8, works


def test_gaifo_reward_is_discriminator_output(small_cfg, demo, other, agent_episode):
    rm = make("gaifo", small_cfg, demo, other, agent_episode, updates=5)
    agent, expert, _ = rollout(5, T=3, N=4)
    s = rm.stream_state(4)
    r0, s = rm.stream_step(agent[0], expert[0], s)
    r1, s = rm.stream_step(agent[1], expert[1], s)
    with torch.no_grad():
        x0 = torch.from_numpy(agent[0]).float() / 255
        x1 = torch.from_numpy(agent[1]).float() / 255
        d0 = torch.sigmoid(rm.reward_net(x0, x0))                        # first frame of an episode pairs with itself
        d1 = torch.sigmoid(rm.reward_net(x0, x1))
    assert torch.allclose(r0, d0, atol=1e-6) and torch.allclose(r1, d1, atol=1e-6)
    with pytest.raises(ValueError, match="gaifo needs"):
        build_reward(RewardConfig.make(variant="gaifo"), demo).update(1)


def test_rewards_come_from_a_slowly_moving_copy(small_cfg, demo, other, agent_episode):
    """With ema, the reward network trails the trained one by ema ** updates; without, it is the trained one."""
    rm = make("virl", replace_options(small_cfg, ema=0.9), demo, other, agent_episode, updates=0)
    before = [p.detach().clone() for p in rm.reward_net.parameters()]
    rm.update(3)
    keep = 0.9 ** 3
    for slow, fast, old in zip(rm.reward_net.parameters(), rm.net.parameters(), before):
        assert torch.allclose(slow, keep * old + (1 - keep) * fast, atol=1e-6)
    assert any(not torch.equal(s, f) for s, f in zip(rm.reward_net.parameters(), rm.net.parameters()))
    # the latent's batch-norm statistics are the trained model's, not an average from their start
    assert float(rm.net.phi.norm.running_var.sub(1.0).abs().max()) > 1e-3
    assert all(torch.equal(s, f) for s, f in zip(rm.reward_net.buffers(), rm.net.buffers()))
    plain = make("virl", replace_options(small_cfg, ema=0.0), demo, other, agent_episode, updates=1)
    assert plain.reward_net is plain.net
    with pytest.raises(ValueError, match="ema"):
        RewardConfig.make(ema=1.0).validate()


def test_where_the_robot_stands_on_the_ground_does_not_change_the_distance():
    """The checker ground painted out: the demonstration re-rendered 6 cm further along the
    ground is the same video to the model (a real render, not a synthetic clip)."""
    import dataclasses

    from virl_quad import demo as demo_lib
    from virl_quad.demo.render import render_demonstration

    d = demo_lib.load("trot", "pupper", ground="checker")
    moved = dataclasses.replace(d.motion, root_pos=d.motion.root_pos + np.array([0.06, 0.0, 0.0]))
    shifted = render_demonstration(moved, "pupper", ground="checker").frames
    assert (shifted != d.frames).mean() > 0.05                    # the ground moved under the robot
    for paint in (True, False):
        rm = build_reward(RewardConfig.make(paint_background=paint, ema=0.0), d.frames, seed=0)
        rm.update(2)
        dist = rm.distance(torch.from_numpy(d.frames[:40, None]), torch.from_numpy(shifted[:40, None]))
        assert (float(dist.max()) < 1e-6) == paint, float(dist.max())


def test_the_encoding_spread_is_logged_and_reads_0_for_a_collapsed_encoder(small_cfg, demo, other, agent_episode):
    rm = make("virl", small_cfg, demo, other, agent_episode)
    logs = rm.update(1)
    assert logs["e_spread"] == pytest.approx(rm.encoding_spread()) and logs["e_spread"] > 1e-4
    with torch.no_grad():                        # every sigmoid unit saturated: one code for every frame
        rm.reward_net.phi.mu.weight.zero_()
        rm.reward_net.phi.mu.bias.fill_(-30.0)
    assert rm.encoding_spread() < 1e-9
    agent, expert, dones = rollout(1)
    assert torch.all(rm.recompute(agent, expert, dones, rm.stream_state(dones.shape[1])) > 0.999)


def test_d2_is_counted_in_units_of_the_demonstrations_distance_to_its_negatives(small_cfg, demo, other,
                                                                             agent_episode):
    """Calibrated, the reward is exp(w_d d^2 / d2_ref), d2_ref the mean d^2 (frames 10 on) between
    the demonstration and the other clip, measured after every update: a behaviour as far from the
    demonstration as another gait gets exp(w_d) however far training has pushed the negatives."""
    rm = make("virl", small_cfg, demo, other, agent_episode)
    logs = rm.update(1)

    def ref(a: np.ndarray, b: np.ndarray, model=rm) -> float:
        n = min(len(a), len(b))
        d = model.distance(torch.from_numpy(a[:n, None]), torch.from_numpy(np.ascontiguousarray(b[:n, None])))
        return float(d[10:, 0].square().mean())

    assert rm.d2_scale() == pytest.approx(ref(demo, other), rel=1e-5) and logs["d2_ref"] == rm.d2_scale() != 1.0
    d = torch.tensor([0.0, rm.d2_scale() ** 0.5])
    assert torch.allclose(rm.reward_of(d), torch.tensor([1.0, float(np.exp(rm.cfg.reward.w_d))]), rtol=1e-4)
    agent, expert, dones = rollout(1)
    calibrated = rm.recompute(agent, expert, dones, rm.stream_state(5))
    rm.cfg.reward.calibrate = False
    raw = rm.recompute(agent, expert, dones, rm.stream_state(5))
    floor = rm.cfg.reward.reward_floor
    assert torch.allclose(calibrated, (raw ** (1.0 / ref(demo, other))).clamp(min=floor), rtol=1e-3)
    # with no other clips the negative is the demonstration played backwards
    alone = build_reward(RewardConfig.make(**small_cfg.to_dict()), demo, seed=3)
    assert alone.d2_scale() == 1.0                 # untrained: raw distances
    alone.update(2)
    assert alone.d2_scale() == pytest.approx(ref(demo, demo[::-1], alone), rel=1e-5)


def test_a_config_saved_before_the_latent_norm_and_view_jitter_loads_without_them(small_cfg, demo):
    """An older model's saved config lacks the settings added since: it loads as it was trained."""
    old = {k: v for k, v in small_cfg.to_dict().items()
           if k not in ("latent_norm", "latent_norm_eps", "view_zoom", "view_shift", "calibrate")}
    cfg = RewardConfig.from_dict(old)
    assert cfg.arch.latent_norm_eps == 1e-5                 # torch's default, which it was saved with
    assert not cfg.arch.latent_norm and cfg.pairs.view_zoom == 0.0 and cfg.pairs.view_shift == 0.0
    assert not cfg.reward.calibrate
    assert isinstance(build_reward(cfg, demo).net.phi.norm, torch.nn.Identity)
    with pytest.raises(ValueError, match="view_zoom"):
        RewardConfig.make(view_zoom=0.6).validate()
