"""The gait prior from the video alone: analysis by synthesis.

The trajectory generator (:mod:`virl_quad.policy.tg`) whose kinematic rendering looks most
like the demonstration video, found without the demonstration's reference motion:

0. **Silhouettes** (:func:`silhouettes`): the flat background (the gray levels that fill the
   top and bottom rows: sky and ground) is painted white. The follow camera sees the ground
   scroll by at the robot's speed, a second period (a checker square per 0.5 s at 0.25 m/s)
   that has nothing to do with the legs; a TG cannot say where along the ground it is. A
   ground with no flat levels (a video resampled to the control rate blends each checker
   square's edge between frames into many levels) keeps only the pixels darker than the
   ground's darkest level, in the video and the candidates alike.
1. **Period** (:func:`gait_period`): the lag, within the gait band, at which the video's
   silhouettes are most alike (self-similarity). Half a trot or pace cycle looks almost
   like a whole one from the side (near and far legs swap), so the search tries the
   period found and twice it.
2. **Candidates**: TG parameters rendered with no physics by the env's own camera (the base
   moving forward at the TG's stance speed, at the height where stance feet touch the
   ground; :mod:`virl_quad.training.synthesis`, each stage's candidates on every core at
   once), as silhouettes, compared with the video's at the best time shift (the global
   phase is unknown: leg FR stays at phase 0 and the shift finds the rest) by the mean
   absolute gray difference. That distance is graded, a near miss nearer than a far one,
   which a contrastive distance model is not: it pushes every pair that differs beyond its
   margin, so near misses and far ones come out alike (docs/experiments.md).
3. **Search**: every phase pattern on a grid of quarter cycles at both periods, then the
   duty factor of the best patterns, then speed and swing height, then each leg's offset
   in eighths.

**The video's body** (:func:`video_body`): a video of another robot (a Laikago's trot for a
Pupper to learn) is further from every candidate drawn on the learner's body than two gaits
drawn on one body are from each other: bodies differ in size, colour and leg shape. So the
candidates are drawn on the body of the registered robots whose built-in trot, rendered by its
own camera, looks most like the video, and the fitted gait is carried over to the learner
(:func:`transfer`): the same frequency, phase pattern and duty factor, step length and swing
height scaled by the ratio of leg lengths (as the motion retargeting scales a clip).

:func:`fit_tg_to_video` returns the nearest candidates (the finalists, as
:class:`~virl_quad.policy.tg.TGParams`: the fit first, the others for
:mod:`virl_quad.training.prior_check`), the report (period, distance, candidates tried) and
each finalist's silhouettes aligned with the video's, for a contact sheet (:func:`save_fit_sheet`).
"""

from __future__ import annotations

import itertools
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from virl_quad.policy.legs import leg_length
from virl_quad.policy.tg import TGParams
from virl_quad.reward.frames import dark_level
from virl_quad.robots.spec import RobotSpec
from virl_quad.training.prior_check import describe_variant
from virl_quad.training.synthesis import RenderPool

GAIT_BAND = (0.5, 5.0)      # Hz, where the gait frequency is looked for
MIN_PERIODICITY = 0.3       # below this the video shows no periodic motion (1: exactly periodic)
MIN_MOTION = 1e-4           # mean squared frame change (intensity in [0, 1]) below which a video is still


@dataclass(frozen=True)
class VideoFitConfig:
    """How hard :func:`fit_tg_to_video` searches (the defaults: 295 kinematic renders)."""

    grid_duties: tuple[float, ...] = (0.3, 0.6)          # duty factors of the phase-pattern grid
    duties: tuple[float, ...] = (0.25, 0.4, 0.5, 0.6, 0.75)   # duty factors tried for the best patterns
    speed_scales: tuple[float, ...] = (0.5, 0.75, 1.0, 1.5, 2.0, 2.5)   # x the robot's built-in trot speed
    swing_scales: tuple[float, ...] = (0.5, 1.0, 1.5)    # x the built-in trot's swing height
    top_patterns: int = 4                                # patterns carried from the grid to the duty search
    finalists: int = 4                                   # best candidates: in the report; the physics check
                                                         # (virl_quad.training.prior_check) tries them in turn


