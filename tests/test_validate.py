"""The orchestrator: every solver on every mechanism, cross-checked (``baseparams validate``).

Wrong plugins are injected at run time (a solver that drops a base parameter, one that
changes a coefficient, a transfer rule that does not hold) and must be caught by the check
that names them; runners (in-process, worker processes, a Dask LocalCluster) must give the
same report, timings apart.
"""

import copy
import json
import os
import time
from fractions import Fraction

import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.hookspecs import hookimpl
from baseparams.model import generate
from baseparams.model.multipoles import TransferRule
from baseparams.orchestrate.jobs import DIED, MISSING_PLUGIN, NOT_APPLICABLE, TIMEOUT, Job, run_job
from baseparams.orchestrate.runners import DaskCluster, InProcess, Processes
from baseparams.orchestrate.validate import mechanism_texts, render_text, validate
from baseparams.solvers.protocol import Capabilities

FAST = ["pendulum", "planar_2r", "four_bar"]


def strip_timings(data):
    """The report's JSON without the seconds (they differ from run to run)."""
    data = copy.deepcopy(data)
    for m in data["mechanisms"]:
        for row in m["solvers"].values():
            row.pop("seconds", None)
    return data


@pytest.fixture(scope="module")
def fast_report():
    return validate(mechanism_texts(FAST), ["dp", "exact", "vp"])


def test_built_ins_agree_and_exact_is_not_applicable_to_a_loop(fast_report):
    data = fast_report.to_json()
    assert data["ok"] is True
    assert [m["name"] for m in data["mechanisms"]] == FAST
    four_bar = data["mechanisms"][2]
    assert four_bar["solvers"]["exact"]["status"] == NOT_APPLICABLE
    assert "closed loop" in four_bar["solvers"]["exact"]["verdict"]
    assert {four_bar["solvers"][s]["rank"] for s in ("dp", "vp")} == {8}
    names = {c["name"] for c in data["mechanisms"][1]["checks"]}
    assert {"energy balance", "transfer rules of R", "ranks", "space exact = vp", "space exact ~ dp"} <= names
    assert all(c["ok"] for m in data["mechanisms"] for c in m["checks"])


