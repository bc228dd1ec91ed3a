"""The exported policy format: ``NAME.pt`` (TorchScript) + ``NAME.json`` (metadata), and its loader.

The TorchScript module maps the policy observation (float32 [B, n], built by
:func:`virl_quad.policy.observation.policy_observation`) to the deterministic
mean action [B, 12] (or [B, 14] with a trajectory generator); the observation
normaliser is baked in. The metadata says everything a robot needs to use it
safely (robot, joint order, default pose, control period, PD gains, and the policy
contract: action scale, clip and rate limit, trajectory generator, phase clock,
observation layout) and where it came from (demonstration, scores, project
version). :func:`load_policy` refuses a policy whose metadata does not match the
robot spec or whose contract this version cannot honour.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from virl_quad import __version__, robots
from virl_quad.policy.contract import PolicyContract
from virl_quad.robots.spec import RobotSpec

#: /2: heading in the observation, the contract's action size, trajectory generator and phase clock
FORMAT = "virl_quad.policy/2"


def metadata_for(spec: RobotSpec, contract: PolicyContract, demo: dict | None, scores: dict | None) -> dict:
    """The metadata dict of a policy for ``spec`` with ``contract`` (action and observation facts)."""
    return {
        "format": FORMAT,
        "project_version": __version__,
        "robot": spec.name,
        "joint_names": list(spec.joint_names),
        "default_pose": spec.default_pose.tolist(),         # rad
        **contract.to_metadata(),                           # action scale, clip, rate limit, TG, clock, layout
        "kp": spec.kp.tolist(), "kd": spec.kd.tolist(),     # N·m/rad, N·m·s/rad
        "torque_limit": spec.torque_limit.tolist(),         # N·m
        "demo": demo or {},
        "scores": scores or {},
    }


class NumpyMLP:
    """The exported actor (normaliser, Linear/ELU layers, identity output) evaluated in numpy.

    A 50 Hz control loop calls the policy once per state; for a 46 -> 256 -> 128 -> 12 MLP,
    torch's per-call overhead is most of the time, and numpy does it in a fraction of it.
    Built only from a module of exactly that structure, and used only after it has
    reproduced the TorchScript output (see :func:`fast_path`)."""

    def __init__(self, mean: np.ndarray, denom: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
        # fold the normaliser (x - mean) / denom into the first layer: one matmul fewer per call
        w, b = layers[0]
        w64 = w.astype(np.float64) / denom.astype(np.float64)[:, None]
        b64 = b.astype(np.float64) - mean.astype(np.float64) @ w64
        self.layers = [(w64.astype(np.float32), b64.astype(np.float32))] + list(layers[1:])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Action(s) for observation(s) ``x`` [n] or [B, n] (float32)."""
        h = x
        last = len(self.layers) - 1
        for i, (w, b) in enumerate(self.layers):
            h = h @ w
            h += b                                   # in place: one temporary array fewer per layer
            if i < last:                             # ELU (alpha 1) = max(h, expm1(min(h, 0))), as e^h - 1 >= h
                neg = np.minimum(h, 0)
                np.expm1(neg, out=neg)
                np.maximum(h, neg, out=h)
        return h


