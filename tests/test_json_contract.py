"""The ``solve --format json`` contract of docs/cli.md, read from the page itself: every
built-in solver prints exactly the documented keys on an open chain and on a closed loop,
with ``null`` exactly where the page says so; the exact solver's documented answer on a
loop is "not applicable" (exit 2). Also: ``solve --help`` lists every registered solver, and
the page's ``baseparams list`` example names every registered mechanism.
"""

import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main

CLI_MD = Path(__file__).resolve().parent.parent / "docs" / "cli.md"
SOLVERS = ("dp", "vp", "exact", "symbolic")
MECHANISMS = ("pendulum", "four_bar")


def _section(text: str, start: str, end: str) -> str:
    return text[text.index(start):text.index(end, text.index(start))]


def documented_keys() -> dict:
    """key -> the solvers for which the page says it is ``null`` (from the key table)."""
    table = _section(CLI_MD.read_text(encoding="utf-8"), "Every solver emits every key below",
                     "and one key only when it is true")
    out = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2 or not cells[0].startswith("`"):
            continue
        keys = re.findall(r"`([a-z_]+)`", cells[0])
        value = "|".join(cells[1:])
        nulls = set()
        match = re.search(r"`null` for (.*)", value)
        if match:
            named = set(re.findall(r"\b(dp|vp|exact|symbolic)\b", match[1]))
            if "the others" in match[1]:
                # "symbolic: the exact values ...; `null` for the others": the solvers named
                # before a colon are the ones the key is for
                before = set(re.findall(r"\b(dp|vp|exact|symbolic):", value[:match.start()]))
                named |= set(SOLVERS) - before
            nulls = named
        for key in keys:
            out[key] = nulls
    return out


OPTIONAL = {"rank_is_upper_bound"}       # documented: present only when true


@pytest.fixture(scope="module")
def outputs():
    runner = CliRunner()
    runs = {}
    for solver in SOLVERS:
        for mech in MECHANISMS:
            result = runner.invoke(main, ["solve", mech, "--solver", solver, "--format", "json"])
            runs[(solver, mech)] = result
    return runs


def test_the_page_documents_the_keys():
    keys = documented_keys()
    assert {"mechanism", "solver", "parameters", "rank", "base", "eliminated", "certified", "digits",
            "singular_values", "expression_values", "geometry", "warnings", "diagnostics",
            "elapsed_s"} == set(keys)
    assert keys["digits"] == {"dp", "exact", "symbolic"}
    assert keys["singular_values"] == {"exact", "symbolic"}
    assert keys["expression_values"] == {"dp", "vp", "exact"}


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("mech", MECHANISMS)
def test_solve_json_has_the_documented_keys(outputs, solver, mech):
    result = outputs[(solver, mech)]
    if solver == "exact" and mech == "four_bar":
        # documented: a solver that does not take the mechanism says why, exit code 2
        assert result.exit_code == 2 and result.stdout == ""
        assert "solver 'exact' is not applicable" in result.stderr and "closed loop" in result.stderr
        return
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    keys = documented_keys()
    assert set(keys) <= set(data), f"missing: {set(keys) - set(data)}"
    assert set(data) - set(keys) <= OPTIONAL, f"undocumented: {set(data) - set(keys) - OPTIONAL}"
    for key, nulls in keys.items():
        assert (data[key] is None) == (solver in nulls), (key, data[key])
    assert data["solver"] == solver and data["mechanism"] == mech
    assert data["rank"] == len(data["base"]) and isinstance(data["certified"], bool)
    assert set(data["eliminated"]) <= set(data["parameters"])
    assert isinstance(data["warnings"], list) and isinstance(data["diagnostics"]["summary"], list)
    for base in data["base"]:
        # a coefficient is a string (exact, or symbolic) or a number with its decimal beside it
        assert set(base) == {"name", "expression", "decimals"}
        numbers = {p for p, v in base["expression"].items() if not isinstance(v, str)}
        assert all(isinstance(base["expression"][p], float) for p in numbers) and set(base["decimals"]) == numbers
    if data["singular_values"] is not None:
        values = [float(v) for v in data["singular_values"]]
        assert values == sorted(values, reverse=True)
    if data.get("rank_is_upper_bound") is not None:
        assert data["rank_is_upper_bound"] is True


def test_the_solvers_agree_on_the_rank(outputs):
    """Not the contract's business, but a free independent check on the same runs."""
    for mech in MECHANISMS:
        ranks = {s: json.loads(outputs[(s, mech)].stdout)["rank"] for s in SOLVERS
                 if outputs[(s, mech)].exit_code == 0}
        assert len(set(ranks.values())) == 1, ranks


def test_solve_help_lists_every_registered_solver():
    text = CliRunner().invoke(main, ["solve", "--help"]).stdout
    for name in registry.solvers():
        assert re.search(rf"^\s+{re.escape(name)}\s", text, re.M), name


def test_the_pages_lists_match_the_registry():
    text = CLI_MD.read_text(encoding="utf-8")
    listing = _section(text, "$ baseparams list", "```\n\nColumns")
    names = re.findall(r"^([a-z0-9_]+)\s+baseparams\s", listing, re.M)
    assert names == list(registry.mechanisms())
    builtin = re.search(r"built in: ([^)]*)\)", text)[1]
    assert set(re.findall(r"`([a-z]+)`", builtin)) == {n for n, r in registry.solvers().items()
                                                       if r.distribution == "baseparams"}
    count = re.search(r"^mechanisms \((\d+)\):", text, re.M)[1]
    assert int(count) == len(registry.mechanisms())
