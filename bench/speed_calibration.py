"""Does the video speed term read an agent's travel right? (run by hand)

    python bench/speed_calibration.py --video dog.mp4 --reference dog_pupper.npz [--draw-as laikago]

``--video``: the demonstration the term's target comes from (any source ``--demo`` takes, imported
for Pupper). ``--reference``: a demonstration with a reference motion of the same clip for Pupper
(``demo render --robot pupper --motion ...``). The reference is played kinematically with its
travel scaled by 0, 0.25, ..., 1.5 and drawn as training draws the agent (on ``--draw-as``'s body
when the video shows another robot); for each scale the script prints the term's mean reading
as a share of the video's slide, its spread, and the reward it pays, with shifts searched to
:func:`~virl_quad.reward.egomotion.search_reach` (what training does) and to the full
:data:`~virl_quad.reward.egomotion.MAX_DX`. A calibrated term reads each scale as itself, up to the
video's speed at least.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from virl_quad import demo as demo_lib
from virl_quad import robots
from virl_quad.reward import egomotion as eg
from virl_quad.sim.shadow import Shadow
from virl_quad.sim.world import World

SCALES = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
STEPS = 250                   # frames per replay (5 s at 50 Hz)


def replay(reference, scale: float, draw_as: str | None) -> np.ndarray:
    """Gray frames [STEPS, 48, 48] of the reference motion, its travel x ``scale``, drawn as the env
    draws the agent (on ``draw_as``'s body, or Pupper's own)."""
    pupper = robots.get("pupper")
    shadow = Shadow(pupper, robots.get(draw_as), "checker") if draw_as else None
    world = None if shadow else World(pupper, ground="checker")
    frames = np.empty((STEPS, 48, 48), np.uint8)
    try:
        for i in range(STEPS):
            pos, quat, q = reference.motion.pose_at(i / 50.0)
            pos = np.array(pos, dtype=np.float64)
            pos[0] *= scale
            q = pupper.clip_to_limits(q)
            if shadow:
                frames[i] = shadow.render(pos, quat, q)
            else:
                world.set_pose(pos, quat, q)
                frames[i] = world.render()
    finally:
        (shadow or world).close()
    return frames


def reading(video, frames: np.ndarray, reach: int) -> tuple[float, float, float]:
    """The term's mean reading / the video's slide, its spread (same unit) and its mean reward."""
    term = eg.VideoSpeedTerm.for_demo(video.frames, video.fps, 1, reach)
    if term is None:
        raise SystemExit("error: the video shows no patterned ground to measure its travel by")
    term.find_agent_ground(frames)
    r, valid, given = term.rollout(torch.from_numpy(frames[:, None]), torch.zeros(len(frames), 1, dtype=torch.bool))
    g = given[valid]
    return float(g.mean()) / term.target, float(g.std()) / abs(term.target), float(r[valid].mean())


def main() -> None:
    """Print the term's reading at each travel scale, searched to search_reach and to MAX_DX."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--video", required=True, help="the demonstration video (any --demo source)")
    ap.add_argument("--reference", required=True, help="the same clip with a reference motion, for Pupper")
    ap.add_argument("--draw-as", default=None, help="the body the agent is drawn on (default: Pupper's own)")
    a = ap.parse_args()
    video = demo_lib.load(a.video, "pupper", ground="checker")
    reference = demo_lib.load(a.reference, "pupper")
    if reference.motion is None:
        raise SystemExit(f"error: {a.reference} has no reference motion")
    reach = eg.search_reach(video.frames)
    print(f"video {a.video}: {video.num_frames} frames at {video.fps:g} fps; search_reach {reach} px (MAX_DX {eg.MAX_DX})")
    print(f"{'travel':>6} | {'read (reach)':>12} {'spread':>7} {'reward':>7} | {'read (MAX_DX)':>13} {'spread':>7} {'reward':>7}")
    for scale in SCALES:
        frames = replay(reference, scale, a.draw_as)
        near, full = reading(video, frames, reach), reading(video, frames, eg.MAX_DX)
        print(f"{scale:6.2f} | {near[0]:12.3f} {near[1]:7.3f} {near[2]:7.3f} | {full[0]:13.3f} {full[1]:7.3f} {full[2]:7.3f}")


if __name__ == "__main__":
    main()
