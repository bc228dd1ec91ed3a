"""Quality of the learned VIRL distance, trained from scratch on simulator renders (run by hand).

    python bench/distance_quality.py                 # 120 s of training per variant (virl, frame)
    python bench/distance_quality.py --seconds 30 --variants virl

Frames: the robot (default Pupper) plays a motion kinematically in the simulator
(``World.set_pose`` + ``World.render``, the environment's own follow camera and
renderer). Motions come from ``virl_quad.demo`` built-in gaits when available
(``--source demo``), else from joint sinusoids (``--source sine``); ``--source
synthetic`` (moving shapes, no simulator) exists only for development.

Training data, rendered once: the demonstration (trot) and "agent" episodes,
each with its matching demonstration frames (from a random start, as RSI does):
other gaits (pace, bound, pronk), perturbed trot playbacks (joint offsets and
noise, other swing height) and time-shifted trot playbacks (out of phase).
The model trains for ``--seconds`` of wall time per variant, then is measured
on held-out renders (new phases and perturbations; "walk" is never trained on):

1. ranking accuracy P(d(positive pair) < d(negative pair)) per negative type,
   the pairs built from the same held-out anchor (goal >= 0.9 for reversed,
   shuffled and frozen-frame negatives);
2. d(demo, demo warped 0.8x) against d(demo, another gait) (goal: smaller);
3. d(demo, demo shifted by s frames) for s = 0..half a cycle (goal: grows).

A sequence distance is the mean over the window of the per-step reward
distance d_t = ||h^e_t - h^a_t|| + ||e^e_t - e^a_t|| (frame term only for
``frame``), streamed from the window's first frame.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from virl_quad.reward import RewardConfig, build_reward
from virl_quad.reward import pairs

ROBOT = "pupper"
WINDOW = 32  # frames per evaluation window


# -- frame source (swappable) ------------------------------------------------------------------
class SineMotion:
    """Fallback motion: hip/knee sinusoids with per-leg phase offsets and a forward-moving base."""

    OFFSETS = {"trot": (0, .5, .5, 0), "pace": (0, .5, 0, .5), "bound": (0, 0, .5, .5),
               "pronk": (0, 0, 0, 0), "walk": (.75, .25, .5, 0)}

    def __init__(self, spec, gait: str, swing_height: float | None = None) -> None:
        self.spec, self.offsets = spec, np.array(self.OFFSETS[gait])
        self.freq, self.amp = 2.0, 0.35 if swing_height is None else 0.35 * swing_height / 0.03
        self.duration = 1.0 / self.freq

    def pose_at(self, t: float):
        ph = 2 * np.pi * (self.freq * t + self.offsets)
        q = np.array(self.spec.default_pose, dtype=np.float64)
        q[1::3] += self.amp * np.sin(ph)
        q[2::3] += self.amp * np.clip(np.cos(ph), 0, None)
        return np.array([0.25 * t, 0.0, self.spec.spawn_height]), np.array([0.0, 0, 0, 1]), q


class FrameSource:
    """Renders gaits: ``frames(gait, n, t0, speed, ...)`` -> uint8 [n, 48, 48]."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._motions: dict = {}
        if kind == "synthetic":
            self.fps, self.world = 50.0, None
            return
        from virl_quad import robots
        from virl_quad.sim.world import World

        self.spec = robots.get(ROBOT)
        self.fps = self.spec.control_hz
        self.world = World(self.spec)
        self.world.reset()
        if kind == "auto":
            try:
                self.motion("trot", None)
                self.kind = "demo"
            except Exception as exc:  # noqa: BLE001 - report and fall back
                print(f"[frame source] virl_quad.demo unavailable ({type(exc).__name__}: {exc}); using sine")
                self.kind = "sine"

    def motion(self, gait: str, swing_height: float | None):
        key = (gait, swing_height)
        if key not in self._motions:
            if self.kind in ("demo", "auto"):
                from virl_quad.motion.gaits import gait_motion

                kw = {} if swing_height is None else {"swing_height": swing_height}
                self._motions[key] = gait_motion(ROBOT, gait, **kw)
            else:
                self._motions[key] = SineMotion(self.spec, gait, swing_height)
        return self._motions[key]

    def cycle(self, gait: str) -> int:
        """Frames per gait cycle."""
        if self.kind == "synthetic":
            return 25
        return max(1, int(round(self.motion(gait, None).duration * self.fps)))

    def frames(self, gait: str, n: int, t0: float = 0.0, speed: float = 1.0, swing_height: float | None = None,
               q_offset: np.ndarray | None = None, q_noise: float = 0.0, rng=None) -> np.ndarray:
        """``n`` frames of ``gait`` from motion time ``t0`` (s), played ``speed`` times faster."""
        if self.kind == "synthetic":
            return synthetic(gait, n, t0 * self.fps, speed, swing_height)
        m = self.motion(gait, swing_height)
        out = np.empty((n, 48, 48), np.uint8)
        for i in range(n):
            pos, quat, q = m.pose_at(t0 + speed * i / self.fps)
            q = np.array(q, dtype=np.float64)
            if q_offset is not None:
                q = q + q_offset
            if q_noise:
                q = q + rng.normal(0.0, q_noise, 12)
            self.world.set_pose(pos, quat, self.spec.clip_to_limits(q))
            out[i] = self.world.render()
        return out


