"""The trajectory generator's parameters for a demonstration: the gait prior a policy starts from.

:func:`fit_tg` fits :class:`~virl_quad.policy.tg.TGParams` by least squares to the feet of a
reference motion in the body frame (forward kinematics with Pinocchio): the frequency is the
motion's gait frequency (a whole number of cycles per loop of a looping clip), the per-leg
phase offsets and the duty factor come from the foot heights, and step length, swing height,
stance height and the feet's neutral positions from the trajectories; the report gives the
fit's RMS foot error (m). :func:`gait_tg` converts a built-in gait
(:mod:`virl_quad.motion.gaits`) exactly. :func:`tg_for_demo` picks: the fit when the
demonstration has a reference motion, else the built-in gait of its name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from virl_quad.motion.gaits import GAIT_NAMES, GaitParams, cycle_steps, gait_params
from virl_quad.policy.tg import BOUNDS, TGParams, TrajectoryGenerator, foot_positions
from virl_quad.robots.spec import RobotSpec

SAMPLES = 200          # body-frame foot samples of a sampled (non-keyframed) motion
GAIT_BAND = (0.5, 5.0)  # Hz, where the gait frequency is looked for
OFFSET_GRID = 100      # candidate phase offsets per leg for the initial guess


def gait_tg(spec: RobotSpec, gait: GaitParams) -> TGParams:
    """The TG of a built-in gait: the same feet relative to the body (frequency rounded to whole
    control steps per cycle, as :func:`virl_quad.motion.gaits.gait_motion` renders it; the base's
    bob and pitch oscillations of a pronk or bound are not part of a TG)."""
    frequency = spec.control_hz / cycle_steps(spec, gait.frequency)
    hip_z = float(np.mean(np.asarray(spec.leg.abduction_origin)[:, 2]))
    return TGParams(frequency=frequency, offsets=tuple(float(o) % 1.0 for o in gait.offsets), duty=gait.duty,
                    step_length=gait.speed * gait.duty / frequency, swing_height=gait.swing_height,
                    stance_height=hip_z + gait.height - spec.foot_radius)


def _body_feet(motion, spec: RobotSpec) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and base-frame feet (T, 4, 3) m over one pass of the motion (a loop's last
    keyframe, which repeats its first, left out)."""
    from virl_quad.kinematics import Kinematics

    kin = Kinematics(spec, floating_base=False)
    if hasattr(motion, "q") and hasattr(motion, "frame_times"):          # keyframes: exact, no interpolation
        times, q = np.asarray(motion.frame_times), np.asarray(motion.q)
        if motion.loop:
            times, q = times[:-1], q[:-1]
    else:
        n = SAMPLES
        times = np.arange(n) * motion.duration / (n if motion.loop else n - 1)
        q = np.array([motion.state_at(float(t)).q for t in times])
    return times, kin.foot_positions_batch(q)


def _frequency(times: np.ndarray, feet: np.ndarray) -> float:
    """Hz: the strongest frequency in :data:`GAIT_BAND` of the feet's height and fore-aft motion,
    a whole number of cycles over the samples' span (for a looping clip: per loop)."""
    sig = feet[:, :, [0, 2]].reshape(len(times), -1)
    sig = sig - sig.mean(axis=0)
    power = (np.abs(np.fft.rfft(sig, axis=0)) ** 2).sum(axis=1)
    span = len(times) * (times[1] - times[0])                                  # s
    k = np.arange(len(power))
    band = (k >= max(1.0, GAIT_BAND[0] * span)) & (k <= GAIT_BAND[1] * span)
    if not band.any():
        raise ValueError(f"the motion ({span:.2f} s) is too short or too coarse for a gait between "
                         f"{GAIT_BAND[0]} and {GAIT_BAND[1]} Hz")
    return float(k[band][np.argmax(power[band])] / span)


def _initial(times: np.ndarray, feet: np.ndarray, frequency: float, hip_z: np.ndarray) -> np.ndarray:
    """Starting point [offsets (4), duty, step length, swing height, stance height, neutral x (4)]."""
    z = feet[:, :, 2]
    ground = np.percentile(z, 10, axis=0)                                       # m, stance height per leg
    lift = np.maximum(z.max(axis=0) - ground, 1e-4)                             # m
    contact = z < ground[None] + 0.2 * lift[None]
    duty = float(np.clip(contact.mean(), *BOUNDS["duty"][:2]))
    phase = (times * frequency) % 1.0
    grid = np.arange(OFFSET_GRID) / OFFSET_GRID
    offsets = np.empty(4)
    for leg in range(4):                                                        # best match of the contact pattern
        leg_phase = (phase[:, None] + grid[None]) % 1.0
        score = ((leg_phase < duty) == contact[:, leg, None]).mean(axis=0)
        offsets[leg] = grid[int(np.argmax(score))]
    x = feet[:, :, 0]
    step = float(np.mean([np.ptp(x[contact[:, leg], leg]) if contact[:, leg].any() else 0.0 for leg in range(4)]))
    neutral_x = np.array([x[contact[:, leg], leg].mean() if contact[:, leg].any() else x[:, leg].mean()
                          for leg in range(4)])
    return np.concatenate([offsets, [duty, step, float(lift.mean()), float(np.mean(hip_z - ground))], neutral_x])


