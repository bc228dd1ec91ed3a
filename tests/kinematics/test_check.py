"""The robot consistency check: passes on the project robots, fails on broken URDFs, clean CLI."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import pytest

from virl_quad import robots
from virl_quad.check import main
from virl_quad.kinematics.checks import run_checks

PUPPER = robots.get("pupper")


def _by_name(report):
    return {r.name: r for r in report.results}


@pytest.mark.parametrize("name", ["pupper", "laikago"])
def test_checks_pass(name):
    report = run_checks(robots.get(name), samples=30)
    failed = [(r.name, r.figures, r.details) for r in report.results if not r.ok]
    assert report.ok, failed
    names = _by_name(report)
    assert "FK feet Pinocchio vs PyBullet" in names
    assert len(report.mapping) == 12
    if name == "laikago":  # limits come from the limits URDF, and the check says so
        limits = names["joint limits vs spec"].figures
        assert "laikago_toes_limits.urdf" in limits and "continuous" in limits
        assert all(row["nq"] == 2 for row in report.mapping)


def test_main_function_call(capsys):
    assert main(["--robot", "pupper", "--samples", "10"]) == 0
    out = capsys.readouterr().out
    assert "FK feet Pinocchio vs PyBullet" in out and "FAIL" not in out


def test_cli_exit_codes():
    ok = subprocess.run([sys.executable, "-m", "virl_quad.check", "--robot", "all", "--samples", "20"],
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    fk_rows = [line for line in ok.stdout.splitlines() if "FK feet Pinocchio vs PyBullet" in line]
    assert len(fk_rows) == 2 and all("PASS" in r and re.search(r"max error \S+ m", r) for r in fk_rows)

    bad = subprocess.run([sys.executable, "-m", "virl_quad.check", "--robot", "dog"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    err = bad.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert "dog" in err and "pupper, laikago, all" in err


def _broken_pupper(tmp_path: Path, old: str, new: str):
    text = Path(PUPPER.urdf_path).read_text()
    assert text.count(old) >= 1, old
    path = tmp_path / "pupper_broken.urdf"
    path.write_text(text.replace(old, new, 1))
    return dataclasses.replace(PUPPER, urdf=str(path))


def test_fails_on_wrong_mass(tmp_path):
    spec = _broken_pupper(tmp_path, '<mass value="0.991"/>', '<mass value="1.091"/>')
    report = run_checks(spec, samples=5)
    assert not report.ok
    mass = _by_name(report)["total mass vs spec"]
    assert not mass.ok and "2.2350" in mass.figures
    assert _by_name(report)["FK feet Pinocchio vs PyBullet"].ok  # the rest is unaffected


def test_fails_on_moved_joint_origin(tmp_path):
    # FR knee 2 cm lower: the FR foot sinks into the ground in the default pose
    old = '<child link="FR_lower_leg"/>\n    <origin xyz="0 0 -0.08"/>'
    spec = _broken_pupper(tmp_path, old, old.replace("-0.08", "-0.10"))
    report = run_checks(spec, samples=5)
    feet = _by_name(report)["feet on the ground at default pose"]
    assert not feet.ok and not report.ok
    assert re.search(r"FR -1\d\.\d\d mm", feet.figures), feet.figures


def test_fails_on_invalid_inertia(tmp_path):
    # base izz far above ixx + iyy: positive definite but physically impossible
    spec = _broken_pupper(tmp_path, 'izz="7.116701e-03"', 'izz="9.0e-03"')
    results = _by_name(run_checks(spec, samples=5))
    assert not results["inertias valid (URDF numbers)"].ok
    assert not results["inertias valid (Pinocchio)"].ok
    assert any("base_link" in d for d in results["inertias valid (URDF numbers)"].details)


def test_fails_on_limit_mismatch(tmp_path):
    spec = _broken_pupper(tmp_path, 'lower="-2.6" upper="-0.2"', 'lower="-2.5" upper="-0.2"')
    limits = _by_name(run_checks(spec, samples=5))["joint limits vs spec"]
    assert not limits.ok and limits.details


def test_unloadable_urdf_is_a_fail_row(tmp_path):
    spec = _broken_pupper(tmp_path, 'name="FR_knee_joint"', 'name="FR_knee_renamed"')
    report = run_checks(spec, samples=5)
    assert not report.ok and len(report.results) == 1
    assert "FR_knee_joint" in report.results[0].figures
