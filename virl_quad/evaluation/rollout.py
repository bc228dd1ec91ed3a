"""Episodes of a policy in the env, recorded and scored with the ground truth.

``evaluate(policy, robot, demo, episodes=...)``: the figures every evaluation reports (score terms,
total at the aligned and the best phase, survival, falls, forward-speed ratio).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from virl_quad import robots
from virl_quad.evaluation.score import TERMS, Trajectory, score_trajectory


def record_episode(env, policy: Callable[[dict], np.ndarray], obs: dict,
                   frames: list | None = None) -> tuple[Trajectory, np.ndarray, bool]:
    """Run one episode of ``env`` (a ``virl_quad.envs`` env) from its first observation ``obs``
    with ``policy`` (obs -> action); its trajectory, demonstration times (s) and whether it fell.
    ``frames``: a list to append ``env.render()`` previews to."""
    u = env.unwrapped
    rows, times, feet = [], [], []

    def grab() -> None:
        """Append the current state, feet, demo time (and preview frame)."""
        s = u.state
        rows.append((s.base_pos, s.base_quat, s.q, s.dq, s.base_lin_vel, s.base_ang_vel))
        feet.append(u.world.foot_positions())
        times.append(u.demo_step / u.demo.fps)
        if frames is not None:
            frames.append(env.render())

    grab()
    fell = False
    while True:
        obs, _, terminated, truncated, _ = env.step(np.asarray(policy(obs), dtype=np.float64))
        grab()
        if terminated or truncated:
            fell = bool(terminated)
            break
    cols = list(zip(*rows))
    traj = Trajectory(root_pos=np.array(cols[0]), root_quat=np.array(cols[1]), q=np.array(cols[2]),
                      dq=np.array(cols[3]), root_lin_vel=np.array(cols[4]), root_ang_vel=np.array(cols[5]),
                      feet=np.array(feet))
    return traj, np.array(times), fell


def evaluate(policy: Callable[[dict], np.ndarray], robot: str, demo, episodes: int = 5, seed: int = 0,
             episode_seconds: float = 10.0, randomize: bool = True, video: str | None = None,
             trajectories: list | None = None, **env_overrides) -> dict:
    """Score ``policy`` (obs dict -> 12 actions) over ``episodes`` seeded episodes of ``demo`` on ``robot``.

    Uses ``virl_quad.envs.make(robot, demo=demo, randomize=..., episode_seconds=...)`` (RSI included).
    Returns the mean term rewards, ``total``, ``total_best_offset``, ``best_offset`` (s),
    ``survival_fraction`` (mean share of the episode lived before a fall), ``falls``,
    ``speed_ratio`` (forward travel along the reference's direction over the reference's;
    nan for a motion in place) and ``episodes`` (per-episode figures). ``video``: an ``.mp4``
    of the first episode. ``trajectories``: a list to append each episode's ``(Trajectory,
    demonstration times)`` to, for scoring against other references.
    """
    from virl_quad import envs
    from virl_quad.kinematics import Kinematics

    motion = getattr(demo, "motion", None)
    if motion is None:
        raise ValueError("the demonstration has no reference motion: the ground-truth score needs one")
    env = envs.make(robot, demo=demo, randomize=randomize, episode_seconds=episode_seconds, **env_overrides)
    kin = Kinematics(robots.get(robot))
    per_episode, weights = [], []
    travel, ref_travel = 0.0, 0.0
    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=seed + ep)
            frames = [] if (video is not None and ep == 0) else None
            traj, times, fell = record_episode(env, policy, obs, frames)
            if trajectories is not None:
                trajectories.append((traj, times))
            res = score_trajectory(traj, motion, times, robot, kin=kin)
            res.pop("per_step")
            steps = len(traj) - 1
            res.update(steps=steps, fell=fell, survival=steps / env.unwrapped.max_steps)
            ref0, ref1 = motion.state_at(times[0]).root_pos, motion.state_at(times[-1]).root_pos
            d_ref = (ref1 - ref0)[:2]
            if np.linalg.norm(d_ref) > 1e-9:
                direction = d_ref / np.linalg.norm(d_ref)
                travel += float((traj.root_pos[-1, :2] - traj.root_pos[0, :2]) @ direction)
                ref_travel += float(np.linalg.norm(d_ref))
            per_episode.append(res)
            weights.append(len(traj))
            if frames:
                from virl_quad.demo.render import write_mp4

                write_mp4(np.array(frames), env.unwrapped.robot.control_hz, video)
    finally:
        env.close()
    w = np.array(weights, dtype=np.float64)
    keys = list(TERMS) + ["total", "total_best_offset"]
    out = {k: float(np.average([r[k] for r in per_episode], weights=w)) for k in keys}
    duration = float(np.sum(w - 1)) / float(demo.fps)
    out["best_offset"] = float(np.median([r["best_offset"] for r in per_episode]))
    out["survival_fraction"] = float(np.mean([r["survival"] for r in per_episode]))
    out["falls"] = int(sum(r["fell"] for r in per_episode))
    in_place = ref_travel < 0.05 * max(duration, 1e-9)  # under 5 cm/s on average
    out["speed_ratio"] = float("nan") if in_place else travel / ref_travel
    out["episodes"] = per_episode
    return out
