"""The project's own cross-solver consistency, through the orchestrator: every registered
mechanism, every registered solver, every check of ``baseparams validate``.

A failure prints the validation report (the failed checks with their evidence). The jobs
of each mechanism run in two worker processes, as on the 2-core CI machine.
"""

import pytest

from baseparams import registry
from baseparams.orchestrate.runners import Processes
from baseparams.orchestrate.validate import mechanism_texts, render_text, validate


@pytest.mark.parametrize("name", sorted(registry.mechanisms()))
def test_every_solver_agrees_on(name):
    report = validate(mechanism_texts([name]), runner=Processes(2))      # two cores
    assert report.ok, render_text(report)
    row = report.mechanisms[0].solvers
    applicable = [s for s, r in row.items() if r["status"] == "ok"]
    assert {"dp", "vp", "symbolic"} <= set(applicable)
    assert all(row[s]["certified"] for s in ("vp", "symbolic"))
    assert len({row[s]["rank"] for s in applicable}) == 1
