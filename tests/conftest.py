"""Fixtures shared by the test files."""

import pytest

from baseparams import registry


@pytest.fixture(autouse=True)
def _no_progress_lines(monkeypatch):
    """The command line's progress lines start after Progress.AFTER (2 s) of wall time: on a
    loaded machine (issue 46: load 8-12 on 2 cores) a quick command took longer and its
    progress landed in the stderr a test reads (one `error:` line, warnings in order). No
    test of the verbs' output depends on wall time then; the tests of progress itself set
    AFTER as they need (tests/test_cli_grammar.py). Commands run as subprocesses are
    unaffected: those tests pass --quiet or read stdout only."""
    from baseparams.cli.options import Progress
    monkeypatch.setattr(Progress, "AFTER", 1e6)            # 11 days: never (inf overflows a Timer)


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
