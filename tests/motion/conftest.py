"""Every test here renders into the session's private cache, not the user's."""

import pytest


@pytest.fixture(autouse=True)
def _private_cache(private_cache) -> None:
    """See :func:`tests.conftest.private_cache`."""
