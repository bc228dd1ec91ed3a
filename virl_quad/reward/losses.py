"""The four VIRL losses and their weighted sum.

L = w_sns * L_SNS + w_sni * L_SNI + w_raes * L_RAES + w_vaei * L_VAEI   (paper: 0.7, 0.1, 0.1, 0.1)
"""

from __future__ import annotations

import torch
from torch.nn import functional as F

from virl_quad.reward.config import RewardConfig
from virl_quad.reward.model import DistanceModel


def contrastive(a: torch.Tensor, b: torch.Tensor, y: torch.Tensor, margin: float = 1.0) -> torch.Tensor:
    """Per-pair contrastive loss y*D^2 + (1-y)*max(margin - D^2, 0), D = ||a - b|| over the last axis.

    ``a``, ``b`` [..., dim]; ``y`` broadcastable to [...] (1 = same, 0 = different). Returns [...].
    """
    d2 = (a - b).pow(2).sum(-1)
    y = y.to(d2.dtype)
    return y * d2 + (1.0 - y) * F.relu(margin - d2)


def sns_loss(h_a: torch.Tensor, h_b: torch.Tensor, y: torch.Tensor, margin: float = 1.0) -> torch.Tensor:
    """L_SNS: contrastive loss on the sequence encodings of the whole windows, h [B, dim], y [B]; mean over pairs."""
    return contrastive(h_a, h_b, y, margin).mean()


def sni_loss(e_a: torch.Tensor, e_b: torch.Tensor, y: torch.Tensor, margin: float = 1.0) -> torch.Tensor:
    """L_SNI: contrastive loss on frame encodings e [T, B, dim] at equal time steps, mean over time and pairs."""
    return contrastive(e_a, e_b, y.unsqueeze(0), margin).mean()


def reconstruction_loss(recon: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L2 reconstruction error as a mean squared error per pixel."""
    return (recon - target).pow(2).mean()


def kl_divergence(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, 1)) summed over the last axis, mean over the rest."""
    return (0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar)).sum(-1).mean()


def vae_loss(recon: torch.Tensor, target: torch.Tensor, mu: torch.Tensor, logvar: torch.Tensor,
             beta: float) -> torch.Tensor:
    """L_VAEI for a set of frames: per-pixel MSE + beta * KL (per frame), averaged over frames."""
    return reconstruction_loss(recon, target) + beta * kl_divergence(mu, logvar)


def _subset(n: int, k: int, device: torch.device) -> torch.Tensor | None:
    """Indices of a random subset of k of n items (None = all, when k <= 0 or k >= n)."""
    if k <= 0 or k >= n:
        return None
    return torch.randperm(n, device=device)[:k]


def raes_loss(model: DistanceModel, h_last: torch.Tensor, frames: torch.Tensor, max_frames: int = 0
              ) -> torch.Tensor:
    """L_RAES: decode h of each sequence in REVERSE order and compare with the time-reversed frames.

    h_last [S, seq_latent], frames [T, S, H, W]. Decoded frame k of a sequence
    is compared with frame T-1-k. With ``max_frames`` > 0 only a random subset
    of that many (time, sequence) frames goes through psi (an unbiased estimate
    of the same mean, for CPU cost).
    """
    T = frames.shape[0]
    y = model.rho(h_last, T)                               # [T, S, D], last frame first
    target = frames.flip(0)
    idx = _subset(y.shape[0] * y.shape[1], max_frames, y.device)
    if idx is None:
        return reconstruction_loss(model.psi(y), target)
    y, target = y.reshape(-1, y.shape[-1])[idx], target.reshape(-1, *frames.shape[2:])[idx]
    return reconstruction_loss(model.psi(y), target)


