"""The reward model's base: a learned video distance turned into r = exp(w_d * d^2), streamed or recomputed.

    d_t = ||h^e_t - h^a_t|| + ||e^e_t - e^a_t||      (variant "frame": frame term only,
    r_t = exp(w_d * d_t^2), w_d = -5                  "sequence": sequence term only)

Two forms that agree (same network, eval mode, no dropout):

- streaming, for online use: :meth:`RewardModel.stream_step` carries each
  env's LSTM state (agent and expert streams) from step to step;
- batch, for recomputing a rollout after the model was updated:
  :meth:`RewardModel.recompute` over [T, N] frames from the state the rollout
  started with.

Reset convention: ``reset_mask[n]`` at a streaming step means "this frame is
the first of a new episode of env n" (state zeroed before it). In a rollout,
``dones[t, n]`` means "frame t is the last of its episode", so the state is
zeroed before frame t + 1; a reset at the rollout's first frame is given by
``start_reset`` (or is already inside a state fresh from :meth:`stream_state`).
So ``recompute(A, E, dones, s0, start_reset=m0)`` equals streaming from ``s0``
with reset masks m0, dones[0], ..., dones[T-2].
"""

from __future__ import annotations

import contextlib
import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from virl_quad.reward.config import RewardConfig, without_retired
from virl_quad.reward.dataset import EpisodeStore
from virl_quad.reward.frames import painted_levels, paint, paint_float, to_float, to_mask, to_uint8
from virl_quad.reward.trainer import Trainer

FORMAT = "virl_quad.reward/1"
_CHUNK = 512  # frames per encoder call in batch recomputation (cache-sized: faster per frame)
#: RewardConfig fields a resumed run may change: they shape training or the reward, not the model.
RESUME_MAY_CHANGE = ("pair_weights", "w_d")


@dataclass(frozen=True)
class StreamState:
    """Opaque per-env reward state; never modified in place (each step returns a new one).

    h, c: LSTM states [2, N, units] of the agent (index 0) and expert (1) streams (units = 0 without LSTM);
    prev: previous agent frame [N, 48, 48] (GAIfO; [N, 0, 0] otherwise);
    fresh: [N] bool, the next frame starts a new episode.
    """

    h: torch.Tensor
    c: torch.Tensor
    prev: torch.Tensor
    fresh: torch.Tensor

    @property
    def num_envs(self) -> int:
        """Number of envs the state covers."""
        return int(self.fresh.shape[0])

    def with_reset(self, mask: torch.Tensor) -> "StreamState":
        """A copy where the envs in ``mask`` [N] bool start a new episode at the next frame."""
        return StreamState(self.h, self.c, self.prev, self.fresh | mask.to(self.fresh.device))


def _pack_rnn_weights(module: nn.Module) -> None:
    """Lay each LSTM's weights of ``module`` out as one block, cuDNN's layout. Moved to a GPU or
    deep-copied there, they are separate tensors, and every call repacks them (torch warns "RNN
    module weights are not part of single contiguous chunk of memory"). A no-op on the CPU. Later
    in-place updates (optimiser steps, the EMA, load_state_dict) keep the layout."""
    for m in module.modules():
        if isinstance(m, nn.RNNBase):
            m.flatten_parameters()


@contextlib.contextmanager
def eval_mode(module: nn.Module):
    """Run a block with ``module`` in eval mode and without gradients, then restore its mode."""
    was = module.training
    module.eval()
    try:
        with torch.no_grad():
            yield
    finally:
        module.train(was)


