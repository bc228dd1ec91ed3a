"""The VIRL reward model (variants virl, frame, sequence, no_ae) and :func:`build_reward`, which
builds the model of any variant (GAIfO's discriminator included). The streaming and batch forms
and their reset conventions are those of :mod:`virl_quad.reward.base`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from virl_quad.reward.base import _CHUNK, FORMAT, RewardModel, StreamState, eval_mode
from virl_quad.reward.config import RewardConfig
from virl_quad.reward.frames import FRAME, to_uint8
from virl_quad.reward.losses import total_loss
from virl_quad.reward.model import DistanceModel
from virl_quad.reward.sampler import PairSampler


#: first frames of each sequence left out of the calibration (the sequence encoder warms up)
CALIBRATION_SKIP = 10


class VirlReward(RewardModel):
    """The VIRL distance (variants virl, frame, sequence, no_ae)."""

    net: DistanceModel

    def __init__(self, cfg: RewardConfig, demo: np.ndarray, clips: list[np.ndarray], seed: int,
                 device: str | torch.device = "cpu") -> None:
        super().__init__(cfg, demo, clips, seed, device)
        self.sampler = PairSampler(self.cfg, self.demo, self.clips, self.dataset)
        self._d2_ref: float | None = None      # see d2_scale

    def _build_net(self) -> nn.Module:
        return DistanceModel(self.cfg)

    def _lstm_units(self) -> int:
        return self.cfg.arch.lstm_units if self.cfg.uses_lstm else 0

    def _loss(self, rng: np.random.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        batch = self.sampler.draw(rng)
        a = torch.from_numpy(batch.a).to(self.device)
        b = torch.from_numpy(batch.b).to(self.device)
        y = torch.from_numpy(batch.y).to(self.device)
        loss, logs = total_loss(self.net, a, b, y)
        logs["window"] = float(batch.a.shape[0])
        return loss, logs

    def update(self, num_updates: int) -> dict[str, float]:
        """As :meth:`RewardModel.update`, plus ``e_spread`` (see :meth:`encoding_spread`) and
        ``d2_ref`` (see :meth:`d2_scale`)."""
        logs = super().update(num_updates)
        if logs:
            logs["e_spread"] = self.encoding_spread()
            self._calibrate()
            logs["d2_ref"] = self.d2_scale()
        return logs

    def load_state_dict(self, d: dict) -> None:
        """As :meth:`RewardModel.load_state_dict`; the calibration is measured again."""
        super().load_state_dict(d)
        if self.trainer.num_updates > 0:
            self._calibrate()

    def d2_scale(self) -> float:
        """With ``calibrate``, once trained: the reward copy's mean d^2 (frames :data:`CALIBRATION_SKIP`
        on, each sequence from a fresh state) between the demonstration and its negatives (the
        other clips, or the demonstration reversed), over their common length; else 1."""
        return self._d2_ref if self.cfg.reward.calibrate and self._d2_ref is not None else 1.0

    def _calibrate(self) -> None:
        negatives = self.clips or [self.demo[::-1]]
        n = min(len(self.demo), *(len(c) for c in negatives))
        others = np.stack([c[:n] for c in negatives], axis=1)               # [n, K, 48, 48], one pass
        expert = np.repeat(self.demo[:n, None], len(negatives), axis=1)
        ref = float(self.distance(expert, others)[min(CALIBRATION_SKIP, n - 1):].square().mean())
        self._d2_ref = ref if np.isfinite(ref) and ref > 1e-6 else None

    def encoding_spread(self) -> float:
        """Mean over latent units of the standard deviation, over the demonstration's frames, of
        the reward copy's frame encoding e (in (0, 1)): near 0 the encoder has collapsed, it maps
        every frame alike and every behaviour gets reward 1 (healthy models: 0.04-0.3)."""
        x = torch.from_numpy(self.demo[:512]).to(self.device).float() / 255.0
        with torch.no_grad(), eval_mode(self.reward_net):
            return float(self._encode(x).std(0).mean())

    def _encode(self, x: torch.Tensor) -> torch.Tensor:
        lead = x.shape[:-2]
        flat = x.reshape(-1, FRAME, FRAME)
        mu = torch.cat([self.reward_net.encode_frames(flat[i:i + _CHUNK])[0] for i in range(0, flat.shape[0], _CHUNK)])
        return mu.reshape(*lead, -1)

    def _rollout(self, agent, expert, resets, state):
        cfg, n = self.cfg, agent.shape[1]
        e = self._encode(torch.cat([agent, expert], dim=1))          # [T, 2N, D]: agent first
        d_frame = (e[:, :n] - e[:, n:]).norm(dim=-1)
        if not cfg.uses_lstm:
            return d_frame, StreamState(state.h, state.c, state.prev, torch.zeros_like(state.fresh))
        lstm, head = self.reward_net.omega.lstm, self.reward_net.omega.head
        h = state.h.reshape(1, 2 * n, -1)
        c = state.c.reshape(1, 2 * n, -1)
        outs = []
        for t in range(agent.shape[0]):
            keep = (~resets[t]).repeat(2).to(h.dtype)[None, :, None]   # same mask for both streams
            out, (h, c) = lstm(e[t:t + 1], (h * keep, c * keep))
            outs.append(out)
        hs = head(torch.cat(outs, dim=0))                              # [T, 2N, S]
        d_seq = (hs[:, :n] - hs[:, n:]).norm(dim=-1)
        d = d_seq if cfg.variant == "sequence" else d_seq + d_frame
        new = StreamState(h.reshape(2, n, -1), c.reshape(2, n, -1), state.prev, torch.zeros_like(state.fresh))
        return d, new


def build_reward(cfg: RewardConfig, demo_frames, other_clips: list | None = None, seed: int = 0,
                 device: str | torch.device = "cpu") -> RewardModel:
    """Build the reward model of ``cfg.variant`` for a demonstration [T, 48, 48] (uint8 or float in [0, 1]).

    ``other_clips``: optional clips [T_k, 48, 48] of other motions (extra negatives
    and anchor material: the paper's multi-task data). ``seed`` fixes weights, batch drawing,
    dropout and noise.
    """
    cfg = RewardConfig.from_dict(cfg.to_dict())  # a validated private copy
    demo = to_uint8(demo_frames, "demo_frames", "T")
    if demo.shape[0] < 2:
        raise ValueError(f"demo_frames needs >= 2 frames, got {demo.shape[0]}")
    clips = [to_uint8(c, f"other_clips[{i}]", "T") for i, c in enumerate(other_clips or [])]
    if cfg.variant == "gaifo":
        from virl_quad.reward.gaifo import GaifoReward

        return GaifoReward(cfg, demo, clips, seed, device)
    return VirlReward(cfg, demo, clips, seed, device)


def from_state_dict(d: dict, device: str | torch.device = "cpu") -> RewardModel:
    """The reward model of any variant rebuilt from its :meth:`RewardModel.state_dict` (the
    dataset starts empty)."""
    cfg = RewardConfig.from_dict(d["config"])
    rm = build_reward(cfg, d["demo"].numpy(), [c.numpy() for c in d["clips"]], d["seed"], device)
    rm.load_state_dict(d)
    return rm


def load_reward(path: str | Path, device: str | torch.device = "cpu") -> RewardModel:
    """A reward model saved with :meth:`RewardModel.save`; ValueError for another kind of file."""
    d = torch.load(str(path), map_location="cpu", weights_only=True)
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} file")
    return from_state_dict(d, device)
