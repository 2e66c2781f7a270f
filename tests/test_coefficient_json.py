"""Floats as floats in the JSON (issue 45, docs/design.md "Results as JSON"): a coefficient
that is not exact is a JSON number, the double nearest its decimal, and that decimal (its
trusted digits) is beside it under ``decimals``; an exact one is its exact string. Results
written before (every coefficient a string) still read: validate's checks and
``diagnose --params`` give the same on both forms."""

import json
import math
from fractions import Fraction

import numpy as np
import pytest

import baseparams as bp
from baseparams.diagnose.given import given_parameters
from baseparams.io.loader import resolve
from baseparams.orchestrate.checks import cross_checks, decimal_rows, stated_tolerance
from baseparams.solvers.result import (Coefficient, coefficient_json, coefficient_text, entry_texts,
                                       expression_text, significant_digits)


def loaded(solution):
    """The JSON as a user's ``json.load`` sees it."""
    return json.loads(json.dumps(solution.to_json(), allow_nan=False))


def old_form(data):
    """The JSON as results were written before 2026-11-28 (issue 45): every coefficient a
    string, the text's, and no ``decimals``."""
    out = dict(data)
    out["base"] = [{**{k: v for k, v in b.items() if k != "decimals"}, "expression": entry_texts(b)}
                   for b in data["base"]]
    return out


def nearest_double(x: float, decimal: str) -> bool:
    """x is the double nearest the decimal: no neighbour of x is closer (exact arithmetic)."""
    target = Fraction(decimal)
    here = abs(Fraction(x) - target)
    return all(here <= abs(Fraction(n) - target) for n in (math.nextafter(x, -math.inf), math.nextafter(x, math.inf)))


@pytest.fixture(scope="module")
def dp():
    return bp.solve("puma560", "dp")


def test_dp_coefficients_are_numbers_equal_to_its_float64_values(dp):
    data = loaded(dp)
    B, index = dp.base_matrix(), {p: j for j, p in enumerate(dp.parameters)}
    numbers = 0
    for i, (b, row) in enumerate(zip(data["base"], dp.result.coefficients)):
        for p, v in b["expression"].items():
            if isinstance(v, str):              # only the parameter a row keeps: exactly 1
                assert v == "1" and row[p].exact
                continue
            assert isinstance(v, float) and not row[p].exact
            decimal = b["decimals"][p]
            assert v == B[i, index[p]] == float(row[p].value)            # the solve's float64 values
            assert nearest_double(v, decimal)
            assert significant_digits(decimal) == row[p].digits          # the trusted digits, kept
            numbers += 1
        assert set(b["decimals"]) == {p for p, v in b["expression"].items() if not isinstance(v, str)}
    assert numbers > dp.rank
    # the text prints the decimals: trailing trusted zeros included (1.00000000000000, not 1.0)
    assert any(d.endswith("0") and "." in d for b in data["base"] for d in b["decimals"].values())
    assert dp.legend() == [f"{b['name']} = {expression_text(entry_texts(b))}" for b in data["base"]]


def test_dp_frame_has_the_json_numbers_as_float_columns(dp):
    frame = dp.to_frame()
    data = loaded(dp)
    assert all(frame[p].dtype == np.float64 for p in dp.parameters)
    for i, b in enumerate(data["base"]):
        assert frame.loc[i, "expression"] == expression_text(entry_texts(b))
        for p, v in b["expression"].items():
            assert frame.loc[i, p] == float(Fraction(v)) if isinstance(v, str) else frame.loc[i, p] == v
        assert all(frame.loc[i, p] == 0.0 for p in dp.parameters if p not in b["expression"])


def test_vp_keeps_its_certified_digits_beside_the_nearest_double():
    """vp without rational recovery: each coefficient's decimal has all its trusted digits
    (more than a double holds), the number is the double nearest it, and the decimal agrees
    with the exact solver's rational (an independent method) to those digits."""
    vp = bp.solve("puma560", "vp", solver_options={"recover": False})
    exact = loaded(bp.solve("puma560", "exact"))
    data = loaded(vp)
    rationals = {next(iter(b["expression"])): b["expression"] for b in exact["base"]}
    compared = 0
    for b, row in zip(data["base"], vp.result.coefficients):
        kept = next(iter(b["expression"]))
        for p, v in b["expression"].items():
            if isinstance(v, str):
                assert v == "1"
                continue
            decimal = b["decimals"][p]
            assert decimal == coefficient_text(row[p]) and significant_digits(decimal) == row[p].digits > 17
            assert isinstance(v, float) and nearest_double(v, decimal)
            if kept in rationals and p in rationals[kept]:
                truth = Fraction(rationals[kept][p])
                assert abs(Fraction(decimal) - truth) <= abs(truth) * Fraction(10) ** (1 - row[p].digits)
                compared += 1
    assert compared >= 30


