"""pytest plugin (entry point ``pytest11``): ``baseparams_validate`` for third parties' tests.

A distribution that adds joint types, transfer rules or solvers checks them against the
built-ins in one line::

    def test_my_joint(baseparams_validate):
        baseparams_validate("mechanisms/collar.toml")          # a path or a registered name

The fixture runs ``baseparams validate`` in-process on the mechanism (every registered
solver, or ``solvers=[...]``) and fails the test with the validation report when any check
fails; it returns the :class:`~baseparams.orchestrate.validate.Report` otherwise.
"""

from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from baseparams.orchestrate.validate import Report, mechanism_texts, render_text, validate


def assert_validates(mechanism: str | Path, solvers: Sequence[str] | None = None,
                     timeout: float | None = None) -> Report:
    """Validate one mechanism (registered name, file path, or a Mechanism read from a file);
    ``pytest.fail`` with the report unless every check passes."""
    source = getattr(mechanism, "path", None) or mechanism
    report = validate(mechanism_texts([str(source)]), solvers, timeout=timeout)
    if not report.ok:
        pytest.fail("baseparams validate found a disagreement:\n" + render_text(report), pytrace=False)
    return report


@pytest.fixture
def baseparams_validate() -> Callable[..., Report]:
    """``baseparams_validate(mechanism_or_path, solvers=None, timeout=None)``: see the module."""
    return assert_validates
