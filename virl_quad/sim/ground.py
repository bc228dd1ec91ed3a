"""The ground the follow camera sees, drawn in numpy instead of by TinyRenderer.

The ground is a flat plane at z = 0 with a gray pattern (:data:`GROUNDS`). TinyRenderer
spends most of a 48x48 frame on the plane's pixels, although every one of them is a
ray-plane intersection and a table look-up. :func:`composite` therefore
renders only the robot with TinyRenderer and draws the ground behind it from the same view
and projection matrices: the same pixel centres, the same depth test, the same gray levels
(TinyRenderer's flat lighting of an upward plane), identical to TinyRenderer's own ground up
to a pixel or two on edges (``tests/sim/test_ground.py`` compares them).

The PNG texture of :func:`texture_path` is the same pattern for TinyRenderer itself
(``World(ground_renderer="tiny")``), the reference the composite is checked against.
"""

from __future__ import annotations

import functools
import os
import tempfile
from pathlib import Path

import numpy as np

from virl_quad.sim.params import GROUNDS

CHECKER_SQUARE = 0.125  # m: side of a square of the "checker" ground (16 per 2 m texture tile)
TEXTURE_LEVELS = {"checker": (95, 150), "plain": (120, 120)}   # texture image's gray, squares (even, odd)
#: the gray TinyRenderer draws the lit plane with, squares (even, odd) in world coordinates
#: (plane100 maps the texture so that the world's even squares are the image's odd ones)
LIT_LEVELS = {"checker": (140, 89), "plain": (112, 112)}
SKY = 255          # gray where no ground is seen (TinyRenderer's clear colour)
NEAR, FAR = 0.02, 20.0  # m, the camera's clip planes (what the projection matrix is built with)


def check_ground(ground: str) -> None:
    """Raise ValueError for a ground name that is not one of :data:`GROUNDS`."""
    if ground not in GROUNDS:
        raise ValueError(f"unknown ground {ground!r}; choose one of: {', '.join(GROUNDS)}")


def texture_path(ground: str) -> str:
    """Path of the ground's texture image for TinyRenderer (made once, cached in the temp folder)."""
    check_ground(ground)
    path = Path(tempfile.gettempdir()) / f"virl_quad_ground_{ground}_v1.png"
    if not path.exists():
        import cv2

        n, px = 16, 16  # squares per texture tile (one tile = 2 m on plane100), pixels per square
        idx = (np.arange(n * px) // px)
        board = ((idx[:, None] + idx[None, :]) % 2).astype(np.uint8)
        img = np.asarray(TEXTURE_LEVELS[ground], dtype=np.uint8)[board]
        tmp = path.with_suffix(f".{os.getpid()}.png")
        cv2.imwrite(str(tmp), img)
        os.replace(tmp, path)
    return str(path)


@functools.lru_cache(maxsize=64)
def _plane_rays(size: int, fx: float, fy: float, rot: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel (row-major, size * size), for a camera of rotation ``rot`` (world -> eye, 3x3
    float64 bytes) at unit height above the plane: where its ray meets the plane, relative to
    the camera (x, y in m), and the eye-frame depth of that point (m; <= 0: it never does).
    TinyRenderer's pixel convention: column j at x_ndc = 2 j / size - 1, row i at
    y_ndc = 1 - 2 (i + 1) / size."""
    j = np.arange(size, dtype=np.float64)
    x, y = np.meshgrid((2 * j / size - 1) / fx, (1 - 2 * (j + 1) / size) / fy)
    eye_rays = np.stack([x.ravel(), y.ravel(), -np.ones(size * size)], axis=-1)   # eye z = -1
    world = eye_rays @ np.frombuffer(rot, dtype=np.float64).reshape(3, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(world[:, 2] < 0, -1.0 / world[:, 2], -1.0)
    out = (depth * world[:, 0], depth * world[:, 1], depth)
    for a in out:
        a.setflags(write=False)
    return out


def ground_image(view: list[float], proj: list[float], size: int, ground: str) -> tuple[np.ndarray, np.ndarray]:
    """The ground alone seen through PyBullet's ``view`` and ``proj`` matrices (column-major
    16 floats): (gray uint8 (size, size), depth (size, size) in the depth buffer's [0, 1]
    convention, 1 where no ground is seen)."""
    m = np.asarray(view, dtype=np.float64).reshape(4, 4).T   # world -> eye
    rot = np.ascontiguousarray(m[:3, :3])
    eye = -rot.T @ m[:3, 3]                                # m, camera position in the world
    dx, dy, dz = _plane_rays(size, float(proj[0]), float(proj[5]), rot.tobytes())
    dist = eye[2] * dz                                     # m, eye-frame depth of each plane point
    seen = (dist > NEAR) & (dist < FAR)
    square = np.floor((eye[0] + eye[2] * dx) * (1 / CHECKER_SQUARE))
    square += np.floor((eye[1] + eye[2] * dy) * (1 / CHECKER_SQUARE))
    levels = np.array([*LIT_LEVELS[ground], SKY], dtype=np.uint8)
    gray = levels[np.where(seen, square.astype(np.int64) & 1, 2)]
    with np.errstate(divide="ignore"):
        depth = np.where(seen, (0.5 * (FAR + NEAR) / (FAR - NEAR) + 0.5) - FAR * NEAR / ((FAR - NEAR) * dist), 1.0)
    return gray.reshape(size, size), depth.reshape(size, size)


def composite(image: np.ndarray, depth: np.ndarray, view: list[float], proj: list[float],
              ground: str) -> np.ndarray:
    """Draw the ground behind a render of the robot alone (``image``: gray (S, S) or RGB (S, S, 3)
    uint8, and its depth buffer (S, S)): each pixel shows whichever of robot and ground is
    nearer. Returns an image of ``image``'s shape."""
    gray, ground_depth = ground_image(view, proj, image.shape[0], ground)
    robot = depth < ground_depth
    if image.ndim == 3:
        return np.where(robot[..., None], image, gray[..., None])
    return np.where(robot, image, gray)