@pytest.mark.parametrize("mechanism, solver", [("planar_2r", "exact"), ("puma560", "vp"), ("planar_2r", "symbolic")])
def test_exact_coefficients_stay_exact_strings(mechanism, solver):
    solution = bp.solve(mechanism, solver)
    data = loaded(solution)
    for b, row in zip(data["base"], solution.result.coefficients):
        assert b["decimals"] == {}
        for p, v in b["expression"].items():
            assert isinstance(v, str) and row[p].exact
            if solver != "symbolic":
                assert Fraction(v) == row[p].value                 # the solver's rational
    if solver == "exact":        # the closed form: m2 moves to joint 2 at x = L1 = 3/5
        assert data["base"][0]["expression"] == {"mx1": "1", "m2": "0.6"}
        assert Fraction(data["base"][0]["expression"]["m2"]) == Fraction(resolve("planar_2r").geometry["L1"])


def test_identify_writes_the_solvers_json_coefficients(tmp_path):
    data = tmp_path / "d.csv"
    bp.simulate("planar_2r", output=data, noise=0.01, seed=1)
    fit = json.loads(json.dumps(bp.identify("planar_2r", data, solver="dp").to_json()))
    solved = loaded(bp.solve("planar_2r", "dp"))
    assert [(b["expression"], b["decimals"]) for b in fit["base"]] == \
        [(b["expression"], b["decimals"]) for b in solved["base"]]
    assert any(isinstance(v, float) for b in fit["base"] for v in b["expression"].values())


def test_diagnose_params_reads_both_forms_alike(tmp_path):
    data = tmp_path / "d.csv"
    bp.simulate("planar_2r", output=data, noise=0.01, seed=1)
    fit = json.loads(json.dumps(bp.identify("planar_2r", data, solver="dp").to_json()))
    new, old = tmp_path / "new.json", tmp_path / "old.json"
    new.write_text(json.dumps(fit))
    old.write_text(json.dumps(old_form(fit)))
    assert any(isinstance(v, str) and v != "1" for b in old_form(fit)["base"] for v in b["expression"].values())
    mechanism = resolve("planar_2r")
    a, b = given_parameters(mechanism, str(new)), given_parameters(mechanism, str(old))
    assert np.array_equal(a.base_map, b.base_map) and np.array_equal(a.parameters, b.parameters)


def test_validate_checks_read_both_forms_alike(dp):
    vp = loaded(bp.solve("puma560", "vp", solver_options={"recover": False}))
    ours = loaded(dp)
    for result in (ours, vp):
        before = old_form(result)
        assert decimal_rows(result) == decimal_rows(before)
        assert stated_tolerance(result) == stated_tolerance(before)
    results = {"dp": ours, "vp": vp}
    old = {name: old_form(r) for name, r in results.items()}
    assert [(c.name, c.ok, c.detail) for c in cross_checks(results)] == \
        [(c.name, c.ok, c.detail) for c in cross_checks(old)]


def test_entry_texts_reads_numbers_without_decimals():
    """A file written by hand (a number and no ``decimals``): its shortest decimal."""
    assert entry_texts({"expression": {"m1": "1", "m2": 0.1, "m3": 2, "m4": "625/251"}}) == \
        {"m1": "1", "m2": "0.1", "m3": "2", "m4": "625/251"}
    with pytest.raises(ValueError, match="m2"):
        entry_texts({"expression": {"m2": [0.1]}})


@pytest.mark.parametrize("coefficient, written", [
    (Coefficient.of_decimal("0.431800000000000"), 0.4318),
    (Coefficient.of_decimal("-3.3e-21"), -3.3e-21),
    (Coefficient.of_decimal("0.6000", Fraction(3, 5)), "0.6"),            # recovered: exact
    (Coefficient.of_exact(Fraction(625, 251)), "625/251"),
    (Coefficient("L1**2", Fraction(9, 25), exact=True), "L1**2"),
    (Coefficient.of_decimal("1e400"), "1e400"),                           # beyond any double
])
def test_coefficient_json(coefficient, written):
    value = coefficient_json(coefficient)
    assert type(value) is type(written) and value == written


def test_the_json_follows_the_text_when_base_was_changed():
    """A result whose ``base`` was changed after it was made (a plugin's post-processing):
    the JSON writes what ``base`` says, a "p/q" as an exact string."""
    result = bp.solve("planar_2r", "exact").result
    result.base[0]["expression"]["m2"] = "8/5"
    result.base[2]["expression"]["m2"] = "0.25"
    base = result.to_json()["base"]
    assert base[0]["expression"] == {"mx1": "1", "m2": "8/5"} and base[0]["decimals"] == {}
    assert base[2]["expression"] == {"Izz1": "1", "m2": 0.25} and base[2]["decimals"] == {"m2": "0.25"}
