"""Shared fixtures for the deployment tests (helpers live in each test module: the
project runs pytest with --import-mode=importlib, so test modules cannot import each other)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

from virl_quad import robots


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
    name = "virl_quad_tests_deploy_fuzzing"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("fuzzing.py"))
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]