def _numpy_mlp(module: torch.jit.ScriptModule) -> NumpyMLP | None:
    """A :class:`NumpyMLP` copy of ``module`` if it has the exported actor's structure, else None."""
    try:
        norm, mlp, out = module.obs_normalizer, module.mlp, module.deterministic_output
        if out.original_name != "_IdentityDeterministicOutput":
            return None
        children = list(mlp.named_children())
        kinds = [c.original_name for _, c in children]
        if kinds != ["Linear", "ELU"] * (len(kinds) // 2) + ["Linear"]:
            return None
        if any(float(c.alpha) != 1.0 for _, c in children[1::2]):
            return None
        mean = norm._mean.detach().numpy().astype(np.float32)[0]
        denom = (norm._std.detach() + float(norm.eps)).numpy().astype(np.float32)[0]
        layers = [(c.weight.detach().numpy().T.astype(np.float32).copy(), c.bias.detach().numpy().astype(np.float32))
                  for _, c in children[::2]]
    except (AttributeError, RuntimeError, IndexError):
        return None
    return NumpyMLP(mean, denom, layers)


def fast_path(module: torch.jit.ScriptModule, size: int, tol: float = 1e-5, seed: int = 0) -> NumpyMLP | None:
    """A numpy copy of ``module`` that matches it on 256 random observations, else None.

    The probes are drawn on the policy's own input scale (its normaliser's mean + 2 std x
    N(0, 1)): far beyond it (e.g. N(0, 2) for an input whose std is 1e-3) the outputs reach
    hundreds and float32 round-off alone exceeds any fixed tolerance. Each output must
    match within ``tol`` x (1 + |output|): float32 agreement, relative for large outputs."""
    fast = _numpy_mlp(module)
    if fast is None:
        return None
    z = np.random.default_rng(seed).normal(0.0, 2.0, (256, size))
    try:
        norm = module.obs_normalizer
        x = (norm._mean.detach().numpy() + norm._std.detach().numpy() * z).astype(np.float32)
    except (AttributeError, RuntimeError, ValueError):
        return None
    with torch.inference_mode():
        want = module(torch.from_numpy(x)).numpy()
    try:
        got = fast(x)
    except ValueError:   # shapes disagree
        return None
    if got.shape != want.shape:
        return None
    return fast if bool(np.all(np.abs(got - want) <= tol * (1.0 + np.abs(want)))) else None


@dataclass
class LoadedPolicy:
    """A TorchScript policy with checked metadata (and, when it reproduces it, a numpy copy)."""

    module: torch.jit.ScriptModule
    meta: dict
    spec: RobotSpec
    contract: PolicyContract
    fast: NumpyMLP | None = None

    def __post_init__(self) -> None:
        self.obs_size = self.contract.observation_size       # entries of the policy observation
        self.action_size = self.contract.action_size         # entries of an action (12, or 14 with a TG)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Action (12 or 14,) for one policy observation (n,); ValueError on NaN/inf or a wrong size.
        Map it to joint targets with :class:`virl_quad.policy.ActionMap` (``self.contract``)."""
        x = np.asarray(obs, dtype=np.float32).reshape(-1)
        if x.shape[0] != self.obs_size:
            raise ValueError(f"observation has {x.shape[0]} entries, policy expects {self.meta['observation']['size']}")
        if not math.isfinite(x.sum(dtype=np.float64)):   # finite iff every entry is (float32 summed in float64)
            raise ValueError("observation contains NaN or inf")
        if self.fast is not None:
            a = self.fast(x).astype(np.float64)
        else:
            with torch.inference_mode():
                a = self.module(torch.from_numpy(x)[None])[0].numpy().astype(np.float64)
        if not math.isfinite(a.sum()):                   # float64 actions: NaN/inf propagate, |a| << 1e307
            raise ValueError("policy produced NaN or inf")
        return a


def check_metadata(meta: dict, spec: RobotSpec) -> PolicyContract:
    """The policy's contract; ValueError naming the first field where ``meta`` disagrees with ``spec``
    or with this version (see :meth:`PolicyContract.from_metadata`)."""
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
    return PolicyContract.from_metadata(meta, spec)


def metadata_path(policy_path: str | Path) -> Path:
    """``NAME.json`` beside ``NAME.pt``."""
    return Path(policy_path).with_suffix(".json")


def load_policy(path: str | Path, robot: str | None = None, numpy_fast_path: bool = True) -> LoadedPolicy:
    """Load ``NAME.pt`` and ``NAME.json``, check them against the robot spec (``robot`` or the metadata's).

    ``numpy_fast_path``: evaluate the policy in numpy when a copy reproduces the TorchScript
    module within 1e-5 (see :func:`fast_path`); otherwise, or when False, through torch."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"policy file {path} does not exist")
    if not zipfile.is_zipfile(path):   # every TorchScript archive is a zip: say so before asking for metadata
        raise ValueError(f"{path} is not a TorchScript policy (not a zip archive; export one with "
                         "python -m virl_quad.export)")
    meta_file = metadata_path(path)
    if not meta_file.is_file():
        raise ValueError(f"policy metadata {meta_file} does not exist")
    try:
        meta = json.loads(meta_file.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"policy metadata {meta_file} is not valid JSON ({exc})") from None
    spec = robots.get(robot or meta.get("robot", ""))
    contract = check_metadata(meta, spec)
    try:
        module = torch.jit.load(str(path), map_location="cpu")
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"{path} is not a TorchScript policy ({first[:100]})") from None
    module.eval()
    fast = fast_path(module, contract.observation_size) if numpy_fast_path else None
    policy = LoadedPolicy(module, meta, spec, contract, fast)
    try:
        probe = policy.act(np.zeros(contract.observation_size, np.float32))
    except RuntimeError as exc:   # the module takes another input size than the metadata says
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"{path} does not take its metadata's {contract.observation_size} observations "
                         f"({first[:100]})") from None
    if probe.shape != (contract.action_size,):
        raise ValueError(f"{path} outputs {probe.shape[0]} actions, its metadata says {contract.action_size}")
    return policy


def save_policy(module: torch.jit.ScriptModule, meta: dict, path: str | Path) -> Path:
    """Write ``NAME.pt`` and ``NAME.json``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module.save(str(path))
    metadata_path(path).write_text(json.dumps(meta, indent=2) + "\n")
    return path