def _params(v: np.ndarray, frequency: float, neutral_y: np.ndarray) -> TGParams:
    return TGParams(frequency=frequency, offsets=tuple(float(o) % 1.0 for o in v[:4]), duty=float(v[4]),
                    step_length=float(v[5]), swing_height=float(v[6]), stance_height=float(v[7]),
                    neutral_xy=tuple((float(x), float(y)) for x, y in zip(v[8:12], neutral_y)))


def fit_tg(motion, spec: RobotSpec) -> tuple[TGParams, dict]:
    """Least-squares TG parameters for a reference motion (anything with ``duration``, ``loop``
    and ``state_at``; a :class:`~virl_quad.motion.motion.Motion`'s keyframes are used directly).

    Returns ``(params, report)``; the report holds ``rms_m`` and ``max_m`` (foot error of the
    fit over the samples, m), ``frequency_hz``, ``cycles`` (gait cycles per pass of the motion)
    and ``samples``. ValueError when the motion is too short or the fitted TG out of reach."""
    times, feet = _body_feet(motion, spec)
    if len(times) < 8:
        raise ValueError(f"a TG fit needs at least 8 samples of the motion, got {len(times)}")
    frequency = _frequency(times, feet)
    hip_z = np.asarray(spec.leg.abduction_origin)[:, 2]
    neutral_y = feet[:, :, 1].mean(axis=0)
    free_f = not motion.loop            # a looping clip holds whole cycles; a clip's frequency is fitted too

    def residual(v: np.ndarray) -> np.ndarray:
        xy = np.stack([v[8:12], neutral_y], axis=1)
        phase = (times * (v[12] if free_f else frequency))[:, None]
        model = foot_positions(phase, v[:4], v[4], v[5], v[6], xy, hip_z - v[7])
        return (model - feet).reshape(-1)

    v0 = np.concatenate([_initial(times, feet, frequency, hip_z), [frequency] if free_f else []])
    lo = np.array([-1.0] * 4 + [BOUNDS["duty"][0], 0.0, 0.0, 1e-3] + [-2.0] * 4 + [GAIT_BAND[0]] * free_f)
    hi = np.array([2.0] * 4 + [BOUNDS["duty"][1], 1.0, 0.5, 2.0] + [2.0] * 4 + [GAIT_BAND[1]] * free_f)
    fit = least_squares(residual, np.clip(v0, lo, hi), bounds=(lo, hi), x_scale="jac", xtol=1e-12, ftol=1e-12)
    x = fit.x.copy()
    x[:4] = np.mod(x[:4], 1.0)
    snapped = x.copy()                      # offsets and duty to 1e-3 when that fits as well (within 1 µm)
    snapped[:5] = np.round(snapped[:5], 3)
    snapped[:4] = np.mod(snapped[:4], 1.0)
    rms = float(np.sqrt(np.mean(fit.fun ** 2)))
    if np.sqrt(np.mean(residual(snapped) ** 2)) <= rms + 1e-6:
        x = snapped
    err = np.linalg.norm(residual(x).reshape(len(times), 4, 3), axis=-1)
    frequency = float(x[12]) if free_f else frequency
    params = _params(x[:12], frequency, neutral_y)
    TrajectoryGenerator(spec, params)                                       # reach and joint limits
    report = {"rms_m": float(np.sqrt(np.mean(err ** 2))), "max_m": float(err.max()), "frequency_hz": float(frequency),
              "cycles": float(frequency * motion.duration), "samples": int(len(times))}
    return params, report


def tg_for_demo(demo, spec: RobotSpec, source: str) -> tuple[TGParams, str]:
    """The TG for a demonstration: fitted to its reference motion when it has one, else the
    built-in gait named like ``source`` (``trot``, ``gait:pace``, ``.../pace.npz``). Returns
    ``(params, one-line description of where it came from and how well it fits)``; ValueError
    when neither exists."""
    motion = getattr(demo, "motion", None)
    if motion is not None:
        params, r = fit_tg(motion, spec)
        return params, (f"fitted to the reference motion: {r['frequency_hz']:.3f} Hz, offsets "
                        f"{[round(o, 3) for o in params.offsets]}, duty {params.duty:.2f}, step "
                        f"{params.step_length * 100:.1f} cm, swing {params.swing_height * 100:.1f} cm, stance "
                        f"{params.stance_height * 100:.1f} cm; RMS foot error {r['rms_m'] * 1000:.2f} mm")
    name = Path(str(source)).stem.removeprefix("gait:")
    if name not in GAIT_NAMES:
        raise ValueError(f"demonstration {source!r} has no reference motion and no built-in gait is named "
                         f"{name!r} ({', '.join(GAIT_NAMES)}): no trajectory generator for it")
    params = gait_tg(spec, gait_params(spec.name, name))
    return params, f"the built-in {name} of {spec.name} (no reference motion to fit)"
