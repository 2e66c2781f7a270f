"""Fixtures shared by the test files."""

import pytest

from baseparams import registry


@pytest.fixture
def registered():
    """Register plugins at run time, then forget them (the registry is shared by all tests)."""
    pm = registry.plugin_manager()
    added = []

    def register(plugin):
        pm.register(plugin)
        added.append(plugin)
        registry.reset()

    yield register
    for plugin in added:
        pm.unregister(plugin)
    registry.reset()
