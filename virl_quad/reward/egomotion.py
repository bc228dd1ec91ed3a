"""How fast the subject of a follow-camera video travels, from the pixels alone.

The follow camera keeps the robot in the middle of the frame, so its travel shows only in
the ground sliding past behind it. The distance model cannot see that: it paints the
ground out (:func:`virl_quad.reward.frames.paint`), since the pattern's phase says where
the robot stands rather than how it moves. A silhouette walking in place and one walking
forwards look alike to it, and a gait that drifts backwards is rewarded as one that walks.

This module measures the ground's slide instead: between two frames ``k`` steps apart, the
shift (px) that best maps the earlier frame's ground pixels onto the later frame's, by a
masked sum of squared differences over integer shifts (the ground blurred first so that
the cost is smooth; every shift's sum at once, by FFT) and a parabola through the best one for the sub-pixel part. The same
estimator runs on the demonstration and on the agent's frames, so its scale (px per m,
which perspective varies by row) cancels in their comparison; a robot's follow camera stands
off in proportion to its size, so a video of another robot compares too, in body lengths, as
a retargeted clip does. It needs a ground with a pattern the camera sees (the ``checker``
ground); on a plain ground there is nothing to measure, and :func:`clip_speed` says so (None).
Each video's ground is found in its own frames (:func:`ground_levels`).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from virl_quad.reward.frames import BORDER_ROWS, flat_levels, level_table, textured_ground

WINDOW_S = 0.16      # s between the two frames compared (8 steps at Pupper's 50 Hz)
MAX_DX = 8           # px, largest horizontal shift searched (Pupper's camera sees the checker at ~25 px
                     # a period; a camera that sees it smaller searches less: :func:`search_reach`)
MAX_DY = 1           # px, vertical shifts searched too (the camera follows the base's bob)
BLUR_SIGMA = 1.0     # px, Gaussian blur of the ground before matching
MIN_PIXELS = 50      # ground pixels two frames must share for a shift to count
MIN_VALID = 0.5      # share of a clip's frame pairs that must give a shift for a clip speed
MIN_CONTRAST = 0.2   # relative rise of the cost away from its best shift: below, no pattern to see
MIN_SLIDE = 0.1      # px per frame, a clip's slide under which its window cannot alias
HEADROOM = 1.5       # an agent this many times as fast as the demonstration still reads within the search
CENTRE = 128.0       # gray level subtracted before the FFTs (keeps their sums small)


def window_steps(fps: float) -> int:
    """Frames between the two frames compared, :data:`WINDOW_S` at ``fps`` (at least 2)."""
    return max(2, int(round(WINDOW_S * float(fps))))


def clip_window(frames: np.ndarray, fps: float, levels: np.ndarray | None = None, reach: int = MAX_DX) -> int:
    """Frames between the two frames compared for this clip: :func:`window_steps`, unless the
    ground slides so far in that many frames that its pattern aliases (a shift past half the
    checker's period reads as one the other way: a Laikago's trot at its camera's scale). The
    clip's mean shift is measured over 1, 2, ... frames; at the first span whose shift per frame
    turns against, or strays by over half from, the 1-frame figure, half that span is kept, so
    that an agent up to twice as fast stays unaliased too. Nor is a window kept over which an
    agent :data:`HEADROOM` times as fast as the clip would slide past the shifts searched
    (``reach``, less the half pixel the sub-pixel step needs): its reading would stop growing
    there, and the clip's own would read short."""
    frames = np.asarray(frames, dtype=np.uint8)
    full = window_steps(fps)
    levels = ground_levels(frames) if levels is None else levels
    if len(frames) <= full or len(levels) == 0:
        return full

    def per_frame(k: int) -> float:
        s = ground_shift(frames[:-k], frames[k:], levels, reach)
        s = s[torch.isfinite(s)]
        return float(s.mean()) / k if len(s) else float("nan")

    one = per_frame(1)
    if not np.isfinite(one) or abs(one) < MIN_SLIDE:
        return full                                     # too slow to alias within the default window
    for k in range(2, full + 1):
        v = per_frame(k)
        if not np.isfinite(v) or v * one <= 0 or abs(v - one) > 0.5 * abs(one):
            return max(1, k // 2)
        if HEADROOM * abs(v) * k > reach - 0.5:
            return k - 1
    return full


def ground_levels(frames: np.ndarray) -> np.ndarray:
    """The gray levels of a video's ground (T, H, W) uint8: the flat levels of its bottom rows
    (:func:`~virl_quad.reward.frames.flat_levels`), the sky left out; for a textured ground
    (:func:`~virl_quad.reward.frames.textured_ground`: a checker blended between frames), every
    level of its range. int64, sorted."""
    frames = np.asarray(frames, dtype=np.uint8)
    ground = textured_ground(frames)
    if ground is not None:
        return np.arange(ground[0], ground[1] + 1, dtype=np.int64)
    return flat_levels(frames[:, -BORDER_ROWS:])


def search_reach(frames: np.ndarray, levels: np.ndarray | None = None) -> int:
    """Largest shift (px) worth searching in a video's ground: :data:`MAX_DX`, or less where the
    camera sees the ground's pattern repeat sooner. A shift past half the pattern's period
    matches as well as one the other way (a Laikago's camera, 2.6x as far off, sees the checker
    at ~10 px a period: its ground sliding 2.6 px forwards also reads 7 px backwards, and a
    sharp render picks either). Half the period is where the ground, compared with itself moved
    sideways by 1, 2, ... px, first differs most."""
    frames = np.asarray(frames, dtype=np.uint8)
    levels = ground_levels(frames) if levels is None else levels
    if len(levels) == 0:
        return MAX_DX
    f, m = ground_fields(frames, levels)
    diffs = []
    for dx in range(1, MAX_DX + 2):
        both = m[:, :, :-dx] & m[:, :, dx:]
        d = (f[:, :, :-dx] - f[:, :, dx:]).square()
        diffs.append(float((d * both).sum() / both.sum().clamp(min=1)))
    for dx in range(2, MAX_DX + 1):                      # the first peak of the difference
        if diffs[dx - 1] >= diffs[dx]:
            return dx
    return MAX_DX


def _blur(x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Masked Gaussian blur of [M, H, W]: the ground's gray levels smoothed over ground pixels
    only, and where that blur rests on ground alone."""
    r = int(np.ceil(3 * BLUR_SIGMA))
    t = torch.arange(-r, r + 1, dtype=torch.float32)
    g = torch.exp(-t.square() / (2 * BLUR_SIGMA ** 2))
    g = g / g.sum()

    taps = [float(v) for v in g]

    def conv(z: torch.Tensor) -> torch.Tensor:        # separable, as sums of shifted copies: a 7-tap
        h, w = z.shape[1:]                              # conv2d on 48 px frames is 4x slower on a CPU
        padded = F.pad(z[:, None], (r, r, r, r), mode="replicate")[:, 0]
        rows = sum(c * padded[:, :, j:j + w] for j, c in enumerate(taps))
        return sum(c * rows[:, j:j + h, :] for j, c in enumerate(taps))

    m = mask.to(torch.float32)
    weight = conv(m)
    return conv(x * m) / weight.clamp(min=1e-6), weight > 0.95


def _spectra(f: torch.Tensor, m: torch.Tensor, reach: int) -> torch.Tensor:
    """What :func:`_shift_costs` correlates of one stack of :func:`ground_fields` [M, H, W]: the
    2-D spectra [M, 3, ...] of the mask, the masked ground and its square (gray levels taken
    from :data:`CENTRE`: the sum of squared differences does not change, and in float32 the
    shifts then match float64's to ~1e-6 px), zero-padded for shifts up to ``reach`` px."""
    h, w = f.shape[1:]
    m0 = m.to(torch.float32)
    x = (f - CENTRE) * m0
    return torch.fft.rfft2(torch.stack([m0, x, x * (f - CENTRE)], 1), s=_padded(h, w, reach))


def _padded(h: int, w: int, reach: int) -> tuple[int, int]:
    """FFT size for an (h, w) frame: zero padding, so no shift searched wraps round."""
    return h + MAX_DY + 1, w + reach + 1


def _shift_costs(sa: torch.Tensor, sb: torch.Tensor, h: int, w: int, reach: int) -> torch.Tensor:
    """Mean squared difference [M, 2 MAX_DY + 1, 2 reach + 1] between frames ``a`` and ``b``
    (their :func:`_spectra`, (h, w) px) with ``b`` moved by (dy, dx), over the pixels that are
    ground in both (inf where fewer than :data:`MIN_PIXELS`). Each of its sums over pixels is a
    cross-correlation, done at once for every shift by FFT:
    sum m_a m_b (a - b)^2 = corr(m_a a^2, m_b) + corr(m_a, m_b b^2) - 2 corr(m_a a, m_b b)."""
    size = _padded(h, w, reach)
    a, b = sa.conj(), sb
    products = torch.stack([a[:, 0] * b[:, 0],
                            a[:, 2] * b[:, 0] + a[:, 0] * b[:, 2] - 2 * a[:, 1] * b[:, 1]], 1)
    c = torch.fft.irfft2(products, s=size)               # c[dy, dx] = sum_p A[p] B[p + (dy, dx)]
    rows = torch.arange(-MAX_DY, MAX_DY + 1) % size[0]
    cols = torch.arange(-reach, reach + 1) % size[1]
    c = c[:, :, rows][:, :, :, cols]
    count, ssd = c[:, 0].round(), c[:, 1].clamp(min=0.0)
    cost = ssd / count.clamp(min=1.0)
    return torch.where(count >= MIN_PIXELS, cost, torch.full_like(cost, float("inf")))


def ground_shift(earlier: np.ndarray | torch.Tensor, later: np.ndarray | torch.Tensor,
                 levels: np.ndarray, reach: int = MAX_DX) -> torch.Tensor:
    """Horizontal shift (px, float32 [M]) of the ground from ``earlier`` to ``later`` frames
    ([M, H, W] uint8, pairwise), searched within +-``reach`` px: positive when it slides right
    (the subject of a camera looking from its right side moves left, backwards). NaN where the
    two frames share too little ground or the ground shows no pattern."""
    a = torch.as_tensor(np.asarray(earlier), dtype=torch.int64)
    b = torch.as_tensor(np.asarray(later), dtype=torch.int64)
    if a.shape != b.shape or a.ndim != 3:
        raise ValueError(f"expected two [M, H, W] frame stacks of one shape, got {list(a.shape)}, {list(b.shape)}")
    reach = _checked(reach)
    fa, ma = ground_fields(a, levels)
    fb, mb = ground_fields(b, levels)
    return _best_shift(_spectra(fa, ma, reach), _spectra(fb, mb, reach), a.shape[1:], reach)


def ground_fields(frames: np.ndarray | torch.Tensor, levels: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """What :func:`ground_shift` compares of frames [M, H, W] uint8: the ground's gray levels
    blurred over ground pixels ([M, H, W] float32) and where that blur rests on ground alone
    ([M, H, W] bool)."""
    x = torch.as_tensor(np.asarray(frames), dtype=torch.int64)
    table = torch.from_numpy(level_table(levels))                  # ground levels: True
    return _blur(x.to(torch.float32), table[x.clamp(0, 255)])


def _checked(reach: int) -> int:
    """``reach`` (px) as an int; ValueError under 2 (the sub-pixel step needs a shift each side)."""
    if int(reach) < 2:
        raise ValueError(f"reach must be at least 2 px, got {reach}")
    return int(reach)


def _best_shift(sa: torch.Tensor, sb: torch.Tensor, shape: tuple[int, int], reach: int) -> torch.Tensor:
    """:func:`ground_shift` of two stacks of :func:`_spectra` of (H, W) = ``shape`` frames."""
    m_ = sa.shape[0]
    cost = _shift_costs(sa, sb, int(shape[0]), int(shape[1]), reach)
    rows = torch.arange(m_)
    best = cost.reshape(m_, -1).argmin(1)
    iy, ix = best // cost.shape[2], (best % cost.shape[2]).clamp(1, 2 * reach - 1)
    line = cost[rows, iy]                                           # [M, X]: the best row's costs
    c0, c1, c2 = line[rows, ix - 1], line[rows, ix], line[rows, ix + 1]
    curv = c0 - 2 * c1 + c2
    sub = torch.where(torch.isfinite(curv) & (curv > 0), 0.5 * (c0 - c2) / curv, torch.zeros_like(c1))
    shift = (ix - reach).to(torch.float32) + sub.clamp(-0.5, 0.5)
    finite = line.masked_fill(~torch.isfinite(line), float("nan"))
    contrast = (torch.nanquantile(finite, 0.5, dim=1) - c1) / c1.clamp(min=1.0)
    ok = torch.isfinite(c1) & (contrast >= MIN_CONTRAST)
    return torch.where(ok, shift, torch.full_like(shift, float("nan")))


def clip_speed(frames: np.ndarray, fps: float, levels: np.ndarray | None = None,
               window: int | None = None, reach: int = MAX_DX) -> float | None:
    """The demonstration's mean ground shift (px per ``window`` frames, default
    :func:`clip_window`) over every pair of frames that far apart inside the clip (a looped
    clip's wrap is not crossed), or None when fewer than :data:`MIN_VALID` of them show a
    ground to measure."""
    frames = np.asarray(frames, dtype=np.uint8)
    levels = ground_levels(frames) if levels is None else levels
    k = clip_window(frames, fps, levels, reach) if window is None else int(window)
    if len(frames) <= k or len(levels) == 0:
        return None
    s = ground_shift(frames[:-k], frames[k:], levels, reach)
    valid = torch.isfinite(s)
    if float(valid.float().mean()) < MIN_VALID:
        return None
    return float(s[valid].mean())


def gated(distance_reward, speed_reward, weight: float):
    """A learned reward with the video speed term: the distance model's reward (in [0, 1]) times
    ``1 - weight + weight * speed_reward`` (tensors or arrays alike). Travelling at the video's
    speed keeps the distance reward whole; standing still or going the wrong way takes up to
    ``weight`` of it away. A product rather than a weighted sum: the term pays only as far as the
    motion looks like the video, so another gait that travels cannot outrank the video's own, and
    its say in the ranking does not grow as the distance rewards' range narrows while the
    distance model trains."""
    return distance_reward * ((1.0 - weight) + weight * speed_reward)


class VideoSpeedTerm:
    """A reward for travelling as fast as the demonstration, measured in both videos alike.

    Over a rollout of agent frames it measures the ground's shift across each block of
    ``window`` frames (the demonstration's :func:`clip_window`) of an episode and pays
    ``exp(-((v - v_demo) / sigma)^2)`` per step, ``sigma = max(|v_demo|, 1 px)``: a robot walking
    in place earns exp(-1) of it, one drifting backwards less. Each step gets the measure of the
    latest block of its episode that ended at or before it (causal; the first block's steps get
    none). The last frames and episode ages of every env carry over from one rollout to the next.
    """

    def __init__(self, target: float, fps: float, levels: np.ndarray, num_envs: int, window: int,
                 agent_levels: np.ndarray | None = None, reach: int = MAX_DX) -> None:
        """``levels``: the demonstration's ground levels (:func:`ground_levels`); ``agent_levels``: the
        agent frames' (None: the same; set them later with :meth:`find_agent_ground`); ``reach``
        (px): the shifts searched, the demonstration's :func:`search_reach`."""
        self.target, self.levels = float(target), np.asarray(levels, dtype=np.int64)
        self.agent_levels = self.levels if agent_levels is None else np.asarray(agent_levels, dtype=np.int64)
        self.sigma = max(abs(self.target), 1.0)                  # px per window
        self.fps = float(fps)
        self.k = int(window)                                     # frames: the window the target was measured over
        self.reach = _checked(reach)                             # px
        self.num_envs = int(num_envs)
        self._history: torch.Tensor | None = None                # [k, N, H, W] uint8: the last k frames
        self._age = torch.zeros(self.num_envs, dtype=torch.int64)  # frames of the episode before the next
        self._held = torch.zeros(self.num_envs)                  # px, the latest block's shift
        self._has = torch.zeros(self.num_envs, dtype=torch.bool)

    @classmethod
    def for_demo(cls, frames: np.ndarray, fps: float, num_envs: int,
                 reach: int | None = None) -> "VideoSpeedTerm | None":
        """The term for a demonstration's frames (T, H, W) uint8 at ``fps``: its ground levels, its
        :func:`search_reach` (or ``reach`` px), its :func:`clip_window` and its :func:`clip_speed`
        as the target; None when it shows no patterned ground to measure."""
        levels = ground_levels(frames)
        reach = search_reach(frames, levels) if reach is None else int(reach)
        window = clip_window(frames, fps, levels, reach)
        target = clip_speed(frames, fps, levels, window, reach)
        return None if target is None else cls(target, fps, levels, num_envs, window, reach=reach)

    def find_agent_ground(self, agent: np.ndarray | torch.Tensor) -> np.ndarray:
        """Take the agent's ground levels from its own frames [T, H, W] uint8 (a demonstration whose
        ground looks unlike the env's: a video resampled to the control rate); returns them."""
        self.agent_levels = ground_levels(np.asarray(agent, dtype=np.uint8))
        return self.agent_levels

    def rollout(self, agent: torch.Tensor, dones: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """For frames [T, N, H, W] uint8 and ``dones`` [T, N] (frame t ends its episode): the term's
        reward [T, N] (float32), where it applies [T, N] bool, and the shift each step was given
        (px per window, [T, N], NaN where none)."""
        agent, dones = torch.as_tensor(agent), torch.as_tensor(dones).bool()
        steps, n = dones.shape
        if agent.shape[:2] != (steps, n) or n != self.num_envs:
            raise ValueError(f"frames {list(agent.shape)} and dones {list(dones.shape)} do not fit {self.num_envs} envs")
        if self._history is None:
            self._history = torch.zeros((self.k, n, *agent.shape[2:]), dtype=torch.uint8)
        frames = torch.cat([self._history, agent.to(torch.uint8)])   # rollout step t at index t + k
        age, ends = self._age.clone(), torch.zeros(steps, n, dtype=torch.bool)
        for t in range(steps):                                   # blocks ending at step t
            ends[t] = (age >= self.k) & (age % self.k == 0)
            age = torch.where(dones[t], torch.zeros_like(age), age + 1)
        t_idx, n_idx = ends.nonzero(as_tuple=True)
        shifts = torch.full((steps, n), float("nan"))
        if len(t_idx):                                           # a frame ending one block starts the next:
            ids = torch.cat([t_idx, t_idx + self.k]) * n + torch.cat([n_idx, n_idx])   # blur each frame once
            unique, inverse = torch.unique(ids, return_inverse=True)
            f, m = ground_fields(frames.reshape(-1, *frames.shape[2:])[unique], self.agent_levels)
            spec = _spectra(f, m, self.reach)                 # and transform it once
            a, b = inverse[:len(t_idx)], inverse[len(t_idx):]
            shifts[t_idx, n_idx] = _best_shift(spec[a], spec[b], f.shape[1:], self.reach)
        given = torch.full((steps, n), float("nan"))
        held, has = self._held.clone(), self._has.clone()
        for t in range(steps):
            new = torch.isfinite(shifts[t])
            held, has = torch.where(new, shifts[t], held), has | new
            given[t] = torch.where(has, held, torch.full_like(held, float("nan")))
            has = has & ~dones[t]
        self._held, self._has, self._age = held, has, age
        self._history = frames[-self.k:].clone()
        valid = torch.isfinite(given)
        reward = torch.exp(-((given - self.target) / self.sigma).square()).nan_to_num(0.0)
        return reward.to(torch.float32), valid, given
