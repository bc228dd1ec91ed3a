"""Open-loop playback: can the simulated robot do a demonstration just by PD-tracking it? (run by hand)

    python bench/demo_playback.py [--robot pupper] [--gaits trot,walk] [--seconds 4] [--lead 0.06]

For each built-in gait, the reference joint angles (``lead`` s ahead, to make up for
the PD lag) are sent as PD targets, with domain randomisation off, from the
reference's own first state. Printed against the reference, measured in the same
run: foot clearance in swing (cm), base height (m), forward travel (m) and their
ratios, the ground-truth score and the share of the time each foot is in the air.

A ratio well below 1 says the robot's actuators (gains, torque limits) cannot
reproduce the motion open-loop: a policy then has to learn more than the
demonstration shows (e.g. exaggerated swing against the PD sag), which costs samples.
"""

from __future__ import annotations

import argparse

import numpy as np

from virl_quad import demo as demo_lib
from virl_quad import envs, robots
from virl_quad.evaluation.score import Trajectory, score_trajectory
from virl_quad.kinematics import Kinematics

AIR = 0.01  # m above the foot radius: "in the air"
ACTION_CLIP = 2.0  # the env's action clip


def playback(robot: str, gait: str, seconds: float, lead: float) -> dict[str, float]:
    """Track ``gait``'s reference open-loop for ``seconds``; figures of the robot and the reference."""
    spec = robots.get(robot)
    d = demo_lib.load(gait, robot)
    m, kin = d.motion, Kinematics(spec)
    env = envs.make(robot, demo=d, randomize=False, episode_seconds=seconds + 1.0, action_clip=ACTION_CLIP)
    u = env.unwrapped
    env.reset(seed=0, options={"demo_step": 0})
    rows, feet, ref_feet, times = [], [], [], []
    fell = False
    try:
        for _ in range(int(round(seconds * spec.control_hz))):
            q = m.state_at(u.demo_step / d.fps + lead).q
            _, _, fell, _, _ = env.step((spec.clip_to_limits(q) - spec.default_pose) / u.action_scale)
            s = u.state
            rows.append((s.base_pos, s.base_quat, s.q, s.dq, s.base_lin_vel, s.base_ang_vel))
            feet.append(u.world.foot_positions())
            times.append(u.demo_step / d.fps)
            ref = m.state_at(times[-1])
            ref_feet.append(kin.foot_positions_batch(ref.q[None], ref.root_pos[None], ref.root_quat[None])[0])
            if fell:
                break
    finally:
        env.close()
    cols = [np.array(c) for c in zip(*rows)]
    traj = Trajectory(*cols, feet=np.array(feet))
    score = score_trajectory(traj, m, np.array(times), robot, kin=kin)["total"]
    fz, rz = np.array(feet)[:, :, 2] - spec.foot_radius, np.array(ref_feet)[:, :, 2] - spec.foot_radius
    travel = float(cols[0][-1, 0] - cols[0][0, 0])
    ref_travel = float(m.state_at(times[-1]).root_pos[0] - m.state_at(times[0]).root_pos[0])
    return {"clearance_cm": 100 * float(np.mean(fz.max(0))), "ref_clearance_cm": 100 * float(np.mean(rz.max(0))),
            "air": float(np.mean(fz > AIR)), "ref_air": float(np.mean(rz > AIR)),
            "height": float(np.mean(cols[0][:, 2])), "ref_height": float(np.mean([m.state_at(t).root_pos[2]
                                                                              for t in times])),
            "travel": travel, "ref_travel": ref_travel, "score": float(score), "fell": float(fell)}


def main() -> None:
    """Print one row per gait."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="pupper")
    p.add_argument("--gaits", default="trot,pace,bound,pronk,walk")
    p.add_argument("--seconds", type=float, default=4.0, help="s of playback per gait")
    p.add_argument("--lead", type=float, default=0.06, help="s the targets run ahead of the reference")
    a = p.parse_args()
    print(f"{a.robot}: open-loop PD playback, {a.seconds:g} s, targets {a.lead:g} s ahead, no randomisation")
    print(f"{'gait':<7}{'clearance cm':>14}{'ratio':>7}{'air %':>11}{'height m':>15}{'travel m':>16}"
          f"{'ratio':>7}{'score':>7}")
    for gait in a.gaits.split(","):
        r = playback(a.robot, gait.strip(), a.seconds, a.lead)
        ratio = r["travel"] / r["ref_travel"] if abs(r["ref_travel"]) > 1e-6 else float("nan")
        print(f"{gait:<7}{r['clearance_cm']:6.2f} / {r['ref_clearance_cm']:4.2f}{r['clearance_cm'] / r['ref_clearance_cm']:7.2f}"
              f"{100 * r['air']:5.0f} / {100 * r['ref_air']:3.0f}{r['height']:7.3f} / {r['ref_height']:5.3f}"
              f"{r['travel']:7.3f} / {r['ref_travel']:6.3f}{ratio:7.2f}{r['score']:7.3f}"
              f"{'  (fell)' if r['fell'] else ''}")


if __name__ == "__main__":
    main()
