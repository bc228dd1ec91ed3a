"""Shared fixtures for the deployment tests. The project runs pytest with --import-mode=importlib,
so test modules cannot import each other: the helper modules beside them are loaded here by path,
``harness.py`` (real HAL and server processes) as ``hil_harness`` before any test module imports it."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

from virl_quad import robots


def _load(name: str, filename: str) -> ModuleType:
    """The module in ``filename`` beside this file, registered in sys.modules as ``name``."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(filename))
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


_load("hil_harness", "harness.py")


@pytest.fixture(params=["pupper", "laikago"])
def spec(request):
    """Each robot's spec."""
    return robots.get(request.param)


@pytest.fixture
def pupper():
    """The Pupper spec."""
    return robots.get("pupper")


@pytest.fixture(scope="session")
def fuzzing() -> ModuleType:
    """``tests/deploy/fuzzing.py`` (the message Fuzzer shared by the fuzz tests), loaded by path."""
    return _load("virl_quad_tests_deploy_fuzzing", "fuzzing.py")
