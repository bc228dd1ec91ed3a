"""Env workers as Ray actors on a real local Ray cluster (2 CPUs): the same results as local
worker processes for the same seed, and a killed actor is one clear error (in the vector env,
and at the training command: one line, exit 2, a checkpoint on disk)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from virl_quad.envs.vec_env import EnvWorkerLost, QuadrupedVecEnv
from virl_quad.training import checkpoint

ray = pytest.importorskip("ray", reason='Ray workers need the cluster extra: pip install -e ".[cluster]"')
from virl_quad.envs.ray_workers import NAMESPACE  # noqa: E402  (after the skip: imports nothing of Ray itself)


@pytest.fixture(scope="module")
def cluster():
    """A local Ray cluster of 2 CPUs, shared by this module's tests; its address."""
    ray.init(num_cpus=2, namespace=NAMESPACE, include_dashboard=False, log_to_driver=False)
    try:
        yield ray.get_runtime_context().gcs_address
    finally:
        ray.shutdown()


def _trace(kind: str, steps: int = 30) -> list[tuple]:
    """Observations, rewards and dones of a fixed action sequence (episodes end and reset inside)."""
    from virl_quad import demo as demo_lib

    env = QuadrupedVecEnv("pupper", 3, num_workers=2, seed=5, episode_seconds=0.2, oracle_reward=True,
                          demo=demo_lib.load("trot", "pupper"), workers_kind=kind)
    rng = np.random.default_rng(0)
    try:
        out = [({k: v.clone() for k, v in env.get_observations().items()}, None, None)]
        for _ in range(steps):
            a = torch.from_numpy(rng.uniform(-0.5, 0.5, (3, env.num_actions))).float()
            obs, rew, done, extras = env.step(a)
            out.append(({k: v.clone() for k, v in obs.items()}, rew.clone(), done.clone()))
    finally:
        env.close()
    return out


def test_same_seed_same_results_as_local_workers(cluster) -> None:
    local, remote = _trace("local"), _trace("ray")
    assert any(bool(d.any()) for _, _, d in local[1:]), "the trace must cross an episode end"
    for (o1, r1, d1), (o2, r2, d2) in zip(local, remote):
        assert o1.keys() == o2.keys()
        for k in o1.keys():
            assert torch.equal(o1[k], o2[k]), k
        if r1 is not None:
            assert torch.equal(r1, r2) and torch.equal(d1, d2)
    assert float(local[-1][1].abs().sum()) > 0     # the oracle reward: numbers that could differ


def test_a_killed_actor_is_one_clear_error(cluster) -> None:
    env = QuadrupedVecEnv("pupper", 2, num_workers=2, seed=0, episode_seconds=1.0, render=False,
                          workers_kind="ray", actor_prefix="killed-")
    try:
        env.step(torch.zeros(2, env.num_actions))
        ray.kill(ray.get_actor("killed-env-1", namespace=NAMESPACE))
        with pytest.raises(EnvWorkerLost, match=r"^env worker 1 \(Ray actor killed-env-1\) was lost") as info:
            for _ in range(50):                       # the kill lands within a few steps
                env.step(torch.zeros(2, env.num_actions))
        assert "\n" not in str(info.value)
    finally:
        env.close()


def test_train_exits_2_with_a_checkpoint_when_an_actor_dies(cluster, tmp_path: Path, wait_for_checkpoint) -> None:
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "virl_quad.train", "--robot", "pupper", "--reward", "oracle", "--iterations", "500",
           "--num-envs", "2", "--num-workers", "2", "--steps-per-env", "8", "--eval-episodes", "1",
           "--eval-seconds", "0.5", "--eval-every", "0", "--no-video", "--save-every", "1",
           "--warm-start-rounds", "0", "--critic-warmup", "0", "--prior-from", "motion",
           "--workers", "ray", "--ray-address", cluster, "--run-dir", str(run_dir)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_checkpoint(proc, run_dir, 2)
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        ray.kill(ray.get_actor(f"run-{proc.pid}-env-0", namespace=NAMESPACE))
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 2, (out[-1500:], err[-1500:])
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err[-3000:]
    assert err.startswith("error: env worker 0 (Ray actor run-") and f"--resume {run_dir}" in err, err
    assert checkpoint.load(run_dir)["iteration"] >= 2


def test_worker_kinds_match_the_training_options() -> None:
    """The training options list the backends the vector env has (kept apart so that the
    options module does not load the simulator)."""
    from virl_quad.envs.vec_env import WORKER_KINDS
    from virl_quad.training.config import WORKER_KINDS as OPTION_KINDS

    assert WORKER_KINDS == OPTION_KINDS
