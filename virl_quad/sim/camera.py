"""Third-person camera that follows a robot's base at a fixed distance.

The camera keeps a fixed world yaw (it does not turn with the robot, so a turn
is visible) and renders with PyBullet's CPU TinyRenderer, which works headless.
Frames are 48x48 grayscale uint8, the VIRL observation; a larger RGB preview
is available for videos. Given a ``ground``, the ground plane is drawn in numpy behind
TinyRenderer's render of the robot (:mod:`virl_quad.sim.ground`), far cheaper than
TinyRenderer's own.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from virl_quad.quiet import import_pybullet_quietly
from virl_quad.sim import ground as ground_mod

import_pybullet_quietly()   # first: its build-time banner would break the CLIs' one-line errors
import pybullet  # noqa: E402

FRAME_SIZE = 48  # px, VIRL frame side


@dataclass(frozen=True)
class CameraParams:
    """Pose of the follow camera relative to the robot's base."""

    distance: float   # m, camera to target
    height: float     # m, target height offset above the base
    yaw: float        # deg, 0 looks at the robot from its right side (+x is to the right)
    pitch: float      # deg, negative looks down
    fov: float = 50.0  # deg, vertical field of view

    @staticmethod
    def from_spec(spec) -> "CameraParams":
        """The nominal camera of a RobotSpec."""
        return CameraParams(spec.camera_distance, spec.camera_height, spec.camera_yaw, spec.camera_pitch)

    def jittered(self, d_distance: float, d_height: float, d_yaw: float) -> "CameraParams":
        """A copy moved by the given offsets (m, m, deg)."""
        return CameraParams(self.distance + d_distance, self.height + d_height, self.yaw + d_yaw,
                            self.pitch, self.fov)


def rgb_to_gray(rgb: np.ndarray) -> np.ndarray:
    """ITU-R BT.601 luma of an (H, W, 3|4) uint8 image, as uint8 (H, W): OpenCV's fixed-point
    conversion (14-bit weights summing to exactly 1, so a gray pixel keeps its level; a coloured
    one is within one level of the float formula), about 7x faster than numpy at 48x48."""
    rgb = np.ascontiguousarray(rgb)
    code = cv2.COLOR_RGBA2GRAY if rgb.shape[-1] == 4 else cv2.COLOR_RGB2GRAY
    return cv2.cvtColor(rgb, code)


def render(client: int, target: np.ndarray, cam: CameraParams, size: int = FRAME_SIZE,
           rgb: bool = False, ground: str | None = None) -> np.ndarray:
    """Render the scene looking at ``target`` (m, world). Gray (size, size) uint8, or RGB (size, size, 3).
    ``ground``: draw this ground (one of :data:`~virl_quad.sim.params.GROUNDS`) behind the scene in
    numpy, for a world whose ground plane TinyRenderer does not draw; None: the scene alone."""
    view = pybullet.computeViewMatrixFromYawPitchRoll(
        cameraTargetPosition=[float(target[0]), float(target[1]), float(target[2]) + cam.height],
        distance=cam.distance, yaw=cam.yaw, pitch=cam.pitch, roll=0.0, upAxisIndex=2,
        physicsClientId=client)
    proj = pybullet.computeProjectionMatrixFOV(fov=cam.fov, aspect=1.0, nearVal=ground_mod.NEAR,
                                               farVal=ground_mod.FAR, physicsClientId=client)
    _, _, px, depth, _ = pybullet.getCameraImage(
        size, size, viewMatrix=view, projectionMatrix=proj, renderer=pybullet.ER_TINY_RENDERER,
        shadow=0, flags=pybullet.ER_NO_SEGMENTATION_MASK, physicsClientId=client)
    img = np.asarray(px, dtype=np.uint8).reshape(size, size, 4)
    img = img[..., :3].copy() if rgb else rgb_to_gray(img)
    if ground is not None:
        img = ground_mod.composite(img, np.asarray(depth).reshape(size, size), view, proj, ground)
    return img
