"""The project's own cross-solver consistency, through the orchestrator: every registered
mechanism, every registered solver, every check of ``baseparams validate``.

A failure prints the validation report (the failed checks with their evidence). The jobs
of each mechanism run in two worker processes, as on the 2-core CI machine.
"""

import pytest

from baseparams import registry
from baseparams.io.loader import resolve
from baseparams.orchestrate.runners import Processes
from baseparams.orchestrate.validate import mechanism_texts, render_text, validate


@pytest.mark.parametrize("name", sorted(registry.mechanisms()))
def test_every_solver_agrees_on(name):
    report = validate(mechanism_texts([name]), runner=Processes(2))      # two cores
    assert report.ok, render_text(report)
    row = report.mechanisms[0].solvers
    applicable = [s for s, r in row.items() if r["status"] == "ok"]
    # the symbolic solver declines couplings between joint coordinates (its transfer rules
    # assume free joints, and it says so): parallelogram_arm's counterweight (issue 49)
    coupled = bool(resolve(name).couplings)
    certifying = ("vp",) if coupled else ("vp", "symbolic")
    assert {"dp", *certifying} <= set(applicable)
    assert all(row[s]["certified"] for s in certifying)
    assert len({row[s]["rank"] for s in applicable}) == 1
