"""Domain randomisation: pure sampling, ranges respected, off means nominal."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.envs.randomize import DRConfig, sample

SPEC = robots.get("pupper")


def _values(draw) -> dict[str, np.ndarray]:
    p, cam, nominal = draw.physics, draw.camera, SPEC
    return {
        "mass_scale": p.mass_scale, "payload": p.payload / nominal.total_mass,
        "inertia_scale": p.inertia_scale, "motor_strength": p.motor_strength,
        "kp_scale": p.kp_scale, "kd_scale": p.kd_scale, "joint_friction": p.joint_friction,
        "joint_damping": p.joint_damping, "ground_friction": p.ground_friction,
        "ground_restitution": p.ground_restitution, "latency": draw.latency,
        "obs_noise": draw.obs_noise, "push_velocity": draw.push_velocity,
        "push_interval": draw.push_interval,
        "camera_distance": (cam.distance - nominal.camera_distance) / nominal.camera_distance,
        "camera_height": (cam.height - nominal.camera_height) / nominal.camera_distance,
        "camera_yaw": cam.yaw - nominal.camera_yaw,
    }


def test_every_parameter_inside_its_range() -> None:
    cfg = DRConfig()
    rng = np.random.default_rng(0)
    seen = {f.name: [] for f in dataclasses.fields(DRConfig)}
    for _ in range(500):
        for name, v in _values(sample(cfg, rng, SPEC)).items():
            seen[name].append(np.atleast_1d(v))
    assert set(seen) == set(_values(sample(cfg, rng, SPEC))), "every range must be checked"
    for name, vals in seen.items():
        lo, hi = getattr(cfg, name)
        v = np.concatenate(vals)
        assert v.min() >= lo - 1e-9 and v.max() <= hi + 1e-9, name
        assert v.max() - v.min() > 0.5 * (hi - lo), f"{name} should cover its range"


def test_pure_function_of_rng() -> None:
    a = sample(DRConfig(), np.random.default_rng(5), SPEC)
    b = sample(DRConfig(), np.random.default_rng(5), SPEC)
    assert a.physics.as_vector().tolist() == b.physics.as_vector().tolist()
    assert (a.latency, a.camera) == (b.latency, b.camera)


def test_off_is_nominal() -> None:
    d = sample(DRConfig.off(), np.random.default_rng(1), SPEC)
    assert d.physics.mass_scale == 1.0 and d.physics.joint_friction is None
    assert d.latency == 0.0 and d.push_velocity == 0.0 and d.obs_noise == 0.0
    assert d.camera.distance == SPEC.camera_distance


def test_overrides() -> None:
    cfg = DRConfig.from_overrides({"ground_friction": (0.9, 0.9), "latency": [0, 0.01]})
    d = sample(cfg, np.random.default_rng(2), SPEC)
    assert d.physics.ground_friction == 0.9 and 0 <= d.latency <= 0.01
    assert cfg.mass_scale == DRConfig().mass_scale
    for bad in ({"latency": (0.1, 0.0)}, {"latency": 3}, {"latency": (0, np.nan)}, {"nope": (0, 1)}):
        with pytest.raises(ValueError):
            DRConfig.from_overrides(bad)


def test_each_robot_has_its_own_ranges() -> None:
    """Pupper's observation latency is bounded by its HAL's period (0-20 ms), Laikago keeps
    motion_imitation's 0-40 ms; the env draws from the robot's ranges."""
    from virl_quad import envs

    assert DRConfig.for_robot(SPEC).latency == (0.0, 0.02)
    assert DRConfig.for_robot(robots.get("laikago")).latency == DRConfig().latency == (0.0, 0.04)
    env = envs.make("pupper", randomize=True, render=False)
    try:
        draws = []
        for seed in range(30):
            env.reset(seed=seed)
            draws.append(env.unwrapped.rand.latency)
        assert max(draws) <= 0.02 and max(draws) > 0.01
    finally:
        env.close()
