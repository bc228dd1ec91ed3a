"""Atomic checkpoints that load with ``torch.load(weights_only=True)``.

A checkpoint holds only tensors, numbers, strings, lists and dicts: policy and
critic (with their observation normalisers), PPO optimiser, distance model and
its optimiser, the training options, the iteration and the RNG states. It is
written to a temporary file in the same folder and renamed over the old one,
so a crash (even ``kill -9``) leaves the previous checkpoint intact.
"""

from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import torch

LATEST = "checkpoint.pt"


#: How the video speed term enters the reward in checkpoints this version writes: it gates the
#: distance reward (see :func:`virl_quad.reward.egomotion.gated`). A checkpoint without the key
#: was trained with the term added as a weighted sum.
SPEED_TERM_FORM = "gate"


def rng_state() -> dict:
    """RNG states of torch, numpy and Python, as weights-only-loadable values."""
    kind, keys, pos, has_gauss, cached = np.random.get_state()
    py = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "numpy": {"kind": kind, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                  "has_gauss": int(has_gauss), "cached": float(cached)},
        "python": [py[0], list(py[1]), py[2]],
    }


def set_rng_state(state: dict) -> None:
    """Restore what :func:`rng_state` captured."""
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"], n["has_gauss"], n["cached"]))
    p = state["python"]
    random.setstate((p[0], tuple(p[1]), p[2]))


def save(path: str | Path, payload: dict) -> Path:
    """Write ``payload`` atomically (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    torch.save(payload, tmp)
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return path


def load(path: str | Path) -> dict:
    """Load a checkpoint (weights only). ValueError (one line) when missing or corrupt."""
    path = Path(path)
    if path.is_dir():
        path = path / LATEST
    if not path.exists():
        raise ValueError(f"no checkpoint at {path}")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated file, wrong format, ...
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"checkpoint {path} cannot be read ({first[:120]})") from None
    if not isinstance(data, dict) or "actor_state_dict" not in data or "iteration" not in data:
        raise ValueError(f"checkpoint {path} is not a virl_quad training checkpoint")
    return data


def contract_payload(contract, spec) -> dict:
    """What a checkpoint records about how its policy's actions and observations are defined: the
    policy contract (metadata form) and the PD gains it was trained with."""
    return {**contract.to_metadata(), "kp": [float(v) for v in spec.kp],   # N·m/rad
            "kd": [float(v) for v in spec.kd]}                             # N·m·s/rad


def contract_of(data: dict, robot: str):
    """The :class:`~virl_quad.policy.PolicyContract` a checkpoint's policy was trained with.

    ValueError (one line) when the checkpoint does not record it (an older version), or when the
    robot's control period or PD gains have changed since: its actions would mean other torques."""
    from virl_quad import robots
    from virl_quad.policy.contract import PolicyContract

    spec = robots.get(robot)
    saved = data.get("contract")
    if not isinstance(saved, dict):
        raise ValueError("checkpoint does not record its policy contract (action scale, clip, trajectory "
                         "generator, observation layout; an older version wrote it): train again")
    for key in ("kp", "kd"):
        want = np.asarray(getattr(spec, key), dtype=np.float64)
        if not np.allclose(np.asarray(saved.get(key, np.nan), dtype=np.float64), want, atol=1e-9):
            raise ValueError(f"checkpoint was trained with {key} {saved.get(key)}, but {robot} now has "
                             f"{want.tolist()}: its actions would mean other torques; train again")
    try:
        return PolicyContract.from_metadata(saved, spec)
    except ValueError as e:
        raise ValueError(f"checkpoint: {e}; train again") from None


def load_reward_model(run_dir: str | Path):
    """A run's distance model with its demonstration: ``(reward model, Demonstration, clips, robot)``.

    ValueError (one line) when the run has no checkpoint or no learned distance (oracle)."""
    from virl_quad import demo as demo_lib
    from virl_quad.reward.reward import from_state_dict

    run_dir = Path(run_dir)
    data = load(run_dir)
    d = data.get("reward", {})
    if "net" not in d:
        raise ValueError(f"{run_dir}: this run has no learned distance model (oracle reward?)")
    clips = [c.numpy() for c in d["clips"]]
    rm = from_state_dict(d)
    robot = data["config"]["robot"]
    return rm, demo_lib.load(str(run_dir / "demo.npz"), robot), clips, robot
