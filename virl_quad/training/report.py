"""A run's artefacts: its log, ``report.json``, the alignment curve and a side-by-side video
(demonstration | agent)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from virl_quad.demo.demonstration import Demonstration
from virl_quad.envs import make

SCALE = 5  # 48 px frames are shown at 240 px


def _gray_to_bgr(frame: np.ndarray, size: int) -> np.ndarray:
    big = cv2.resize(frame, (size, size), interpolation=cv2.INTER_NEAREST)
    return cv2.cvtColor(big, cv2.COLOR_GRAY2BGR)


def side_by_side_video(policy: Callable[[dict], np.ndarray], robot: str, demo: Demonstration,
                       path: str | Path, seconds: float = 6.0, seed: int = 0, **env_overrides) -> Path:
    """Write an .mp4: the demonstration frame | the agent's 48x48 frame | the agent's RGB preview.

    ``env_overrides``: EnvConfig fields (e.g. the policy's ``action_scale`` and ``action_clip``)."""
    env = make(robot, demo=demo, randomize=False, time_limit=False, **env_overrides)
    obs, _ = env.reset(seed=seed, options={"demo_step": 0})
    size = 48 * SCALE
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.mp4")
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), env.unwrapped.robot.control_hz,
                             (3 * size, size))
    if not writer.isOpened():
        raise RuntimeError(f"OpenCV cannot write {path}")
    try:
        for _ in range(int(seconds * env.unwrapped.robot.control_hz)):
            rgb = cv2.resize(env.render(), (size, size), interpolation=cv2.INTER_AREA)[..., ::-1]
            frame = np.hstack([_gray_to_bgr(obs["expert_image"], size), _gray_to_bgr(obs["agent_image"], size),
                               np.ascontiguousarray(rgb)])
            cv2.putText(frame, "demonstration", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1)
            cv2.putText(frame, "agent", (size + 6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1)
            writer.write(frame)
            obs, _, terminated, _, _ = env.step(policy(obs))
            if terminated:
                obs, _ = env.reset(options={"demo_step": env.unwrapped.demo_step})
    finally:
        writer.release()
        env.close()
    os.replace(tmp, path)
    return path


def write_report(path: str | Path, report: dict) -> Path:
    """Write ``report.json`` atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(report, indent=2, default=_jsonable))
    os.replace(tmp, path)
    return path


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


class RunLog:
    """Progress lines on stdout and appended to the run's ``train.log``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __call__(self, line: str) -> None:
        """Print ``line`` and append it to the log file."""
        print(line, flush=True)
        with open(self.path, "a") as f:
            f.write(line + "\n")


def alignment_curve(path: Path) -> list[list[float]]:
    """[[iteration, env steps, rank correlation], ...] of the run's evaluations that probed it."""
    if not path.exists():
        return []
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [[r["iteration"], r.get("env_steps", 0), r["reward_alignment"]] for r in rows if "reward_alignment" in r]
