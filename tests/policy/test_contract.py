"""The policy contract in the exported metadata: written by the export, refused at load when it lacks
or contradicts its trajectory generator (one line; at the CLIs one ``error:`` line, exit code 2), and
the robot side that reads it imports no simulator."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from virl_quad import robots
from virl_quad.motion.gaits import gait_params
from virl_quad.export import default_contract, export_actor, fresh_actor
from virl_quad.policy import PolicyContract
from virl_quad.policy_io import load_policy
from virl_quad.training.prior import gait_tg

ROOT = Path(__file__).resolve().parents[2]
SPEC = robots.get("pupper")
TG = gait_tg(SPEC, gait_params("pupper", "trot"))


@pytest.fixture(scope="module")
def tg_policy(tmp_path_factory) -> Path:
    """An untrained Pupper policy with the built-in trot's TG (48 observations, 14 actions)."""
    contract = default_contract("pupper", tg=TG)
    out = tmp_path_factory.mktemp("tg_policy") / "tg.pt"
    return export_actor(fresh_actor(contract, seed=2), "pupper", out, contract, demo={"source": "trot"})


def _meta(path: Path) -> dict:
    return json.loads(path.with_suffix(".json").read_text())


def _write(path: Path, meta: dict, tmp_path: Path, name: str = "bad") -> Path:
    bad = tmp_path / f"{name}.pt"
    bad.write_bytes(path.read_bytes())
    bad.with_suffix(".json").write_text(json.dumps(meta))
    return bad


def test_tg_policy_round_trips(tg_policy: Path) -> None:
    policy = load_policy(tg_policy)
    assert policy.contract.tg == TG and policy.action_size == 14 and policy.obs_size == 48
    meta = _meta(tg_policy)
    assert meta["tg"] == TG.to_dict() and meta["action_size"] == 14 and meta["tg_modulation"]["gain"] == 0.5
    a = policy.act(np.zeros(48, np.float32))
    assert a.shape == (14,)
    for contract in (default_contract("pupper"), default_contract("pupper", demo_frames=40),
                     default_contract("pupper", tg=TG)):
        assert PolicyContract.from_metadata(json.loads(json.dumps(contract.to_metadata())), SPEC) == contract


def _refusals(meta: dict) -> list[tuple[str, dict]]:
    """(expected message part, metadata) for each way to lack or contradict the TG."""
    no_tg = {k: v for k, v in meta.items() if k != "tg"}
    bad_duty = dict(meta, tg=dict(meta["tg"], duty=1.5))
    far = dict(meta, tg=dict(meta["tg"], stance_height=0.3))
    layout12 = default_contract("pupper", demo_frames=25).to_metadata()["observation"]
    return [
        ("lacks its trajectory generator", no_tg),                                   # 14 actions, no TG
        ("lacks its trajectory generator", dict(no_tg, action_size=12)),            # layout: 14 last actions
        ("lacks its trajectory generator ('tg') or phase clock",                     # a phase, no clock
         dict(no_tg, action_size=12, observation=layout12)),
        ("'duty'", bad_duty),                                                         # bad value
        ("reach", far),                                                               # out of the leg's reach
        ("but 12 actions", dict(meta, action_size=12, observation=layout12)),       # wrong action size for a TG
        ("contradicts", dict(meta, action_size=12)),
        ("modulation", dict(meta, tg_modulation={"gain": 1.0, "frequency_scale": [0.5, 1.5],
                                                 "amplitude_scale": [0.0, 1.5]})),
        ("phase clock", dict(meta, phase_hz=2.0)),                                    # two clocks
        ("layout differs", dict(meta, observation=dict(meta["observation"], size=47))),
        ("unknown TG field", dict(meta, tg=dict(meta["tg"], speed=0.3))),
    ]


def test_lacking_or_contradicting_tg_is_refused_with_one_line(tg_policy: Path, tmp_path: Path) -> None:
    meta = _meta(tg_policy)
    for i, (part, bad) in enumerate(_refusals(meta)):
        with pytest.raises(ValueError) as info:
            PolicyContract.from_metadata(bad, SPEC)
        assert part in str(info.value) and "\n" not in str(info.value), (part, str(info.value))
        with pytest.raises(ValueError, match="policy") as info:        # the same through the loader
            load_policy(_write(tg_policy, bad, tmp_path, f"bad{i}"))
        assert part in str(info.value) and "\n" not in str(info.value)


def _cli(module: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=180)


def test_serve_and_evaluate_refuse_a_bad_tg_in_one_line(tg_policy: Path, tmp_path: Path) -> None:
    meta = _meta(tg_policy)
    missing = _write(tg_policy, {k: v for k, v in meta.items() if k != "tg"}, tmp_path, "missing")
    contradicting = _write(tg_policy, dict(meta, tg=dict(meta["tg"], frequency=-2.0)), tmp_path, "contra")
    for bad, word in ((missing, "lacks its trajectory generator"), (contradicting, "frequency")):
        for module, args in (("virl_quad.deploy.serve", ["--policy", str(bad), "--wait", "1", "--quiet"]),
                             ("virl_quad.evaluate", ["--policy", str(bad), "--episodes", "1"])):
            r = _cli(module, *args)
            lines = r.stderr.strip().splitlines()
            assert r.returncode == 2 and len(lines) == 1, (module, r.stderr)
            assert lines[0].startswith("error: ") and word in lines[0] and "Traceback" not in r.stderr


def test_the_robot_side_imports_no_simulator(tg_policy: Path) -> None:
    """The policy package imports numpy and the robot spec only; the policy server loads a TG policy
    and answers a state without PyBullet, Gymnasium, Pinocchio or SciPy in the process."""
    code = f"""
import sys
import virl_quad.policy
assert not {{'torch', 'scipy', 'pinocchio', 'pybullet', 'gymnasium'}} & set(sys.modules), sorted(sys.modules)
import virl_quad.deploy.serve as serve
from virl_quad.deploy import protocol as P
from virl_quad import robots
runner = serve.PolicyRunner(serve.load({str(tg_policy)!r}))
out, reason = runner.handle(P.encode_state(P.RobotState.standing(robots.get('pupper')), 1, active=True))
assert out is not None and reason == '', reason
heavy = {{'pybullet', 'gymnasium', 'pinocchio', 'scipy'}} & set(sys.modules)
assert not heavy, heavy
print('ok')
"""
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr
