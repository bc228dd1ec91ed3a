"""Every entry point answers --help (exit 0) and documents its options."""

from __future__ import annotations

import subprocess
import sys

import pytest

MODULES = ["virl_quad.train", "virl_quad.export", "virl_quad.evaluate", "virl_quad.check", "virl_quad.demo",
           "virl_quad.deploy.hal", "virl_quad.deploy.serve", "virl_quad.compare"]


@pytest.mark.parametrize("module", MODULES)
def test_help(module: str) -> None:
    p = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-1500:]
    assert "usage:" in p.stdout and "Traceback" not in p.stderr


def test_train_help_lists_every_option_with_its_meaning_by_concern() -> None:
    import dataclasses

    from virl_quad.cli import options
    from virl_quad.training.config import TrainArgs

    out = subprocess.run([sys.executable, "-m", "virl_quad.train", "--help"], capture_output=True, text=True,
                         timeout=120).stdout
    for name in options(TrainArgs()):
        assert "--" + name.replace("_", "-") in out, name
    assert "distance-model batch updates per iteration" in out
    for section in dataclasses.fields(TrainArgs):        # one group per concern, its options under it
        title = out.index(f"\n{section.name} (")
        first = dataclasses.fields(getattr(TrainArgs(), section.name))[0].name.replace("_", "-")
        assert out.index(f"--{first}", title) > title, section.name


def test_a_section_is_declared_by_its_type_and_each_instance_owns_its_own() -> None:
    from virl_quad.envs.config import EnvConfig
    from virl_quad.reward.config import OptimConfig, RewardConfig
    from virl_quad.training.config import TrainArgs

    a, b = RewardConfig(), RewardConfig()
    assert isinstance(a.optim, OptimConfig) and a.optim == OptimConfig()
    a.optim.lr = 5e-4
    assert b.optim.lr == OptimConfig().lr                 # not one shared default object
    assert TrainArgs().env is not TrainArgs().env
    assert EnvConfig().demo is None                       # a plain field keeps its own default
    assert RewardConfig.make(lr=3e-4).optim.lr == 3e-4