class RewardModel:
    """Common machinery: data, training, streaming/batch rewards, checkpoints. Use :func:`build_reward`."""

    def __init__(self, cfg: RewardConfig, demo: np.ndarray, clips: list[np.ndarray], seed: int,
                 device: str | torch.device = "cpu") -> None:
        self.cfg, self.seed, self.device = cfg, int(seed), torch.device(device)
        self._raw = (demo, clips)                    # as given: what a checkpoint saves
        levels = painted_levels(demo) if cfg.pairs.paint_background else np.zeros(0, np.int64)
        self._levels = levels                                    # gray levels painted white
        self._levels_t = torch.from_numpy(levels).to(self.device)
        self.demo, self.clips = paint(demo, levels), [paint(c, levels) for c in clips]   # what the model sees
        self.dataset = EpisodeStore(cfg.store.max_bytes, cfg.store.max_episode_frames)
        with torch.random.fork_rng(devices=[]):  # seeded weight init, caller's global RNG untouched
            torch.manual_seed(self.seed)
            self.net = self._build_net().to(self.device).eval()
        self.reward_net = copy.deepcopy(self.net) if cfg.optim.ema > 0 else self.net   # what rewards come from
        for net in (self.net, self.reward_net):
            _pack_rnn_weights(net)
        self.trainer = Trainer(self.net, self._loss, cfg.optim.lr, cfg.optim.grad_clip, self.seed)

    # -- to be provided by a variant ---------------------------------------------------------
    def _build_net(self) -> nn.Module:
        raise NotImplementedError

    def _loss(self, rng: np.random.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        raise NotImplementedError

    def _lstm_units(self) -> int:
        return 0

    def _frame_side(self) -> int:
        return 0

    def _rollout(self, agent: torch.Tensor, expert: torch.Tensor, resets: torch.Tensor,
                 state: StreamState) -> tuple[torch.Tensor, StreamState]:
        """Distances d [T, N] (>= 0) of frames [T, N, H, W] given resets [T, N] (before frame t)."""
        raise NotImplementedError

    # -- data and training -------------------------------------------------------------------
    def _paint(self, frames, name: str, axes: str) -> np.ndarray:
        """Checked uint8 frames with the background painted (``cfg.pairs.paint_background``)."""
        return paint(to_uint8(frames, name, axes), self._levels)

    def _float(self, frames, name: str, axes: str) -> torch.Tensor:
        """Checked float frames in [0, 1] on the model's device, background painted."""
        return paint_float(to_float(frames, name, axes, self.device), self._levels_t)

    def add_episode(self, agent_frames, expert_frames) -> None:
        """Store one agent episode with its matching expert frames, each [T, 48, 48] uint8."""
        self.dataset.add_episode(self._paint(agent_frames, "agent_frames", "T"),
                                 self._paint(expert_frames, "expert_frames", "T"))

    def add_rollout(self, agent_frames, expert_frames, dones) -> int:
        """Store a rollout [T, N, 48, 48] split into episodes by ``dones`` [T, N]; see EpisodeStore.add_rollout."""
        return self.dataset.add_rollout(self._paint(agent_frames, "agent_frames", "TN"),
                                        self._paint(expert_frames, "expert_frames", "TN"), dones)

    def update(self, num_updates: int) -> dict[str, float]:
        """Run ``num_updates`` batch updates of the distance model; return means over them for logging.

        Keys: the loss parts of the variant (``sns``, ``sni``, ``raes``, ``vaei``; ``disc``,
        ``d_expert``, ``d_agent`` for gaifo), ``total``, ``grad_norm`` (before clipping) and,
        for the VIRL variants, ``window`` (frames per training sequence). Empty for 0 updates.
        """
        logs = self.trainer.update(num_updates)
        if self.reward_net is not self.net:
            keep = self.cfg.optim.ema ** num_updates          # one EMA step per update, applied at once
            with torch.no_grad():
                for slow, fast in zip(self.reward_net.parameters(), self.net.parameters()):
                    slow.mul_(keep).add_(fast, alpha=1.0 - keep)
                # batch-norm statistics: the trained model's (an average from their initial
                # value would scale e by statistics that no weights ever had)
                for slow, fast in zip(self.reward_net.buffers(), self.net.buffers()):
                    slow.copy_(fast)
        return logs

    # -- rewards -----------------------------------------------------------------------------
    def stream_state(self, num_envs: int) -> StreamState:
        """A fresh state for ``num_envs`` envs (every env starts a new episode at its next frame)."""
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        u, s = self._lstm_units(), self._frame_side()
        z = torch.zeros(2, num_envs, u, device=self.device)
        return StreamState(z, z.clone(), torch.zeros(num_envs, s, s, device=self.device),
                           torch.ones(num_envs, dtype=torch.bool, device=self.device))

    def _check_state(self, state: StreamState, n: int) -> None:
        if not isinstance(state, StreamState):
            raise ValueError(f"state must be a StreamState, got {type(state).__name__}")
        if state.num_envs != n or state.h.shape[-1] != self._lstm_units():
            raise ValueError(f"state is for {state.num_envs} envs of this variant, frames for {n}")

    def d2_scale(self) -> float:
        """The unit d^2 is counted in before it becomes a reward (1: raw distances)."""
        return 1.0

    def reward_of(self, d: torch.Tensor) -> torch.Tensor:
        """Rewards exp(w_d d^2 / :meth:`d2_scale`) of distances d (any shape), in [reward_floor, 1]."""
        r = torch.exp(self.cfg.reward.w_d * d.square() / self.d2_scale())
        return r.clamp(min=self.cfg.reward.reward_floor, max=1.0)

    def stream_step(self, agent, expert, state: StreamState, reset_mask=None
                    ) -> tuple[torch.Tensor, StreamState]:
        """Reward of one step for N envs: frames [N, 48, 48] (uint8 or float in [0, 1], numpy or torch).

        ``reset_mask`` [N] bool: these envs start a new episode with this frame.
        Returns (r float32 [N] in (0, 1] on the model's device, the next state).
        """
        a = self._float(agent, "agent", "N")
        e = self._float(expert, "expert", "N")
        n = a.shape[0]
        if e.shape[0] != n:
            raise ValueError(f"agent has {n} frames, expert {e.shape[0]}")
        self._check_state(state, n)
        resets = state.fresh.clone()
        if reset_mask is not None:
            resets |= to_mask(reset_mask, "reset_mask", (n,), self.device)
        with eval_mode(self.reward_net):
            d, state = self._rollout(a[None], e[None], resets[None], state)
        return self.reward_of(d[0]), state

    def recompute(self, agent, expert, dones, start_state: StreamState, start_reset=None,
                  return_state: bool = False):
        """Rewards [T, N] of a whole rollout: frames [T, N, 48, 48], ``dones`` [T, N] (frame t ends an episode).

        ``start_state`` is the state the rollout's first stream_step received and
        ``start_reset`` [N] that step's reset mask. With ``return_state`` also
        returns the state after the last frame (under the current weights).
        """
        a = self._float(agent, "agent", "TN")
        e = self._float(expert, "expert", "TN")
        if a.shape != e.shape:
            raise ValueError(f"agent {list(a.shape)} and expert {list(e.shape)} frames differ in shape")
        T, n = a.shape[:2]
        d_mask = to_mask(dones, "dones", (T, n), self.device)
        self._check_state(start_state, n)
        first = start_state.fresh.clone()
        if start_reset is not None:
            first |= to_mask(start_reset, "start_reset", (n,), self.device)
        resets = torch.cat([first[None], d_mask[:-1]], dim=0)
        with eval_mode(self.reward_net):
            d, state = self._rollout(a, e, resets, start_state)
        r = self.reward_of(d)
        return (r, state) if return_state else r

    def distance(self, expert, agent) -> torch.Tensor:
        """d_t [T, N] between expert and agent sequences [T, N, 48, 48] streamed from a fresh state."""
        a = self._float(agent, "agent", "TN")
        e = self._float(expert, "expert", "TN")
        if a.shape != e.shape:
            raise ValueError(f"agent {list(a.shape)} and expert {list(e.shape)} frames differ in shape")
        resets = torch.zeros(a.shape[:2], dtype=torch.bool, device=self.device)
        with eval_mode(self.reward_net):
            return self._rollout(a, e, resets, self.stream_state(a.shape[1]))[0]

    # -- checkpoints -------------------------------------------------------------------------
    def state_dict(self) -> dict:
        """Config, demonstration, clips, seed, network, optimiser and RNG states (not the dataset)."""
        return {
            "format": FORMAT,
            "config": self.cfg.to_dict(),
            "seed": self.seed,
            "demo": torch.from_numpy(self._raw[0].copy()),
            "clips": [torch.from_numpy(c.copy()) for c in self._raw[1]],
            "net": {k: v.detach().cpu().clone() for k, v in self.net.state_dict().items()},
            "reward_net": {k: v.detach().cpu().clone() for k, v in self.reward_net.state_dict().items()},
            "trainer": self.trainer.state_dict(),
        }

    def load_state_dict(self, d: dict) -> None:
        """Restore network, optimiser and RNG states saved by a model with the same config
        (:data:`RESUME_MAY_CHANGE` aside: a resumed run may draw pairs or shape the reward differently)."""
        if d.get("format") != FORMAT:
            raise ValueError(f"not a {FORMAT} state (format {d.get('format')!r})")
        saved, mine = without_retired(d["config"]), self.cfg.to_dict()   # an older version's settings
        for key in RESUME_MAY_CHANGE:                 # how pairs are drawn and d becomes a reward
            saved.pop(key, None)
            mine.pop(key, None)
        if saved != mine:
            raise ValueError("state was saved with a different RewardConfig")
        self.net.load_state_dict(d["net"])
        if self.reward_net is not self.net:
            self.reward_net.load_state_dict(d.get("reward_net", d["net"]))
        self.trainer.load_state_dict(d["trainer"])

    def save(self, path: str | Path) -> None:
        """Write :meth:`state_dict` to ``path`` (readable with torch.load(weights_only=True));
        :func:`virl_quad.reward.reward.load_reward` rebuilds the model from it."""
        torch.save(self.state_dict(), str(path))