def synthetic(gait: str, n: int, t0: float, speed: float, swing: float | None) -> np.ndarray:
    """Development-only clips: a disc whose path depends on the gait name."""
    k = {"trot": 0, "pace": 1, "bound": 2, "pronk": 3, "walk": 4}[gait]
    yy, xx = np.mgrid[0:48, 0:48]
    r = 5 + (0 if swing is None else 2)
    out = np.empty((n, 48, 48), np.uint8)
    for i in range(n):
        ph = 2 * np.pi * (t0 + speed * i) / 25
        cx, cy = 24 + 12 * np.sin(ph + k), 24 + 9 * np.cos((1 + k % 2) * ph)
        out[i] = np.where((xx - cx) ** 2 + (yy - cy) ** 2 < r * r, 220, 40)
    return out


# -- data ---------------------------------------------------------------------------------------
def agent_episodes(src: FrameSource, demo: np.ndarray, rng: np.random.Generator, count: int, length: int,
                   gaits: tuple[str, ...]) -> list[tuple[np.ndarray, np.ndarray, str]]:
    """(agent, matching expert, kind) episodes: other gaits, perturbed and time-shifted trot playbacks."""
    cyc, T = src.cycle("trot"), demo.shape[0]
    out = []
    for k in range(count):
        i0 = int(rng.integers(T))                          # RSI: the expert starts at a random frame
        expert = demo[(i0 + np.arange(length)) % T]
        kind = ["gait", "perturbed", "shifted"][k % 3]
        t0 = i0 / src.fps
        if kind == "gait":
            g = gaits[int(rng.integers(len(gaits)))]
            agent = src.frames(g, length, t0=float(rng.uniform(0, 2)))
            kind = g
        elif kind == "perturbed":
            agent = src.frames("trot", length, t0=t0, swing_height=float(rng.choice([0.015, 0.045])),
                               q_offset=rng.normal(0, 0.12, 12), q_noise=0.04, rng=rng)
        else:
            shift = int(rng.integers(3, cyc - 2))
            agent = src.frames("trot", length, t0=t0 + shift / src.fps)
        out.append((agent, expert, kind))
    return out


def seq_distance(rm, a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """Mean-over-time reward distance of each pair (a[k], b[k]) of equal-length windows."""
    A = np.stack(a, axis=1)
    B = np.stack(b, axis=1)
    with torch.no_grad():
        return rm.distance(A, B).mean(0).numpy()


def to_u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x * 255), 0, 255).astype(np.uint8)


