"""GAIfO baseline: a discriminator on consecutive frame pairs, expert (1) versus agent (0).

Reward choice: r_t = D(o_{t-1}, o_t) = sigmoid(logit) in (0, 1] (clamped to
>= reward_floor), the probability that the agent's transition is the
expert's. It is positive and bounded like the VIRL reward, so the two are
interchangeable in the PPO loop (no change of sign or scale conventions, and
early termination is not rewarded). Internally the distance is
d = sqrt(softplus(-logit) / |w_d|) so that exp(w_d * d^2) = D exactly.
At an episode's first frame the pair is (o_0, o_0).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from virl_quad.reward.config import RewardConfig
from virl_quad.reward.frames import FRAME
from virl_quad.reward.model import conv_out
from virl_quad.reward.base import _CHUNK, RewardModel, StreamState

_SCALE = np.float32(1.0 / 255.0)


class PairDiscriminator(nn.Module):
    """Logit that a (previous, current) frame pair comes from the expert; same trunk sizes as phi."""

    def __init__(self, cfg: RewardConfig) -> None:
        super().__init__()
        a = cfg.arch
        self.conv1 = nn.Conv2d(2, a.conv1_filters, a.conv1_kernel, a.conv1_stride)
        self.drop = nn.Dropout2d(a.dropout)  # whole feature maps: far cheaper on CPU than per-unit
        self.conv2 = nn.Conv2d(a.conv1_filters, a.conv2_filters, a.conv2_kernel, a.conv2_stride)
        n2 = conv_out(conv_out(a.image_size, a.conv1_kernel, a.conv1_stride), a.conv2_kernel, a.conv2_stride)
        self.fc = nn.Linear(a.conv2_filters * n2 * n2, a.dense_units)
        self.out = nn.Linear(a.dense_units, 1)

    def forward(self, prev: torch.Tensor, cur: torch.Tensor) -> torch.Tensor:
        """Frames [B, H, W] each (in [0, 1]) -> logits [B]."""
        x = torch.stack([prev, cur], dim=1)
        x = self.drop(F.relu(self.conv1(x)))
        x = F.relu(self.conv2(x))
        return self.out(F.relu(self.fc(x.flatten(1)))).squeeze(-1)


class GaifoReward(RewardModel):
    """The GAIfO baseline behind the common reward-model API (variant ``gaifo``)."""

    net: PairDiscriminator

    def _build_net(self) -> nn.Module:
        return PairDiscriminator(self.cfg)

    def _frame_side(self) -> int:
        return FRAME

    def _expert_pairs(self, rng: np.random.Generator, k: int) -> tuple[np.ndarray, np.ndarray]:
        T = self.demo.shape[0]
        i = rng.integers(0, T if self.cfg.pairs.clips_cyclic else T - 1, size=k)
        j = (i + 1) % T
        return self.demo[i], self.demo[j]

    def _agent_pairs(self, rng: np.random.Generator, k: int) -> tuple[np.ndarray, np.ndarray]:
        seqs = self.dataset.sequences()
        lengths = np.array([a.shape[0] for a, _ in seqs], dtype=np.int64)
        eligible = np.flatnonzero(lengths >= 2)
        if eligible.size == 0:
            raise ValueError("gaifo needs stored agent episodes of >= 2 frames before update()")
        w = (lengths[eligible] - 1).astype(np.float64)
        eps = rng.choice(eligible, size=k, p=w / w.sum())  # uniform over stored transitions
        prev, cur = [], []
        for e in eps.tolist():
            agent, _ = seqs[e]
            t = int(rng.integers(1, agent.shape[0]))
            prev.append(agent[t - 1])
            cur.append(agent[t])
        return np.stack(prev), np.stack(cur)

    def _loss(self, rng: np.random.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        k = self.cfg.pairs.batch_pairs
        ep, ec = self._expert_pairs(rng, k)
        ap, ac = self._agent_pairs(rng, k)
        prev = torch.from_numpy(np.concatenate([ep, ap]).astype(np.float32) * _SCALE).to(self.device)
        cur = torch.from_numpy(np.concatenate([ec, ac]).astype(np.float32) * _SCALE).to(self.device)
        y = torch.cat([torch.ones(k), torch.zeros(k)]).to(self.device)
        logits = self.net(prev, cur)
        loss = F.binary_cross_entropy_with_logits(logits, y)
        with torch.no_grad():
            p = torch.sigmoid(logits)
        return loss, {"disc": float(loss.detach()), "total": float(loss.detach()),
                      "d_expert": float(p[:k].mean()), "d_agent": float(p[k:].mean())}

    def _rollout(self, agent, expert, resets, state):
        T, n = agent.shape[:2]
        before = torch.cat([state.prev[None], agent[:-1]], dim=0)        # frame t-1 (state for t = 0)
        prev = torch.where(resets[..., None, None], agent, before)      # a new episode pairs (o_0, o_0)
        p, c = prev.reshape(-1, FRAME, FRAME), agent.reshape(-1, FRAME, FRAME)
        logits = torch.cat([self.reward_net(p[i:i + _CHUNK], c[i:i + _CHUNK]) for i in range(0, p.shape[0], _CHUNK)])
        d = (F.softplus(-logits) / -self.cfg.reward.w_d).sqrt().reshape(T, n)
        new = StreamState(state.h, state.c, agent[-1].clone(), torch.zeros_like(state.fresh))
        return d, new