def silhouettes(frames: np.ndarray, video: np.ndarray | None = None) -> np.ndarray:
    """Frames (T, H, W) uint8 as silhouettes, by the rule ``video``'s background calls for (None:
    the frames' own): on a flat background, its gray levels painted white
    (:func:`virl_quad.reward.frames.background_levels`; the same for a video and a render on
    another ground); on a textured one (:func:`dark_level`), black where a pixel is darker than
    the ground's darkest level and white elsewhere (a robot darker than its ground)."""
    return _silhouettes(frames, dark_level(frames if video is None else video))


def _silhouettes(frames: np.ndarray, level: int | None) -> np.ndarray:
    """:func:`silhouettes` with the video's :func:`dark_level` found once by the caller."""
    from virl_quad.reward.frames import background_levels, paint

    if level is None:
        return paint(frames, background_levels(frames))
    return np.where(np.asarray(frames) < level, 0, 255).astype(np.uint8)


def gait_period(frames: np.ndarray, fps: float) -> tuple[float, float]:
    """(period in frames, periodicity in [0, 1]) of a video (T, H, W) uint8 at ``fps`` (Hz).

    The period is the lag in :data:`GAIT_BAND` with the smallest mean squared frame difference
    (the first lag within 10 % of the smallest, so not a multiple), refined to a fraction of a
    frame by a parabola; periodicity is 1 minus that difference over twice the frames' variance
    (0: no better than unrelated frames). ValueError for a still or too short video."""
    x = np.asarray(frames, dtype=np.float32) / 255.0
    x = x.reshape(len(x), -1)
    x = x - x.mean(axis=0)
    lo = max(2, int(math.floor(fps / GAIT_BAND[1])))
    hi = min(len(x) // 2, int(math.ceil(fps / GAIT_BAND[0])))
    if hi < lo + 2:
        raise ValueError(f"the video ({len(x)} frames at {fps:g} fps) is too short to find a gait period: "
                         f"it needs two cycles of at least {1 / GAIT_BAND[1]:.1f} s")
    var = float(np.mean(x ** 2))
    if var < MIN_MOTION:
        raise ValueError("the video is a still image: no motion to fit a gait to")
    lags = np.arange(lo, hi + 1)
    diff = np.array([np.mean((x[k:] - x[:-k]) ** 2) for k in lags])
    best = float(diff.min())
    i = int(np.argmax(diff <= best + 0.1 * (np.median(diff) - best)))
    while i + 1 < len(diff) and diff[i + 1] < diff[i]:          # to the bottom of that dip
        i += 1
    while i > 0 and diff[i - 1] < diff[i]:
        i -= 1
    period = float(lags[i])
    if 0 < i < len(diff) - 1:                                    # parabola through the dip
        a, b, c = diff[i - 1], diff[i], diff[i + 1]
        den = a - 2 * b + c
        if den > 0:
            period += float(0.5 * (a - c) / den)
    return period, float(max(0.0, 1.0 - diff[i] / (2.0 * var)))


def template(spec: RobotSpec) -> TGParams:
    """The starting TG: the robot's built-in trot (stance height, swing height, speed)."""
    from virl_quad.motion.gaits import gait_params
    from virl_quad.training.prior import gait_tg

    return gait_tg(spec, gait_params(spec.name, "trot"))


def candidate(base: TGParams, frequency: float, offsets, duty: float, speed: float, swing: float) -> TGParams:
    """``base`` at another frequency (Hz), leg offsets, duty, forward speed (m/s) and swing height (m)."""
    return replace(base, frequency=frequency, offsets=tuple(float(o) % 1.0 for o in offsets), duty=duty,
                   step_length=speed * duty / frequency, swing_height=swing)


def relative_offsets(offsets) -> tuple[float, ...]:
    """Leg offsets relative to leg FR (cycles in [0, 1)): the phase pattern without its global phase."""
    o = np.asarray(offsets, dtype=np.float64)
    return tuple(float(v) for v in np.mod(o - o[0], 1.0))


def transfer(params: TGParams, body: RobotSpec, spec: RobotSpec) -> TGParams:
    """A TG fitted on ``body`` carried over to ``spec``: frequency (Hz), phase pattern and duty
    kept, step length and swing height (m) scaled by the leg-length ratio, stance height and
    neutral feet of ``spec``'s built-in trot. ``params`` itself when the two are one robot."""
    if body.name == spec.name:
        return params
    k = leg_length(spec) / leg_length(body)
    return replace(template(spec), frequency=params.frequency, offsets=params.offsets, duty=params.duty,
                   step_length=params.step_length * k, swing_height=params.swing_height * k)


def video_body(video: np.ndarray, fps: float, bodies: list[RobotSpec]) -> tuple[RobotSpec, dict[str, float]]:
    """The body among ``bodies`` whose built-in trot, rendered kinematically by its own camera at
    ``fps`` (Hz), is nearest a video (T, 48, 48) uint8, both as silhouettes by the video's rule;
    returns it and each body's distance (gray levels / 255, at the best time shift over one trot
    cycle)."""
    level = dark_level(video)
    target = torch.from_numpy(_silhouettes(video, level)).float() / 255.0
    costs: dict[str, float] = {}
    for body in bodies:
        base = template(body)
        shifts = int(math.ceil(fps / base.frequency))
        with RenderPool(body, 1, fps) as pool:
            raw = pool.render_many([base], len(target) + shifts)[0]
        f = torch.from_numpy(_silhouettes(raw, level)).float() / 255.0
        costs[body.name] = float(min((target - f[s:s + len(target)]).abs().mean() for s in range(shifts)))
    return min(bodies, key=lambda b: costs[b.name]), costs


def same_pattern(a, b, tolerance: float = 0.125) -> bool:
    """Whether two leg-offset sets are the same phase pattern (each leg within ``tolerance`` cycles
    relative to leg FR)."""
    d = np.mod(np.asarray(relative_offsets(a)) - np.asarray(relative_offsets(b)) + 0.5, 1.0) - 0.5
    return bool(np.all(np.abs(d) <= tolerance + 1e-9))


class _Scorer:
    """Distance of candidate renders to a video (T, 48, 48) uint8, both as silhouettes by the
    video's rule: the mean absolute difference (gray levels / 255) at the best time shift."""

    def __init__(self, video: np.ndarray, renders: RenderPool, shifts: int) -> None:
        self.renders, self.shifts, self.level = renders, shifts, dark_level(video)
        self.video = _silhouettes(video, self.level)
        self.video_f = torch.from_numpy(self.video).float() / 255.0
        self.cache: dict[TGParams, tuple[float, int, np.ndarray | None]] = {}

    def prefetch(self, candidates: list[TGParams]) -> None:
        """Render and score the candidates not scored yet, all at once (on the pool's processes)."""
        todo = list(dict.fromkeys(p for p in candidates if p not in self.cache))
        n = len(self.video)
        for params, raw in zip(todo, self.renders.render_many(todo, n + self.shifts)):
            if raw is None:
                self.cache[params] = (math.inf, 0, None)
                continue
            frames = _silhouettes(raw, self.level)
            f = torch.from_numpy(frames).float() / 255.0
            costs = torch.stack([(self.video_f - f[s:s + n]).abs().mean() for s in range(self.shifts)])
            s = int(torch.argmin(costs))
            self.cache[params] = (float(costs[s]), s, frames)

    def cost(self, params: TGParams) -> tuple[float, int, np.ndarray | None]:
        """(distance at the best shift, that shift in frames, the render) of a candidate; inf
        for one out of reach."""
        self.prefetch([params])
        return self.cache[params]


def _search(scorer: _Scorer, base: TGParams, periods: list[float], fps: float, cfg: VideoFitConfig) -> list[TGParams]:
    """The search of the module doc; returns the finalists, best frame cost first."""
    cost = lambda p: scorer.cost(p)[0]
    speed0 = base.step_length * base.frequency / base.duty                         # m/s
    grid = [(0.0,) + o for o in itertools.product((0.0, 0.25, 0.5, 0.75), repeat=3)]
    pool = [candidate(base, fps / p, o, d, speed0, base.swing_height)
            for p in periods for o in grid for d in cfg.grid_duties]
    scorer.prefetch(pool)
    pool.sort(key=cost)
    best_patterns = pool[:cfg.top_patterns]
    pool = [candidate(p, p.frequency, p.offsets, d, speed0, base.swing_height) for p in best_patterns for d in cfg.duties]
    scorer.prefetch(pool)
    pool = sorted(pool, key=cost)
    best = pool[0]
    sized = [candidate(best, best.frequency, best.offsets, best.duty, speed0 * v, base.swing_height * w)
             for v in cfg.speed_scales for w in cfg.swing_scales]
    scorer.prefetch(sized)
    best = min(sized, key=cost)
    for _ in range(2):                                                             # each leg's offset in eighths
        for leg in (1, 2, 3):
            trial = []
            for step in (-0.125, 0.0, 0.125):
                o = list(best.offsets)
                o[leg] = (o[leg] + step) % 1.0
                trial.append(replace(best, offsets=tuple(o)))
            scorer.prefetch(trial)
            best = min(trial, key=cost)
    ranked = sorted(set(pool + sized + [best]), key=cost)
    return ranked[:cfg.finalists]


def fit_tg_to_video(frames: np.ndarray, fps: float, spec: RobotSpec, cfg: VideoFitConfig = VideoFitConfig(),
                    log: Callable[[str], None] | None = None, workers: int | None = None,
                    bodies: list[RobotSpec] | None = None) -> tuple[TGParams, dict, np.ndarray]:
    """Fit TG parameters for robot ``spec`` to a demonstration video (T, 48, 48) uint8 at ``fps``
    (Hz), the robot's control rate. The candidates are drawn on the body among ``bodies`` that
    the video shows (:func:`video_body`; None: ``spec``'s own) and carried over to ``spec``
    (:func:`transfer`); they are rendered on ``workers`` processes (None: one per CPU core; the
    fit is the same for any number).

    Returns ``(finalists, report, fitted)``: the best candidates' parameters, nearest first (the
    fit: ``finalists[0]``), the report, and each finalist's silhouettes (F, T, 48, 48) aligned with
    the video's. The report holds ``period_frames``, ``periodicity``, ``body`` (the robot the
    candidates were drawn on) and ``body_distances`` (each body's, with ``bodies``), ``distance``
    (of the nearest, gray levels / 255), ``candidates`` (renders made), ``seconds`` and
    ``finalists`` (each one's figures for ``spec`` and its parameters as ``tg``:
    :meth:`TGParams.to_dict`). ValueError
    (one line) for a still video, one with no periodic motion, or one too short for two cycles."""
    t0 = time.time()
    raw = np.asarray(frames, dtype=np.float32) / 255.0
    if len(raw) > 1 and float(np.mean((raw[1:] - raw[:-1]) ** 2)) < MIN_MOTION:   # before painting, which
        raise ValueError("the video is a still image: no motion to fit a gait to")  # turns codec noise into flicker
    video = np.asarray(frames, dtype=np.uint8)
    frames = silhouettes(video)
    if abs(fps - spec.control_hz) > 1e-6:
        raise ValueError(f"the video runs at {fps:g} fps, not {spec.name}'s control rate {spec.control_hz:g} Hz")
    period, periodicity = gait_period(frames, fps)
    if periodicity < MIN_PERIODICITY:
        raise ValueError(f"the video shows no periodic motion (periodicity {periodicity:.2f} < {MIN_PERIODICITY}): "
                         "no gait to fit")
    periods = [period] + ([2 * period] if fps / (2 * period) >= GAIT_BAND[0] else [])
    if log:
        log(f"  prior fit: period {period:.2f} frames ({fps / period:.2f} Hz), periodicity {periodicity:.2f}; "
            f"trying {', '.join(f'{fps / p:.2f}' for p in periods)} Hz")
    body, body_costs = spec, {}
    if bodies and len(bodies) > 1:
        body, body_costs = video_body(video, fps, bodies)
        if log:
            log(f"  prior fit: the video shows a {body.name} body (built-in trots "
                + ", ".join(f"{n} {c * 255:.1f}" for n, c in body_costs.items()) + " gray levels apart)")
    with RenderPool(body, workers, fps) as renders:
        scorer = _Scorer(video, renders, int(math.ceil(max(periods))))
        drawn = _search(scorer, template(body), periods, fps, cfg)
    costs = [scorer.cost(p) for p in drawn]                                      # cached: no new renders
    finalists = [transfer(p, body, spec) for p in drawn]
    report = {"period_frames": period, "periodicity": periodicity, "body": body.name,
              "body_distances": body_costs, "transferred": body.name != spec.name, "distance": costs[0][0],
              "candidates": len(scorer.cache), "seconds": time.time() - t0,
              "finalists": [{"offsets": list(relative_offsets(p.offsets)), "frequency_hz": p.frequency, "duty": p.duty,
                             "step_length_m": p.step_length, "swing_height_m": p.swing_height,
                             "distance": c[0], "tg": p.to_dict()} for p, c in zip(finalists, costs)]}
    return finalists, report, np.stack([render[shift:shift + len(frames)] for _, shift, render in costs])


def describe(params: TGParams, report: dict) -> str:
    """One line: the fitted TG and how close its rendering is to the video."""
    return (f"fitted to the video: {params.frequency:.2f} Hz, offsets (FR, FL, RR, RL) "
            f"{[round(o, 3) for o in relative_offsets(params.offsets)]}, duty {params.duty:.2f}, step "
            f"{params.step_length * 100:.1f} cm, swing {params.swing_height * 100:.1f} cm; silhouettes "
            f"{report['distance'] * 255:.2f} gray levels apart ({report['candidates']} candidates, "
            f"{report['seconds']:.0f} s)"
            + (f"; drawn on the {report['body']} body the video shows, carried over by leg length"
               if report.get("transferred") else "")
            + (f"; finalist {report['kept_finalist']}: the nearer ones' trackers fell in more than half their "
               "episodes" if report.get("kept_finalist") else "")
            + (f"; slowed to {report['slowed_to_mps']:.2f} m/s: at the video's speed its tracker fell in more than "
               "half its episodes" if report.get("slowed_to_mps") else "")
            + (f"; {describe_variant(report['variant'])}: its tracker travels further the way the video's "
               "ground slides" if report.get("variant") else ""))


def save_fit_sheet(video: np.ndarray, fitted: np.ndarray, path: str | os.PathLike, fps: float = 0.0,
                   title: str = "video | fitted gait") -> Path:
    """A PNG contact sheet of video | fitted gait, frame by frame, side by side (16 frames)."""
    import cv2

    from virl_quad.demo.sheet import contact_sheet

    pairs = np.concatenate([np.asarray(video, np.uint8), np.full((len(video), 48, 2), 255, np.uint8),
                            np.asarray(fitted, np.uint8)], axis=2)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), contact_sheet(pairs, columns=4, max_frames=16, fps=fps, title=title)):
        raise ValueError(f"cannot write {path}")
    return path