def test_the_cli_prints_the_table_and_exits_0(tmp_path):
    result = CliRunner().invoke(main, ["validate", "pendulum", "--solver", "dp", "--solver", "exact", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "all agree: 1 mechanism(s), 2 solver(s)" in result.output
    result = CliRunner().invoke(main, ["validate", "pendulum", "--solver", "dp", "--format", "markdown"])
    assert result.exit_code == 0 and result.stdout.startswith("| mechanism | dp | checks |")


def test_bad_input_exits_2(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text(generate.serial_chain(101, bodies=3).replace('type = "R"', 'type = "Q"', 1)
                      .replace('type = "P"', 'type = "Q"', 1))
    result = CliRunner().invoke(main, ["validate", str(broken)])
    assert result.exit_code == 2 and "unknown joint type 'Q'" in result.output, result.output
    runner = CliRunner()
    for args in (["validate"], ["validate", "no_such_mechanism"], ["validate", "pendulum", "--solvers", "nope"],
                 ["validate", "--all", "pendulum"]):
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert "Traceback" not in result.output


class DroppingSolver:
    """Wrong on purpose: dp's result with its last base parameter dropped, no warning."""
    name = "dropper"
    description = "drops a base parameter (test)"
    capabilities = Capabilities(closed_loops=True)
    options = ()

    def applicable(self, mechanism):
        return None

    def solve(self, mechanism, progress=None, **options):
        result = registry.solvers()["dp"].item.solve(mechanism)
        result.rank -= 1
        result.base = result.base[:-1]
        result.warnings = []
        return result


class ChangingSolver:
    """Wrong on purpose: exact's result with one coefficient changed (same rank)."""
    name = "changer"
    description = "changes a coefficient (test)"
    capabilities = Capabilities(exact_coefficients=True, certifies=True)
    options = ()

    def applicable(self, mechanism):
        return registry.solvers()["exact"].item.applicable(mechanism)

    def solve(self, mechanism, progress=None, **options):
        result = registry.solvers()["exact"].item.solve(mechanism)
        row = next(b for b in result.base if len(b["expression"]) > 1)
        param = next(p for p, v in row["expression"].items() if v != "1")
        row["expression"][param] = str(Fraction(row["expression"][param]) + 1)
        return result


class WrongSolvers:
    @hookimpl
    def baseparams_solvers(self):
        return [DroppingSolver(), ChangingSolver()]


def test_a_wrong_solver_is_caught_by_name(registered):
    registered(WrongSolvers())
    report = validate(mechanism_texts(["planar_2r"]), ["exact", "dropper", "changer"])
    assert not report.ok
    failed = {c.name: c.detail for c in report.mechanisms[0].checks if not c.ok}
    assert "rank dropper" in failed and "dropper gives rank 5, exact gives 6" in failed["rank dropper"]
    assert "space exact = changer" in failed and "DIFFERENT" in failed["space exact = changer"]
    verdicts = {s: row["verdict"] for s, row in report.mechanisms[0].solvers.items()}
    assert verdicts == {"exact": "agrees", "dropper": "disagrees", "changer": "disagrees"}
    result = CliRunner().invoke(main, ["validate", "planar_2r", "--solvers", "exact,changer", "--quiet"])
    assert result.exit_code == 1
    assert "FAILED checks:" in result.output and "space exact = changer" in result.output


class WrongRule:
    """Claims that a dipole perpendicular to a revolute axis crosses the joint: false."""
    @hookimpl(tryfirst=True)
    def baseparams_transfer_rules(self, joint_type):
        if joint_type != "R":
            return None
        return [TransferRule("dipole", (0, 0, 0), (1, 0, 0), 4)]


def test_a_wrong_transfer_rule_is_caught(registered):
    registered(WrongRule())
    report = validate(mechanism_texts(["planar_2r"]), ["exact"])
    failed = {c.name: c.detail for c in report.mechanisms[0].checks if not c.ok}
    assert "transfer rules of R" in failed
    assert "NOT null directions of W" in failed["transfer rules of R"]


class SlowSolver:
    name = "sleeper"
    description = "sleeps (test)"
    capabilities = Capabilities(closed_loops=True)
    options = ()

    def applicable(self, mechanism):
        return None

    def solve(self, mechanism, progress=None, **options):
        time.sleep(600)


class DyingSolver(SlowSolver):
    name = "dier"

    def solve(self, mechanism, progress=None, **options):
        os._exit(7)


class OddSolvers:
    @hookimpl
    def baseparams_solvers(self):
        return [SlowSolver(), DyingSolver()]


def test_timeouts_and_deaths_are_reported_and_other_results_stay(registered):
    registered(OddSolvers())
    texts = mechanism_texts(["pendulum"])
    jobs = [Job(texts[0], "sleeper"), Job(texts[0], "dp"), Job(texts[0], "dier")]
    # the timeout is every job's: dp on the pendulum (0.1 s alone) must end within it on a
    # loaded machine too (2 s left it a few times its own time, issue 46), the sleeper (600 s) never does
    outcomes = Processes(2).run(jobs, timeout=10)
    assert [o.status for o in outcomes] == [TIMEOUT, "ok", DIED]
    assert outcomes[1].result["rank"] == 3
    assert "exit code 7" in outcomes[2].message
    assert InProcess().run(jobs[:1], timeout=1)[0].status == TIMEOUT


def test_worker_processes_give_the_in_process_report(fast_report):
    again = validate(mechanism_texts(FAST), ["dp", "exact", "vp"], runner=Processes(2))
    assert strip_timings(again.to_json()) == strip_timings(fast_report.to_json())


def test_a_dask_local_cluster_gives_the_in_process_report(fast_report):
    pytest.importorskip("dask.distributed")
    again = validate(mechanism_texts(FAST), ["dp", "exact", "vp"], runner=DaskCluster("local", 2))
    assert strip_timings(again.to_json()) == strip_timings(fast_report.to_json())


def test_a_worker_without_the_plugin_says_so(registered):
    """A solver registered only in this process is unknown to a fresh worker."""
    registered(OddSolvers())
    texts = mechanism_texts(["pendulum"])
    outcome = run_job(Job(texts[0], "not_installed_anywhere"))
    assert outcome.status == MISSING_PLUGIN and "not installed on this worker" in outcome.message


def test_generated_mechanisms_validate(tmp_path):
    """Mechanisms nobody tuned for: a random chain, a random tree and a random four-bar."""
    paths = []
    for name, text in (("chain", generate.serial_chain(101, bodies=4)), ("tree", generate.tree(202, bodies=4)),
                       ("loop", generate.four_bar(303))):
        paths.append(tmp_path / f"{name}.toml")
        paths[-1].write_text(text)
    report = validate(mechanism_texts([str(p) for p in paths]), ["dp", "exact", "vp"])
    assert report.ok, render_text(report)
    assert report.mechanisms[2].solvers["exact"]["status"] == NOT_APPLICABLE


def test_json_report_keys():
    result = CliRunner().invoke(main, ["validate", "pendulum", "--solver", "exact", "--format", "json"])
    data = json.loads(result.stdout)
    assert set(data) >= {"ok", "mechanisms"}
    m = data["mechanisms"][0]
    assert set(m) >= {"name", "ok", "solvers", "checks"}
    assert all(set(c) >= {"name", "ok", "detail"} for c in m["checks"])


def test_two_files_of_one_name_are_kept_apart(tmp_path):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "robot.toml").write_text(
            (registry.mechanisms()["pendulum"].item.path).read_text())
    texts = mechanism_texts([str(tmp_path / "a" / "robot.toml"), str(tmp_path / "b" / "robot.toml")])
    assert [t.name for t in texts] == ["robot", "robot#2"]


def test_a_solvers_error_names_the_source_file_not_the_workers_copy(tmp_path):
    text = open(registry.mechanisms()["pendulum"].item.path, encoding="utf-8").read()
    path = tmp_path / "no_trajectory.toml"
    path.write_text(text[:text.index("[trajectory]")])
    report = validate(mechanism_texts([str(path)]), ["dp"])
    outcome = report.mechanisms[0].solvers["dp"]
    assert outcome["status"] == "error" and str(path) in outcome["verdict"]
    details = [c.detail for c in report.mechanisms[0].checks]
    assert all("baseparams-job-" not in d for d in details + [outcome["verdict"]])