def evaluate(rm, src: FrameSource, rng: np.random.Generator, anchors: int) -> dict:
    """All held-out figures for one trained model."""
    cyc = src.cycle("trot")
    L = WINDOW
    # held-out anchors: trot at fractional phases never rendered for training
    t0s = rng.uniform(0, 4, anchors)
    anchor = [src.frames("trot", L + 1, t0=float(t)) for t in t0s]
    xf = [a.astype(np.float32) / 255 for a in anchor]
    pos_makers = {
        "gaussian_noise": lambda x: pairs.gaussian_noise(x, rng, 0.05),
        "out_of_sync": lambda x: pairs.out_of_sync(x, rng),
        "duplicate_first": lambda x: pairs.duplicate_first(x, rng),
    }
    pos = {k: [f(x) for x in xf] for k, f in pos_makers.items()}
    d_pos = {k: seq_distance(rm, [to_u8(p[0]) for p in v], [to_u8(p[1]) for p in v]) for k, v in pos.items()}
    negs = {
        "reversed": [pairs.reversed_order(x, rng) for x in xf],
        "shuffled_one": [pairs.shuffled_one(x, rng) for x in xf],
        "shuffled_both": [pairs.shuffled_both(x, rng) for x in xf],
        "frozen_frame": [pairs.frozen_frame(x, rng) for x in xf],
    }
    d_neg = {k: seq_distance(rm, [to_u8(p[0]) for p in v], [to_u8(p[1]) for p in v]) for k, v in negs.items()}
    base = [a[:L] for a in anchor]
    half = cyc // 2
    d_neg["time_shift_half_cycle"] = seq_distance(
        rm, base, [src.frames("trot", L, t0=float(t) + half / src.fps) for t in t0s])
    d_neg["perturbed_trot"] = seq_distance(rm, base, [src.frames(
        "trot", L, t0=float(t), swing_height=0.045, q_offset=rng.normal(0, 0.12, 12), q_noise=0.04, rng=rng)
        for t in t0s])
    gait_d = {}
    for g in ("pace", "bound", "pronk", "walk"):
        gait_d[g] = seq_distance(rm, base, [src.frames(g, L, t0=float(rng.uniform(0, 2))) for _ in t0s])
        d_neg[f"gait_{g}"] = gait_d[g]
    acc = {n: float(np.mean([(d_pos[p] < dn).mean() for p in d_pos])) for n, dn in d_neg.items()}
    warped = {s: seq_distance(rm, base, [src.frames("trot", L, t0=float(t), speed=s) for t in t0s])
              for s in (0.8, 1.25)}
    shifts = list(range(0, half + 1))
    shift_d = [float(seq_distance(rm, base, [src.frames("trot", L, t0=float(t) + s / src.fps) for t in t0s]).mean())
               for s in shifts]
    return {"d_pos": {k: float(v.mean()) for k, v in d_pos.items()},
            "d_neg": {k: float(v.mean()) for k, v in d_neg.items()}, "acc": acc,
            "warped": {s: float(v.mean()) for s, v in warped.items()},
            "gait": {g: float(v.mean()) for g, v in gait_d.items()}, "shifts": shifts, "shift_d": shift_d}


