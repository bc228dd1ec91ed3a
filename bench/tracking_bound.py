"""How high can the ground-truth score go on this robot? A privileged tracker's score (run by hand).

    python bench/tracking_bound.py [--robot pupper] [--demo trot] [--episodes 3] [--gains 0,1,3,6]

A learned policy sees only proprioception; this controller cheats
(``virl_quad.evaluation.tracker``): every control step it reads the reference joint angles
q_ref at the demonstration clock and commands, through the environment's own action
space (scale, clip, rate limit, PD gains, torque limits),

    target = q_ref(t + lead) + g * (q_ref(t) - q)          (rad)

i.e. PD tracking whose stiffness is raised (1 + g) times by feedback on the target. Episodes
are the evaluation's (10 s, reference state initialisation at seeded random phases,
domain randomisation on unless ``--no-randomize``). Printed beside it, from the same run:
the score of holding the default pose, and the bar of the training issue (2x that).

A joint-space tracker that knows the reference is an optimistic estimate of what a
policy can reach: if its best score stays below the bar, the bar is out of reach for
this robot model whatever the reward, and the gap says how far.
"""

from __future__ import annotations

import argparse

import numpy as np

from virl_quad import demo as demo_lib
from virl_quad import envs, robots
from virl_quad.evaluation.rollout import record_episode
from virl_quad.evaluation.score import TERMS, score_trajectory
from virl_quad.evaluation.tracker import DEFAULT_LEAD, tracker_action
from virl_quad.kinematics import Kinematics
from virl_quad.policy.observation import policy_block


def run(robot: str, demo, gain: float | None, lead: float, episodes: int, randomize: bool,
        observed: bool = False) -> dict[str, float]:
    """Mean figures over seeded episodes; ``gain`` None: hold the default pose (action 0).
    ``observed``: the tracker feeds back the joint angles of the policy observation (delayed
    and noisy, as a policy measures them) instead of the simulator's true ones."""
    spec = robots.get(robot)
    m, kin = demo.motion, Kinematics(spec)
    env = envs.make(robot, demo=demo, randomize=randomize, episode_seconds=10.0)
    out: dict[str, list[float]] = {k: [] for k in (*TERMS, "total", "survival", "travel", "ref_travel")}
    c = env.unwrapped.contract
    q_cols = policy_block("joint_pos_minus_default", c.with_phase, c.action_size)

    def policy(obs: dict) -> np.ndarray:
        if gain is None:
            return np.zeros(c.action_size)
        q = obs["policy"][q_cols] + spec.default_pose if observed else None
        return tracker_action(env, gain, lead, q=q)

    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=ep)
            traj, times, fell = record_episode(env, policy, obs)
            res = score_trajectory(traj, m, times, robot, kin=kin)
            for k in (*TERMS, "total"):
                out[k].append(res[k])
            out["survival"].append(0.0 if fell else 1.0)
            out["travel"].append(float(traj.root_pos[-1, 0] - traj.root_pos[0, 0]))
            out["ref_travel"].append(float(m.state_at(times[-1]).root_pos[0] - m.state_at(times[0]).root_pos[0]))
    finally:
        env.close()
    res = {k: float(np.mean(v)) for k, v in out.items()}
    res["speed_ratio"] = res["travel"] / res["ref_travel"] if abs(res["ref_travel"]) > 1e-6 else float("nan")
    return res


def main() -> None:
    """Print one row for the default pose and one per tracker gain."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper")
    p.add_argument("--demo", default="trot", help="built-in gait or motion file")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--gains", default="1,2,3", help="feedback gains g (comma-separated)")
    p.add_argument("--lead", type=float, default=DEFAULT_LEAD, help="s the feed-forward reference runs ahead")
    p.add_argument("--no-randomize", action="store_true", help="domain randomisation off")
    p.add_argument("--observed", action="store_true", help="feed back the observed joint angles (delayed, "
                   "noisy: what a policy measures) instead of the true ones")
    a = p.parse_args()
    d = demo_lib.load(a.demo, a.robot)
    rand = not a.no_randomize
    print(f"{a.robot}, demo {a.demo}: {a.episodes} episodes of 10 s, randomisation {'on' if rand else 'off'}, "
          f"lead {a.lead:g} s{', observed joint angles' if a.observed else ''}")
    print(f"{'controller':<22}" + "".join(f"{k[:9]:>10}" for k in (*TERMS, "total")) + f"{'survival':>10}{'speed':>8}")
    rows = [("default pose", None)] + [(f"tracker g={float(g):g}", float(g)) for g in a.gains.split(",")]
    base = None
    best = 0.0
    for name, g in rows:
        r = run(a.robot, d, g, a.lead, a.episodes, rand, a.observed)
        base = r["total"] if g is None else base
        best = max(best, r["total"]) if g is not None else best
        print(f"{name:<22}" + "".join(f"{r[k]:10.3f}" for k in (*TERMS, "total"))
              + f"{r['survival']:10.2f}{r['speed_ratio']:8.2f}", flush=True)
    print(f"best tracker / default pose: {best / base:.2f}  (the training issue's bar: 2.00, score {2 * base:.3f})")


if __name__ == "__main__":
    main()
