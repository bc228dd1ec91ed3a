"""Drawing one training batch of pairs: half positive, half negative, built on the fly.

Material comes from three places: agent episodes in the off-policy store
(EESP windows), the demonstration (time-warped windows) and, when given,
clips of other motions. One window length L is drawn per batch (EESP), so
every sequence of a batch has L frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from virl_quad.reward import augment, pairs
from virl_quad.reward.config import NEGATIVE_PAIRS, POSITIVE_PAIRS, RewardConfig
from virl_quad.reward.dataset import EpisodeStore

_SCALE = np.float32(1.0 / 255.0)


@dataclass
class Batch:
    """A batch of pairs, time-major: a, b float32 [L, B, H, W] in [0, 1]; y float32 [B] (1 = positive)."""

    a: np.ndarray
    b: np.ndarray
    y: np.ndarray
    kinds: list[str]


class PairSampler:
    """Builds batches of labelled pairs from unlabelled demonstration, clips and agent episodes."""

    def __init__(self, cfg: RewardConfig, demo: np.ndarray, clips: list[np.ndarray],
                 dataset: EpisodeStore) -> None:
        self.cfg, self.demo, self.clips, self.dataset = cfg, demo, list(clips), dataset
        self._seqs: list[tuple[np.ndarray, np.ndarray]] = []
        off = cfg.pairs.same_source_max_offset
        shortest = min(c.shape[0] for c in [demo] + self.clips)
        if not cfg.pairs.clips_cyclic and shortest < cfg.pairs.window_min + 1 + 2 * off:
            raise ValueError(f"clips need >= {cfg.pairs.window_min + 1 + 2 * off} frames "
                             f"(window_min + 1 + 2 * same_source_max_offset) unless clips_cyclic; got {shortest}")
        self.clip_cap = 10**9 if cfg.pairs.clips_cyclic else shortest - 1 - 2 * off

    # -- material -----------------------------------------------------------------------------
    def _expert_clip(self, rng: np.random.Generator) -> np.ndarray:
        if self.clips and rng.random() >= 0.5:
            return self.clips[int(rng.integers(len(self.clips)))]
        return self.demo

    def _warped(self, rng: np.random.Generator, clip: np.ndarray, need: int) -> np.ndarray:
        c = self.cfg.pairs
        return augment.warped_window(rng, clip, need, c.warp_min, c.warp_max, c.clips_cyclic)[0]

    def _agent_window(self, rng: np.random.Generator, eligible: np.ndarray, need: int
                      ) -> tuple[np.ndarray, np.ndarray, int]:
        """(agent uint8 episode, expert uint8 episode, EESP start) for a window of ``need`` frames."""
        agent, expert = self._seqs[int(rng.choice(eligible))]
        return agent, expert, augment.eesp_start(rng, agent.shape[0], need)

    def _anchor(self, rng: np.random.Generator, eligible: np.ndarray, need: int) -> np.ndarray:
        """One window of ``need`` frames: an agent window (EESP) or an expert-material window (warped)."""
        if eligible.size and rng.random() < self.cfg.pairs.agent_source_prob:
            agent, _, i = self._agent_window(rng, eligible, need)
            return agent[i:i + need].astype(np.float32) * _SCALE
        return self._warped(rng, self._expert_clip(rng), need)

    def _same_source(self, rng: np.random.Generator, eligible: np.ndarray, L: int) -> pairs.Pair:
        off = self.cfg.pairs.same_source_max_offset
        if eligible.size and rng.random() < self.cfg.pairs.agent_source_prob:
            agent, _, i = self._agent_window(rng, eligible, L)
            lo, hi = max(0, i - off), min(agent.shape[0] - L, i + off)
            j = int(rng.integers(lo, hi + 1))
            x1 = agent[i:i + L].astype(np.float32) * _SCALE
            x2 = agent[j:j + L].astype(np.float32) * _SCALE
        else:
            stream = self._warped(rng, self._expert_clip(rng), L + 2 * off)
            o1, o2 = rng.integers(0, 2 * off + 1, size=2)
            x1, x2 = stream[o1:o1 + L], stream[o2:o2 + L]
        return pairs.same_source(x1, x2, L)

    # -- batch --------------------------------------------------------------------------------
    def window_length(self, rng: np.random.Generator) -> int:
        """Draw this batch's window length L (EESP, capped by the clips when they do not loop)."""
        c = self.cfg.pairs
        l_max = augment.eesp_max_length(self.dataset.mean_episode_length, c.window_min, c.window_max)
        return augment.eesp_length(rng, c.window_min, min(l_max, self.clip_cap))

    def available(self, L: int, have_agent: bool) -> tuple[list[str], list[str]]:
        """Names of the positive and negative constructors usable for windows of L frames."""
        w = self.cfg.pairs.pair_weights
        pos = [n for n in POSITIVE_PAIRS if w.get(n, 1.0) > 0]
        neg = [n for n in NEGATIVE_PAIRS if w.get(n, 1.0) > 0
               and not (n == "expert_vs_agent" and not have_agent)
               and not (n == "other_clip" and not self.clips)
               and not (n == "shuffled_both" and L < 3)]
        if not pos or not neg:
            raise ValueError("pair_weights leave no positive or no negative pair constructor")
        return pos, neg

    def _pick(self, rng: np.random.Generator, names: list[str]) -> str:
        w = np.array([self.cfg.pairs.pair_weights.get(n, 1.0) for n in names], dtype=np.float64)
        return names[int(rng.choice(len(names), p=w / w.sum()))]

    def make_pair(self, rng: np.random.Generator, name: str, L: int, eligible: np.ndarray) -> pairs.Pair:
        """Build one pair of L-frame sequences with the named constructor."""
        if name == "gaussian_noise":
            return pairs.gaussian_noise(self._anchor(rng, eligible, L + 1), rng, self.cfg.pairs.noise_sigma)
        if name in pairs.SINGLE:
            return pairs.SINGLE[name](self._anchor(rng, eligible, L + 1), rng)
        if name == "same_source":
            return self._same_source(rng, eligible, L)
        if name == "expert_vs_agent":
            agent, expert, i = self._agent_window(rng, eligible, L)
            return pairs.expert_vs_agent(expert[i:i + L].astype(np.float32) * _SCALE,
                                         agent[i:i + L].astype(np.float32) * _SCALE, L)
        if name == "other_clip":
            other = self.clips[int(rng.integers(len(self.clips)))]
            return pairs.other_clip(self._warped(rng, self.demo, L), self._warped(rng, other, L), L)
        raise ValueError(f"unknown pair constructor {name!r}")

    def draw(self, rng: np.random.Generator, batch_pairs: int | None = None) -> Batch:
        """Draw a batch: ``batch_pairs`` pairs (default cfg.pairs.batch_pairs), the first half positive."""
        B = batch_pairs or self.cfg.pairs.batch_pairs
        L = self.window_length(rng)
        self._seqs = self.dataset.sequences()       # finished and open agent episodes
        lengths = np.array([a.shape[0] for a, _ in self._seqs], dtype=np.int64)
        eligible = np.flatnonzero(lengths >= L + 1)
        pos, neg = self.available(L, eligible.size > 0)
        kinds = [self._pick(rng, pos) for _ in range(B // 2)] + [self._pick(rng, neg) for _ in range(B - B // 2)]
        made = [self.make_pair(rng, k, L, eligible) for k in kinds]
        view = (rng, self.cfg.pairs.view_zoom, self.cfg.pairs.view_shift)
        a = augment.view_jitter(np.stack([m[0] for m in made], axis=1), *view)
        b = augment.view_jitter(np.stack([m[1] for m in made], axis=1), *view)
        y = np.array([m[2] for m in made], dtype=np.float32)
        return Batch(a, b, y, kinds)
