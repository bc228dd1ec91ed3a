"""The agent's pose drawn on another robot's body: the body a demonstration video shows.

A distance model trained on a video of one robot (a Laikago's trot) and frames of another (a
Pupper) learns first that the bodies differ, and that difference swamps the motion's: the
reward then pays nothing for moving like the video. A :class:`Shadow` draws each of the
agent's poses on the video's body instead, kinematically (no physics), with that body's own
camera and the same ground, so agent and expert frames differ in the motion alone.

The pose is carried over by the leg-length ratio ``k`` (m of the body per m of the agent),
measured from each robot's default pose: each foot's offset from its default position in the
base frame, the base's height above its default standing height and its travel on the ground
are scaled by ``k``; the base's orientation is kept. The body's joint angles come from its
closed-form leg kinematics, clipped to its joint limits.
"""

from __future__ import annotations

import numpy as np

from virl_quad.policy.legs import LegKinematics, leg_length
from virl_quad.robots.spec import RobotSpec
from virl_quad.sim import camera
from virl_quad.sim.world import World


class Shadow:
    """Renders of ``spec``'s poses drawn on ``body`` (another robot) on the ``ground``."""

    def __init__(self, spec: RobotSpec, body: RobotSpec, ground: str) -> None:
        self.spec, self.body = spec, body
        self.k = leg_length(body) / leg_length(spec)                       # m of the body per m of the agent
        self._src, self._dst = LegKinematics(spec), LegKinematics(body)
        self._src_feet0 = self._src.forward(spec.default_pose)             # m (4, 3), base frame
        self._dst_feet0 = self._dst.forward(body.default_pose)
        self._cam0 = camera.CameraParams.from_spec(spec)
        self._body_cam = camera.CameraParams.from_spec(body)
        self.world = World(body, ground=ground)

    def pose(self, base_pos: np.ndarray, base_quat: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The body's base position (m), orientation (xyzw) and joint angles (rad, 12) for the
        agent's (m, xyzw, rad)."""
        feet = self._dst_feet0 + self.k * (self._src.forward(q) - self._src_feet0)
        q_body = self.body.clip_to_limits(self._dst.inverse(feet))
        p = np.asarray(base_pos, dtype=np.float64)
        pos = np.array([self.k * p[0], self.k * p[1],
                        self.body.spawn_height + self.k * (p[2] - self.spec.spawn_height)])
        return pos, np.asarray(base_quat, dtype=np.float64), q_body

    def camera_for(self, cam: camera.CameraParams) -> camera.CameraParams:
        """The body's camera moved as ``cam`` is moved from the agent's nominal one (distance
        and height offsets scaled by the two cameras' distance ratio, yaw offset kept)."""
        r = self._body_cam.distance / self._cam0.distance
        return self._body_cam.jittered(r * (cam.distance - self._cam0.distance), r * (cam.height - self._cam0.height),
                                       cam.yaw - self._cam0.yaw)

    def render(self, base_pos: np.ndarray, base_quat: np.ndarray, q: np.ndarray,
               cam: camera.CameraParams | None = None) -> np.ndarray:
        """Gray frame (48, 48) uint8 of the agent's pose drawn on the body; ``cam``: the agent's
        camera this episode (None: its nominal one)."""
        pos, quat, q_body = self.pose(base_pos, base_quat, q)
        self.world.set_pose(pos, quat, q_body)
        return self.world.render(cam=self.camera_for(cam or self._cam0))

    def close(self) -> None:
        """Release the body's physics client."""
        self.world.close()
