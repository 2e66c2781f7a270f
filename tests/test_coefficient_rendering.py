"""One rendering of coefficients (issue 45, docs/design.md "Results as JSON"): the same
strings in the text, the legend, the JSON (an exact one as its string, any other as a number
with its decimal under ``decimals``), the frame and the CSV; an exact value as its exact
string, any other decimal with exactly the digits the solver trusts. The JSON's numbers:
tests/test_coefficient_json.py."""

import csv
import io
import json
from fractions import Fraction

import pytest
from click.testing import CliRunner

import baseparams as bp
from baseparams.cli import main
from baseparams.model.expressions import exact_text
from baseparams.solvers.result import Coefficient, coefficient_text, entry_texts, expression_text, significant_digits

CASES = [("puma560", "dp"), ("puma560", "vp"), ("puma560", "exact"), ("planar_2r", "symbolic"),
         ("four_bar", "vp")]


@pytest.fixture(scope="module", params=CASES, ids=[f"{m}-{s}" for m, s in CASES])
def solved(request):
    mechanism, solver = request.param
    return bp.solve(mechanism, solver, solver_options={"samples": 40} if solver == "exact" else None)


def test_every_view_prints_the_same_strings(solved):
    base = solved.to_json()["base"]
    lines = [f"{b['name']} = {expression_text(entry_texts(b))}" for b in base]
    assert solved.legend() == lines
    assert [line.strip() for line in solved.to_text().splitlines()[1:1 + len(base)]] == lines
    assert [f"{r['name']} = {r['expression']}" for r in solved.rows()] == lines
    result = CliRunner().invoke(main, ["solve", solved.mechanism.name, "--solver", solved.result.solver,
                                       "--format", "csv", "--quiet"]
                                + (["--samples", "40"] if solved.result.solver == "exact" else []))
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(io.StringIO(result.stdout)))
    assert [f"{name} = {text}" for name, text in rows[1:]] == lines


def test_exact_values_are_exact_strings_and_decimals_carry_their_digits(solved):
    """Each JSON string against the coefficient's data: an exact value is exactly its
    shortest exact string (no trailing zeros: "1", not "1.000..."); any other decimal has
    exactly the digits the solver trusts."""
    base = solved.to_json()["base"]
    seen = 0
    for b, row in zip(base, solved.result.coefficients):
        assert list(b["expression"]) == list(row)
        for name, text in entry_texts(b).items():
            c = row[name]
            plain = _number(text)
            if c.exact and plain:
                assert Fraction(text) == c.value and text == exact_text(c.value)
                assert not ("." in text and text.endswith("0"))
            elif plain:
                assert not c.exact and significant_digits(text) == c.digits
            seen += 1
    assert seen > solved.result.rank


def test_vp_writes_the_exact_solvers_rationals():
    """vp's recovered rationals, written exactly, are the strings of the exact solver (an
    independent method) on the rows both keep, to the character."""
    vp, exact = (bp.solve("puma560", s).to_json() for s in ("vp", "exact"))
    assert vp["diagnostics"]["rational_recovery"]["succeeded"]
    by_kept = lambda result: {next(iter(b["expression"])): entry_texts(b) for b in result["base"]}  # noqa: E731
    rows_vp, rows_exact = by_kept(vp), by_kept(exact)
    common = set(rows_vp) & set(rows_exact)
    assert len(common) >= 30
    assert all(rows_vp[k] == rows_exact[k] for k in common)


def test_symbolic_values_are_exact_strings():
    values = bp.solve("planar_2r", "symbolic").to_json()["expression_values"]
    texts = [t for row in values for t in row.values()]
    assert "0.6" in texts and all(t == exact_text(Fraction(t)) for t in texts)


@pytest.mark.parametrize("coefficient, text", [
    (Coefficient("1.00000000000000000000000000000", Fraction(1), exact=True, digits=30), "1"),
    (Coefficient("0.66666666666666666666666666667", Fraction(2, 3), exact=True, digits=29), "2/3"),
    (Coefficient("-0.50000", Fraction(-1, 2), exact=True, digits=5), "-0.5"),
    (Coefficient("0.431800000000000", Fraction("0.4318"), exact=False, digits=15), "0.431800000000000"),
    (Coefficient("L1**2", Fraction(9, 25), exact=True), "L1**2"),
])
def test_coefficient_text(coefficient, text):
    assert coefficient_text(coefficient) == text


def test_expression_text_signs_fractions_and_expressions():
    assert expression_text({"m1": "1", "Iyy1": "-390625/63001", "mx2": "0.5", "m3": "L1 - L2"}) == \
        "m1 - 390625/63001*Iyy1 + 0.5*mx2 + (L1 - L2)*m3"
    assert expression_text({}) == "0"


def test_identify_prints_the_solvers_strings(tmp_path):
    data = tmp_path / "d.csv"
    bp.simulate("planar_2r", output=data, noise=0.01, seed=1)
    fit = bp.identify("planar_2r", data, solver="vp")
    legend = bp.solve("planar_2r", "vp").legend()
    text = fit.to_text()
    assert all(line in text for line in legend)
    assert [b["expression"] for b in json.loads(json.dumps(fit.to_json()))["base"]] == \
        [b["expression"] for b in bp.solve("planar_2r", "vp").to_json()["base"]]


def _number(text: str) -> bool:
    try:
        Fraction(text)
        return True
    except ValueError:
        return False
