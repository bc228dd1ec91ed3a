"""The exported policy format: ``NAME.pt`` (TorchScript) + ``NAME.json`` (metadata), and its loader.

The TorchScript module maps the policy observation (float32 [B, n], built by
:func:`virl_quad.envs.observation.policy_observation`) to the deterministic
mean action [B, 12]; the observation normaliser is baked in. The metadata
says everything a robot needs to use it safely (robot, joint order, default
pose, action scale, control period, PD gains, observation layout) and where
it came from (demonstration, scores, project version). :func:`load_policy`
refuses a policy whose metadata does not match the robot spec.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from virl_quad import __version__, robots
from virl_quad.envs import observation as obs_lib
from virl_quad.robots.spec import RobotSpec

FORMAT = "virl_quad.policy/1"


def metadata_for(spec: RobotSpec, with_phase: bool, action_scale: float, action_clip: float,
                 demo: dict | None, scores: dict | None) -> dict:
    """The metadata dict of a policy for ``spec``."""
    return {
        "format": FORMAT,
        "project_version": __version__,
        "robot": spec.name,
        "joint_names": list(spec.joint_names),
        "default_pose": spec.default_pose.tolist(),         # rad
        "action_scale": action_scale,                       # rad per unit action
        "action_clip": action_clip,                         # |a| clipped to this before scaling
        "control_dt": spec.control_dt,                      # s
        "kp": spec.kp.tolist(), "kd": spec.kd.tolist(),     # N·m/rad, N·m·s/rad
        "torque_limit": spec.torque_limit.tolist(),         # N·m
        "observation": {
            "size": obs_lib.policy_size(with_phase),
            "with_phase": with_phase,
            "layout": [{"name": n, "size": k, "scale": s} for n, k, s in obs_lib.policy_layout(with_phase)],
        },
        "demo": demo or {},
        "scores": scores or {},
    }


@dataclass
class LoadedPolicy:
    """A TorchScript policy with checked metadata."""

    module: torch.jit.ScriptModule
    meta: dict
    spec: RobotSpec

    @property
    def with_phase(self) -> bool:
        """Whether the observation carries the demonstration phase."""
        return bool(self.meta["observation"]["with_phase"])

    @property
    def demo_frames(self) -> int:
        """Length of the demonstration cycle in control steps (phase = step % frames / frames)."""
        return int(self.meta.get("demo", {}).get("num_frames", 0))

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Action (12,) for one policy observation (n,); ValueError on NaN/inf or a wrong size."""
        x = np.asarray(obs, dtype=np.float32).reshape(-1)
        if x.shape[0] != self.meta["observation"]["size"]:
            raise ValueError(f"observation has {x.shape[0]} entries, policy expects {self.meta['observation']['size']}")
        if not np.all(np.isfinite(x)):
            raise ValueError("observation contains NaN or inf")
        with torch.inference_mode():
            a = self.module(torch.from_numpy(x)[None])[0].numpy().astype(np.float64)
        if not np.all(np.isfinite(a)):
            raise ValueError("policy produced NaN or inf")
        return a

    def joint_targets(self, action: np.ndarray) -> np.ndarray:
        """PD targets (rad) for an action, as in training: default + scale * clip(a), within joint limits."""
        a = np.clip(action, -self.meta["action_clip"], self.meta["action_clip"])
        return self.spec.clip_to_limits(self.spec.default_pose + self.meta["action_scale"] * a)


def check_metadata(meta: dict, spec: RobotSpec) -> None:
    """Raise ValueError naming the first field where ``meta`` disagrees with ``spec``."""
    if meta.get("format") != FORMAT:
        raise ValueError(f"policy metadata format is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("robot") != spec.name:
        raise ValueError(f"policy is for robot {meta.get('robot')!r}, not {spec.name!r}")
    if meta.get("joint_names") != list(spec.joint_names):
        raise ValueError(f"policy joint order {meta.get('joint_names')} differs from {spec.name}'s")
    checks = {"default_pose": spec.default_pose, "kp": spec.kp, "kd": spec.kd}
    for key, want in checks.items():
        got = np.asarray(meta.get(key, []), dtype=np.float64)
        if got.shape != want.shape or not np.allclose(got, want, atol=1e-6):
            raise ValueError(f"policy {key} {got.tolist()} differs from {spec.name}'s {want.tolist()}")
    if abs(float(meta.get("control_dt", -1)) - spec.control_dt) > 1e-9:
        raise ValueError(f"policy control period {meta.get('control_dt')} s differs from {spec.name}'s "
                         f"{spec.control_dt} s")
    obs = meta.get("observation", {})
    want_layout = [{"name": n, "size": k, "scale": s} for n, k, s in obs_lib.policy_layout(bool(obs.get("with_phase")))]
    if obs.get("layout") != want_layout:
        raise ValueError("policy observation layout differs from this version's observation builder")


def metadata_path(policy_path: str | Path) -> Path:
    """``NAME.json`` beside ``NAME.pt``."""
    return Path(policy_path).with_suffix(".json")


def load_policy(path: str | Path, robot: str | None = None) -> LoadedPolicy:
    """Load ``NAME.pt`` and ``NAME.json``, check them against the robot spec (``robot`` or the metadata's)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"policy file {path} does not exist")
    meta_file = metadata_path(path)
    if not meta_file.is_file():
        raise ValueError(f"policy metadata {meta_file} does not exist")
    try:
        meta = json.loads(meta_file.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"policy metadata {meta_file} is not valid JSON ({exc})") from None
    spec = robots.get(robot or meta.get("robot", ""))
    check_metadata(meta, spec)
    try:
        module = torch.jit.load(str(path), map_location="cpu")
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"{path} is not a TorchScript policy ({first[:100]})") from None
    module.eval()
    policy = LoadedPolicy(module, meta, spec)
    probe = policy.act(np.zeros(meta["observation"]["size"], np.float32))
    if probe.shape != (12,):
        raise ValueError(f"{path} outputs {probe.shape[0]} actions, expected 12")
    return policy


def save_policy(module: torch.jit.ScriptModule, meta: dict, path: str | Path) -> Path:
    """Write ``NAME.pt`` and ``NAME.json``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module.save(str(path))
    metadata_path(path).write_text(json.dumps(meta, indent=2) + "\n")
    return path
