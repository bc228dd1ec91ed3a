"""Each loss is zero/low where it should be and positive where it should be; a fixed batch can be overfit."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from virl_quad.reward import RewardConfig, build_reward
from virl_quad.reward.losses import (contrastive, kl_divergence, raes_loss, reconstruction_loss,
                                     sni_loss, sns_loss, total_loss, vae_loss, vaei_loss)
from virl_quad.reward.model import DistanceModel


def test_contrastive_positive_pairs_zero_iff_equal():
    a = torch.rand(5, 64)
    y = torch.ones(5)
    assert contrastive(a, a.clone(), y).abs().max() == 0
    b = a + 0.1
    assert torch.allclose(contrastive(a, b, y), torch.full((5,), 64 * 0.01), atol=1e-5)  # = ||a-b||^2


def test_contrastive_negative_pairs_hinge_on_squared_distance():
    a = torch.zeros(3, 4)
    y = torch.zeros(3)
    far = a.clone()
    far[:, 0] = 1.5                       # D^2 = 2.25 >= margin 1 -> no loss
    assert contrastive(a, far, y).abs().max() == 0
    near = a.clone()
    near[:, 0] = 0.5                      # D^2 = 0.25 -> 1 - 0.25
    assert torch.allclose(contrastive(a, near, y), torch.full((3,), 0.75))
    assert torch.allclose(contrastive(a, a, y), torch.ones(3))          # identical negatives cost the margin
    assert torch.allclose(contrastive(a, near, y, margin=2.0), torch.full((3,), 1.75))


def test_sns_and_sni_follow_labels():
    h = torch.rand(4, 64)
    y = torch.tensor([1.0, 1.0, 0.0, 0.0])
    far = h + torch.tensor([0.0, 0.0, 1.0, 1.0])[:, None]          # negatives far apart, positives equal
    assert sns_loss(h, far, y) == 0
    assert sns_loss(h, h, y) > 0.4                                   # negatives on top of each other: margin
    e = torch.rand(6, 4, 64)
    assert sni_loss(e, e + torch.tensor([0.0, 0.0, 1.0, 1.0])[None, :, None], y) == 0
    assert sni_loss(e, e + 0.2, torch.ones(4)) > 0


def test_reconstruction_and_vae_terms():
    x = torch.rand(3, 48, 48)
    assert reconstruction_loss(x, x) == 0
    assert reconstruction_loss(x, 1 - x) > 0.05
    mu0, lv0 = torch.zeros(7, 64), torch.zeros(7, 64)
    assert kl_divergence(mu0, lv0) == 0
    assert kl_divergence(mu0 + 0.5, lv0) > 0 and kl_divergence(mu0, lv0 - 1.0) > 0
    assert vae_loss(x, x, mu0, lv0, beta=1.0) == 0
    assert vae_loss(x, 1 - x, mu0 + 0.3, lv0, beta=1.0) > vae_loss(x, 1 - x, mu0, lv0, beta=1.0)


def test_raes_compares_with_reversed_frames():
    """The sequence autoencoder loss is the MSE between the decoder output and the TIME-REVERSED input."""
    torch.manual_seed(0)
    model = DistanceModel(RewardConfig()).eval()
    frames = torch.linspace(0, 1, 5)[:, None, None, None].expand(5, 3, 48, 48).contiguous()  # time-varying
    with torch.no_grad():
        h, _ = model.encode_sequence(model.encode_frames(frames)[0])
        dec = model.decode_sequence_reversed(h[-1], 5)
        got = raes_loss(model, h[-1], frames)
    assert torch.allclose(got, ((dec - frames.flip(0)) ** 2).mean())


@pytest.mark.parametrize("variant,parts", [
    ("virl", {"sns", "sni", "raes", "vaei"}), ("sequence", {"sns", "sni", "raes", "vaei"}),
    ("no_ae", {"sns", "sni"}), ("frame", {"sni", "vaei"})])
def test_total_loss_parts_per_variant(variant, parts):
    cfg = RewardConfig.make(variant=variant)
    torch.manual_seed(0)
    model = DistanceModel(cfg).train()
    a, b = torch.rand(4, 6, 48, 48), torch.rand(4, 6, 48, 48)
    y = torch.tensor([1.0, 1, 1, 0, 0, 0])
    loss, logs = total_loss(model, a, b, y)
    assert set(logs) == parts | {"total"}
    assert all(logs[k] > 0 for k in parts)                       # random pairs: every term is positive
    w = {"sns": cfg.loss.w_sns, "sni": cfg.loss.w_sni if variant != "frame" else cfg.loss.w_sns + cfg.loss.w_sni,
         "raes": cfg.loss.w_raes, "vaei": cfg.loss.w_vaei}
    assert loss.item() == pytest.approx(sum(w[k] * logs[k] for k in parts), rel=1e-5)
    loss.backward()
    unused = {"phi.logvar.weight", "phi.logvar.bias"} if variant == "no_ae" else set()
    assert all(p.grad is not None for n, p in model.named_parameters() if n not in unused)


def test_vaei_subset_is_unbiased_in_expectation():
    torch.manual_seed(0)
    model = DistanceModel(RewardConfig.make(dropout=0.0)).eval()
    frames = torch.rand(4, 8, 48, 48)
    mu, lv = model.encode_frames(frames)
    lv = torch.full_like(lv, -30.0)                 # no sampling noise: compare subset vs full mean
    with torch.no_grad():
        full = vaei_loss(model, mu, lv, frames, 1e-3, 0).item()
        sub = np.mean([vaei_loss(model, mu, lv, frames, 1e-3, 8).item() for _ in range(200)])
    assert sub == pytest.approx(full, rel=0.05)


def test_overfit_one_fixed_batch(demo, other, agent_episode):
    """Training on one fixed real batch drives the total loss down at least 10x."""
    cfg = RewardConfig.make(batch_pairs=8, window_min=8, window_max=8, ae_frames=0, dropout=0.0,
                       paint_background=False)       # synthetic clips: the blobs on their dark ground as they are
    rm = build_reward(cfg, demo, [other], seed=0)
    for s in range(3):
        rm.add_episode(*agent_episode(s))
    batch = rm.sampler.draw(np.random.default_rng(0))
    a, b, y = (torch.from_numpy(v) for v in (batch.a, batch.b, batch.y))
    torch.manual_seed(0)
    opt = torch.optim.Adam(rm.net.parameters(), lr=2e-3)
    rm.net.train()
    first = total_loss(rm.net, a, b, y)[1]["total"]
    for _ in range(80):
        loss, _ = total_loss(rm.net, a, b, y)
        opt.zero_grad()
        loss.backward()
        opt.step()
    last = np.mean([total_loss(rm.net, a, b, y)[1]["total"] for _ in range(5)])
    assert last <= first / 10, (first, last)


def test_unique_frames_encodes_each_distinct_frame_once():
    from virl_quad.reward.losses import unique_frames

    x = torch.rand(5, 48, 48)
    frames = torch.cat([x, x.flip(0), x[2:3].expand(3, 48, 48)])   # 13 slots, 5 distinct frames
    uniq, inv = unique_frames(frames)
    assert uniq.shape[0] == 5 and torch.equal(uniq[inv], frames)
    y = torch.rand(4, 48, 48)
    uniq, inv = unique_frames(y)
    assert uniq.shape[0] == 4 and torch.equal(uniq[inv], y)
