"""The numpy ground against TinyRenderer's own: the same frames."""

from __future__ import annotations

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.sim.camera import CameraParams
from virl_quad.sim.ground import LIT_LEVELS, SKY, ground_image
from virl_quad.sim.world import World


@pytest.mark.parametrize("robot,ground", [("pupper", "checker"), ("pupper", "plain"), ("laikago", "checker")])
def test_numpy_ground_draws_the_frames_tinyrenderer_draws(robot: str, ground: str) -> None:
    spec = robots.get(robot)
    rng = np.random.default_rng(3)
    with World(spec, ground=ground) as fast, World(spec, ground=ground, ground_renderer="tiny") as ref:
        for _ in range(8):   # random poses (some with feet below the ground), places and camera jitter
            pos = [rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(0.02, 0.3)]
            quat = fast.bc.getQuaternionFromEuler(rng.normal(0, 0.4, 3))
            q = np.asarray(spec.default_pose) + rng.normal(0, 0.4, 12)
            for w in (fast, ref):
                w.set_pose(pos, quat, q)
            cam = CameraParams.from_spec(spec).jittered(rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02),
                                                        rng.uniform(-10, 10))
            for size, rgb in ((48, False), (128, True)):
                a = fast.render(size=size, rgb=rgb, cam=cam).astype(int)
                b = ref.render(size=size, rgb=rgb, cam=cam).astype(int)
                assert a.shape == b.shape
                assert (a == b).mean() >= 0.995, (size, (a == b).mean())   # differences: edge pixels only
                assert np.abs(a - b).mean() < 0.5


def test_ground_image_sees_squares_below_and_sky_above_the_horizon() -> None:
    import pybullet

    view = pybullet.computeViewMatrixFromYawPitchRoll([0.0, 0.0, 0.2], 0.6, 0.0, -15.0, 0.0, 2)
    proj = pybullet.computeProjectionMatrixFOV(50.0, 1.0, 0.02, 20.0)
    gray, depth = ground_image(view, proj, 48, "checker")
    assert (gray[0] == SKY).all() and (depth[0] == 1.0).all()          # top row: above the horizon
    assert set(np.unique(gray[-10:])) == set(LIT_LEVELS["checker"])   # bottom rows: both squares
    assert (np.diff(depth[20:, 0]) < 0).all()                          # nearer towards the bottom
    moved = pybullet.computeViewMatrixFromYawPitchRoll([0.125, 0.0, 0.2], 0.6, 0.0, -15.0, 0.0, 2)
    shifted, _ = ground_image(moved, proj, 48, "checker")
    assert (shifted[-10:] != gray[-10:]).mean() > 0.8                  # one square along: colours swap


def test_unknown_ground_renderer_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown ground renderer"):
        World(robots.get("pupper"), ground_renderer="opengl")
