"""Shared fixtures for the deployment tests (helpers live in each test module: the
project runs pytest with --import-mode=importlib, so test modules cannot import each other)."""

from __future__ import annotations

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