def train(variant: str, demo: np.ndarray, episodes, seconds: float, seed: int, clips):
    """Build and train a model of ``variant`` for ``seconds`` of wall time; return it with stats."""
    cfg = RewardConfig.make(variant=variant, clips_cyclic=True)
    rm = build_reward(cfg, demo, clips, seed=seed)
    for agent, expert, _ in episodes:
        rm.add_episode(agent, expert)
    t0, n, last = time.perf_counter(), 0, {}
    while time.perf_counter() - t0 < seconds:
        last = rm.update(5)
        n += 5
    return rm, n, time.perf_counter() - t0, last


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=120.0, help="wall-clock training budget per variant (s)")
    ap.add_argument("--variants", default="virl,frame", help="comma-separated variants to train and compare")
    ap.add_argument("--source", default="auto", choices=["auto", "demo", "sine", "synthetic"])
    ap.add_argument("--episodes", type=int, default=90, help="agent episodes in the training set")
    ap.add_argument("--episode-len", type=int, default=100, help="frames per agent episode")
    ap.add_argument("--anchors", type=int, default=48, help="held-out anchor windows")
    ap.add_argument("--clips", action="store_true", help="also give pace/bound/pronk as other_clips")
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads (1: OpenMP stalls badly when the cores are shared)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)

    t = time.perf_counter()
    src = FrameSource(args.source)
    cyc = src.cycle("trot")
    demo = src.frames("trot", cyc * 8)                     # 8 whole cycles: loops seamlessly
    train_gaits = ("pace", "bound", "pronk")
    episodes = agent_episodes(src, demo, rng, args.episodes, args.episode_len, train_gaits)
    clips = [src.frames(g, cyc * 4, t0=0.3) for g in train_gaits] if args.clips else None
    where = "moving shapes, NO simulator: development only" if src.kind == "synthetic" else ROBOT
    print(f"frame source: {src.kind} ({where}, {src.fps:.0f} fps, trot cycle {cyc} frames); demo {demo.shape[0]}"
          f" frames; {len(episodes)} agent episodes x {args.episode_len} frames "
          f"(other gaits {train_gaits}, perturbed trot, time-shifted trot); other_clips: "
          f"{'pace/bound/pronk' if clips else 'none'}; rendered in {time.perf_counter() - t:.1f} s")
    print(f"training budget: {args.seconds:.0f} s wall time per variant, torch threads {args.threads}, "
          f"seed {args.seed}; evaluation: {args.anchors} held-out anchors, windows of {WINDOW} frames")
    results = {}
    for v in args.variants.split(","):
        rm, n, secs, last = train(v, demo, episodes, args.seconds, args.seed, clips)
        losses = ", ".join(f"{k} {x:.4f}" for k, x in last.items() if k not in ("window", "grad_norm"))
        print(f"[{v}] {n} updates in {secs:.0f} s ({1000 * secs / max(n, 1):.0f} ms/update); last losses: {losses}")
        results[v] = evaluate(rm, src, np.random.default_rng(args.seed + 1), args.anchors)

    names = list(results)
    print("\n1. ranking accuracy P(d(positive pair) < d(negative pair)), held-out anchors")
    print(f"   {'negative type':24s}" + "".join(f"{n:>10s}" for n in names)
          + "".join(f"{'d ' + n:>10s}" for n in names) + "   (d: mean distance of the negative pairs)")
    for k in results[names[0]]["acc"]:
        goal = "  (goal >= 0.9)" if k in ("reversed", "shuffled_one", "shuffled_both", "frozen_frame") else ""
        print(f"   {k:24s}" + "".join(f"{results[n]['acc'][k]:10.3f}" for n in names)
              + "".join(f"{results[n]['d_neg'][k]:10.3f}" for n in names) + goal)
    print("   mean d of positives: " + "; ".join(
        f"{n}: " + ", ".join(f"{k} {v:.3f}" for k, v in results[n]["d_pos"].items()) for n in names))
    print("\n2. mean d(demo, X)")
    print(f"   {'X':24s}" + "".join(f"{n:>10s}" for n in names))
    rows = [("warped 0.8x", lambda r: r["warped"][0.8]), ("warped 1.25x", lambda r: r["warped"][1.25])]
    rows += [(f"gait {g}" + (" (held out)" if g == "walk" else ""), lambda r, g=g: r["gait"][g])
             for g in ("pace", "bound", "pronk", "walk")]
    for label, f in rows:
        print(f"   {label:24s}" + "".join(f"{f(results[n]):10.3f}" for n in names))
    for n in names:
        r = results[n]
        ok = r["warped"][0.8] < min(r["gait"].values())
        print(f"   [{n}] d(demo, warped 0.8x) < d(demo, every other gait): {'yes' if ok else 'NO'}")
    print("\n3. mean d(demo, demo shifted by s frames)")
    print(f"   {'s':>4s}" + "".join(f"{n:>10s}" for n in names))
    for i, s in enumerate(results[names[0]]["shifts"]):
        print(f"   {s:4d}" + "".join(f"{results[n]['shift_d'][i]:10.3f}" for n in names))
    for n in names:
        d = np.array(results[n]["shift_d"])
        rho = np.corrcoef(np.arange(len(d)), d)[0, 1]
        print(f"   [{n}] increasing steps: {int((np.diff(d) > 0).sum())}/{len(d) - 1}, "
              f"correlation with shift {rho:.2f}, d(half cycle)/d(1 frame) = {d[-1] / max(d[1], 1e-9):.1f}")


if __name__ == "__main__":
    main()
