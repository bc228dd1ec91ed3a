"""Network shapes, the transposed convolutions, and reverse-order sequence decoding."""

from __future__ import annotations

import pytest
import torch
from torch.nn import functional as F

from virl_quad.reward import RewardConfig
from virl_quad.reward.model import ConvTranspose2d, DistanceModel
from virl_quad.reward.losses import raes_loss


def test_shapes_and_ranges():
    cfg = RewardConfig()
    model = DistanceModel(cfg).eval()
    x = torch.rand(3, 2, 48, 48)
    mu, logvar = model.encode_frames(x)
    assert mu.shape == logvar.shape == (3, 2, 64)
    assert (mu > 0).all() and (mu < 1).all()                            # sigmoid on the last layer
    assert model.phi.conv1.out_channels == 8 and model.phi.conv1.kernel_size == (6, 6)
    assert model.phi.conv2.out_channels == 16 and model.phi.conv2.kernel_size == (4, 4)
    assert model.phi.fc.out_features == 256 and model.omega.lstm.hidden_size == 128
    h, _ = model.encode_sequence(mu)
    assert h.shape == (3, 2, 64)
    rec = model.psi(mu)
    assert rec.shape == (3, 2, 48, 48) and (rec >= 0).all() and (rec <= 1).all()
    assert DistanceModel(RewardConfig.make(variant="frame")).omega is None
    assert DistanceModel(RewardConfig.make(variant="no_ae")).psi is None


def test_transposed_conv_matches_torch():
    torch.manual_seed(0)
    for cin, cout, k, s, n in [(16, 8, 4, 2, 10), (8, 1, 6, 2, 22), (3, 2, 3, 2, 5)]:
        m = ConvTranspose2d(cin, cout, k, s)
        x = torch.randn(4, cin, n, n)
        ref = F.conv_transpose2d(x, m.weight, m.bias, s)
        assert torch.allclose(m(x), ref, atol=1e-5)


def test_sequence_decoder_outputs_last_frame_first():
    """Train only L_RAES on sequences of distinct frames: decoded step k must match frame T-1-k."""
    torch.manual_seed(0)
    cfg = RewardConfig.make(dropout=0.0)
    model = DistanceModel(cfg).train()
    T = 4
    yy = torch.arange(48.0)[:, None].expand(48, 48)
    bars = torch.stack([((yy // 12) == t).float() for t in range(T)])   # frame t: a bar in band t
    frames = torch.stack([bars, bars.flip(-1)], dim=1)                   # [T, 2, 48, 48], 2 sequences
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(200):
        mu, _ = model.encode_frames(frames)
        h, _ = model.encode_sequence(mu)
        loss = raes_loss(model, h[-1], frames)
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    with torch.no_grad():
        h, _ = model.encode_sequence(model.encode_frames(frames)[0])
        dec = model.decode_sequence_reversed(h[-1], T)                   # step k = frame T-1-k
        forward_order = model.reconstruct_sequence(frames)
    err_rev = ((dec - frames.flip(0)) ** 2).mean()
    err_fwd = ((dec - frames) ** 2).mean()
    assert err_rev < 0.06 and err_rev < err_fwd / 4, (float(err_rev), float(err_fwd))
    assert torch.allclose(forward_order, dec.flip(0))



def test_latent_norm_spreads_the_frames_of_a_render():
    """A fresh encoder maps a painted render's mostly white frames almost alike (a spread of e
    about 1e-3, where training can stall with every behaviour rewarded 1); batch-normalised
    before the sigmoid, e spreads over the frames from the first update."""
    from virl_quad import demo as demo_lib

    frames = torch.from_numpy(demo_lib.load("trot", "pupper").frames[:256]).float() / 255.0
    for seed in (0, 1, 2):
        spreads = {}
        for norm in (False, True):
            torch.manual_seed(seed)
            phi = DistanceModel(RewardConfig.make(latent_norm=norm)).phi.train()
            with torch.no_grad():
                spreads[norm] = float(phi(frames)[0].std(0).mean())
        assert spreads[False] < 0.01 and spreads[True] > 0.1, (seed, spreads)
    assert isinstance(DistanceModel(RewardConfig.make(latent_norm=False)).phi.norm, torch.nn.Identity)


def test_the_latent_norm_does_not_depend_on_the_scale_of_its_input():
    """Over a render's frames e's pre-activation varies by 1e-9 .. 1e-4 in trained models; shrunk
    a hundredfold, the normalised encoding must not move (with torch's variance floor of 1e-5
    it shrinks towards one point, where the contrastive loss has no gradient left)."""
    from virl_quad import demo as demo_lib

    frames = torch.from_numpy(demo_lib.load("trot", "pupper").frames[:128]).float() / 255.0
    spreads = {}
    for eps in (1e-5, RewardConfig().arch.latent_norm_eps):
        torch.manual_seed(0)
        phi = DistanceModel(RewardConfig.make(latent_norm_eps=eps, dropout=0.0)).phi.train()
        with torch.no_grad():
            before = phi(frames)[0]
            phi.mu.weight.mul_(1e-2)
            phi.mu.bias.mul_(1e-2)
            after = phi(frames)[0]
        spreads[eps] = float(after.std(0).mean()) / float(before.std(0).mean())
    assert spreads[RewardConfig().arch.latent_norm_eps] == pytest.approx(1.0, abs=1e-3), spreads
    assert spreads[1e-5] < 0.5, spreads                     # the test can tell the two apart


def test_dropout_drops_single_units_not_whole_feature_maps():
    """A dropped map, one of conv1's 8, can move e more than any frame does; the encoder drops units."""
    torch.manual_seed(0)
    phi = DistanceModel(RewardConfig()).phi.train()
    out = phi.drop(torch.ones(16, phi.conv1.out_channels, 22, 22))
    dropped = out == 0
    assert 0.05 < float(dropped.float().mean()) < 0.15
    assert not dropped.all(dim=(-1, -2)).any()              # no map is dropped whole