def vaei_loss(model: DistanceModel, mu: torch.Tensor, logvar: torch.Tensor, frames: torch.Tensor,
              beta: float, max_frames: int = 0) -> torch.Tensor:
    """L_VAEI over frames [..., H, W] with encodings [..., D]: reparameterised sample, decode, MSE + beta * KL.

    ``max_frames`` > 0: use a random subset of that many frames (unbiased for the mean).
    """
    mu, logvar = mu.reshape(-1, mu.shape[-1]), logvar.reshape(-1, logvar.shape[-1])
    frames = frames.reshape(-1, *frames.shape[-2:])
    idx = _subset(mu.shape[0], max_frames, mu.device)
    if idx is not None:
        mu, logvar, frames = mu[idx], logvar[idx], frames[idx]
    z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()
    return vae_loss(model.psi(z), frames, mu, logvar, beta)


def unique_frames(frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Bitwise-identical frames of [N, H, W] found once: returns (unique [U, H, W], inverse [N]).

    Pairs such as (x, reversed x) hold the same frames twice; encoding each distinct
    frame once saves a third of the encoder work on a typical batch. Rows are grouped
    by a random-projection fingerprint and the grouping is verified exactly; if any
    fingerprint collides the frames are returned as they are.
    """
    flat = frames.reshape(frames.shape[0], -1)
    proj = torch.linspace(0.5, 1.5, flat.shape[1], device=flat.device, dtype=torch.float64)
    key = (flat.to(torch.float64) * proj).sum(1)
    _, inverse = torch.unique(key, return_inverse=True)
    first = torch.full((int(inverse.max()) + 1,), flat.shape[0], dtype=torch.long, device=flat.device)
    first.scatter_reduce_(0, inverse, torch.arange(flat.shape[0], device=flat.device), reduce="amin")
    if not torch.equal(flat[first[inverse]], flat):
        return frames, torch.arange(frames.shape[0], device=frames.device)
    return frames[first], inverse


def total_loss(model: DistanceModel, a: torch.Tensor, b: torch.Tensor, y: torch.Tensor
               ) -> tuple[torch.Tensor, dict[str, float]]:
    """Weighted VIRL loss of a batch of pairs; a, b [T, B, H, W] in [0, 1], y [B] in {0, 1}.

    Returns the scalar loss (with gradient) and the parts as floats for logging.
    The variant decides which parts exist (see :class:`RewardConfig`). Identical
    frames in the batch are encoded once (:func:`unique_frames`); L_VAEI averages
    over the distinct frames.
    """
    cfg: RewardConfig = model.cfg
    n = a.shape[1]
    frames = torch.cat([a, b], dim=1)                      # [T, 2B, H, W]
    uniq, inverse = unique_frames(frames.reshape(-1, *frames.shape[2:]))
    mu_u, logvar_u = model.encode_frames(uniq)             # each distinct frame encoded once
    mu = mu_u[inverse].reshape(*frames.shape[:2], -1)      # [T, 2B, D]
    parts: dict[str, torch.Tensor] = {}
    weights: dict[str, float] = {}
    parts["sni"] = sni_loss(mu[:, :n], mu[:, n:], y, cfg.loss.margin)
    weights["sni"] = cfg.loss.w_sni if cfg.uses_lstm else cfg.loss.w_sns + cfg.loss.w_sni
    if cfg.uses_lstm:
        h, _ = model.encode_sequence(mu)
        parts["sns"] = sns_loss(h[-1, :n], h[-1, n:], y, cfg.loss.margin)
        weights["sns"] = cfg.loss.w_sns
        if cfg.uses_decoders:
            parts["raes"] = raes_loss(model, h[-1], frames, cfg.loss.ae_frames)
            weights["raes"] = cfg.loss.w_raes
    if cfg.uses_decoders:
        parts["vaei"] = vaei_loss(model, mu_u, logvar_u, uniq, cfg.loss.vae_beta, cfg.loss.ae_frames)
        weights["vaei"] = cfg.loss.w_vaei
    loss = sum(weights[k] * parts[k] for k in parts)
    logs = {k: float(v.detach()) for k, v in parts.items()}
    logs["total"] = float(loss.detach())
    return loss, logs
