"""Pairs without labels: each constructor builds (seq_a, seq_b, label) from unlabelled windows.

Windows are float32 arrays [T, H, W] in [0, 1]. Single-source constructors take
a window ``x`` of length L + 1 (one spare frame, needed by the out-of-sync
copies) and return two sequences of exactly L frames. label 1 = "the same
motion" (positive), 0 = "different" (negative). Nothing here is stored: the
batch sampler calls these when a batch is drawn.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Pair = tuple[np.ndarray, np.ndarray, int]


def _check(x: np.ndarray, need: int) -> int:
    if x.ndim != 3 or x.shape[0] < need:
        raise ValueError(f"window must be [T>={need}, H, W], got {list(x.shape)}")
    return x.shape[0] - 1


def _maybe_swap(a: np.ndarray, b: np.ndarray, label: int, rng: np.random.Generator) -> Pair:
    return (b, a, label) if rng.random() < 0.5 else (a, b, label)


def _derangement(n: int, rng: np.random.Generator) -> np.ndarray:
    """A random permutation of range(n) that is not the identity (n >= 2)."""
    while True:
        p = rng.permutation(n)
        if (p != np.arange(n)).any():
            return p


# -- positives ------------------------------------------------------------------------------
def gaussian_noise(x: np.ndarray, rng: np.random.Generator, sigma: float = 0.05) -> Pair:
    """Positive: the window and a copy with i.i.d. Gaussian noise (std ``sigma``) on every pixel, clipped to [0, 1]."""
    L = _check(x, 2)
    a = x[:L]
    b = np.clip(a + rng.normal(0.0, sigma, a.shape).astype(np.float32), 0.0, 1.0)
    return a, b, 1


def out_of_sync(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Positive: out-of-sync copies, one without the first frame, the other without the last (x[1:], x[:-1])."""
    _check(x, 3)
    return _maybe_swap(x[1:], x[:-1], 1, rng)


def duplicate_first(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Positive: the window and a copy whose first frame is shown twice ([x0, x0, x1, ..., x_{L-2}]); either side."""
    L = _check(x, 3)
    a = x[:L]
    b = np.concatenate([a[:1], a[:L - 1]], axis=0)
    return _maybe_swap(a, b, 1, rng)


def duplicate_last(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Positive: the window and a copy whose last frame is shown twice ([x0, ..., x_{L-2}, x_{L-2}]); either side."""
    L = _check(x, 3)
    a = x[:L]
    b = np.concatenate([a[:L - 1], a[L - 2:L - 1]], axis=0)
    return _maybe_swap(a, b, 1, rng)


def same_source(x1: np.ndarray, x2: np.ndarray, length: int) -> Pair:
    """Positive: two windows drawn from the same source (agent-agent or expert-expert), first ``length`` frames."""
    if x1.shape[0] < length or x2.shape[0] < length:
        raise ValueError(f"same_source needs two windows of >= {length} frames")
    return x1[:length], x2[:length], 1


# -- negatives ------------------------------------------------------------------------------
def reversed_order(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Negative: the window and the same frames played backwards."""
    L = _check(x, 3)
    a = x[:L]
    return a, a[::-1].copy(), 0


def frozen_frame(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Negative: the window and one of its frames (chosen at random) repeated for the whole length."""
    L = _check(x, 3)
    a = x[:L]
    k = int(rng.integers(L))
    return a, np.repeat(a[k:k + 1], L, axis=0), 0


def shuffled_one(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Negative: the window and a copy with its frames in a random (non-identity) order."""
    L = _check(x, 3)
    a = x[:L]
    return a, a[_derangement(L, rng)], 0


def shuffled_both(x: np.ndarray, rng: np.random.Generator) -> Pair:
    """Negative: two copies of the window, each shuffled with a different random order (L >= 3)."""
    L = _check(x, 4)
    a = x[:L]
    p = _derangement(L, rng)
    q = _derangement(L, rng)
    while (q == p).all():
        q = _derangement(L, rng)
    return a[p], a[q], 0


def expert_vs_agent(expert: np.ndarray, agent: np.ndarray, length: int) -> Pair:
    """Negative (adversarial): an expert window and an agent window (the agent's matching frames)."""
    if expert.shape[0] < length or agent.shape[0] < length:
        raise ValueError(f"expert_vs_agent needs two windows of >= {length} frames")
    return expert[:length], agent[:length], 0


def other_clip(demo: np.ndarray, other: np.ndarray, length: int) -> Pair:
    """Negative: a window of the demonstration and a window of a clip of another motion."""
    if demo.shape[0] < length or other.shape[0] < length:
        raise ValueError(f"other_clip needs two windows of >= {length} frames")
    return demo[:length], other[:length], 0


#: Constructors of one window (x has L + 1 frames), by the name used in RewardConfig.pair_weights.
SINGLE: dict[str, Callable[[np.ndarray, np.random.Generator], Pair]] = {
    "out_of_sync": out_of_sync,
    "duplicate_first": duplicate_first,
    "duplicate_last": duplicate_last,
    "reversed": reversed_order,
    "frozen_frame": frozen_frame,
    "shuffled_one": shuffled_one,
    "shuffled_both": shuffled_both,
}
