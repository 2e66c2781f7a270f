"""Base-parameter names do not depend on the solver (issue 45): dp, vp, exact and symbolic
keep the leftmost independent parameters, so ``phi_b01`` is the same combination under
each of them. Checked on built-in and generated mechanisms against vp's (certified) rows:
the same kept parameter under every name, and each coefficient equal (exact and symbolic's
values exactly, dp's to its printed digits)."""

from fractions import Fraction

import numpy as np
import pytest

import baseparams as bp
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.solvers.run import run_solver

from baseparams.plugins.solvers.dp.gautier import dp_gautier


def _rows(result) -> dict[str, dict[str, str]]:
    return {row["name"]: row["expression"] for row in result.to_json()["base"]}


def _values(result) -> dict[str, dict[str, Fraction]]:
    """{name: {parameter: value}}: exact values where the solver gives them, else the decimals."""
    data = result.to_json()
    exact = data.get("expression_values") or [row["expression"] for row in data["base"]]
    return {row["name"]: {p: Fraction(v) for p, v in values.items()} for row, values in zip(data["base"], exact)}


def _same_names(reference, other, tolerance: float) -> None:
    ref, got = _values(reference), _values(other)
    assert list(ref) == list(got)
    for name in ref:
        assert list(ref[name])[0] == list(got[name])[0], name        # the same leading (kept) parameter
        for param in set(ref[name]) | set(got[name]):
            a, b = ref[name].get(param, Fraction(0)), got[name].get(param, Fraction(0))
            assert abs(float(a - b)) <= tolerance * max(1.0, abs(float(a))), (name, param, a, b)


@pytest.mark.parametrize("name", ["pendulum", "planar_2r", "scara", "puma560", "four_bar", "slider_crank"])
def test_dp_and_vp_name_the_same_base_parameters(name):
    vp = bp.solve(name, solver="vp")
    _same_names(vp, bp.solve(name, solver="dp"), 1e-6)


@pytest.mark.parametrize("name", ["planar_2r", "scara", "puma560"])
def test_exact_and_symbolic_name_them_alike(name):
    vp = bp.solve(name, solver="vp")
    _same_names(vp, bp.solve(name, solver="exact"), 0.0)
    if name != "puma560":              # symbolic's coefficients are expressions; their values are compared
        _same_names(vp, bp.solve(name, solver="symbolic"), 0.0)


@pytest.mark.parametrize("family,seed", [("serial_chain", s) for s in range(4)] + [("tree", s) for s in range(4)])
def test_generated_mechanisms_name_them_alike(family, seed):
    text = getattr(generate, family)(seed, max_bodies=4, samples=40)
    mech = parse_mechanism(text, f"<{family} {seed}>")
    exact = run_solver("exact", mech)
    _same_names(exact, run_solver("vp", mech), 1e-25)          # vp prints its trusted decimals
    dp = run_solver("dp", mech)
    if not dp.diagnostics.details.get("pivoting") == "qr":        # natural order unless dp said why not
        _same_names(exact, dp, 1e-6)


def test_dp_qr_pivoting_is_still_there():
    """``-O pivoting=qr``: the old choice, other kept parameters on planar_2r (my1, m2 kept)."""
    dp = bp.solve("planar_2r", solver="dp", solver_options={"pivoting": "qr"})
    kept = [next(iter(row["expression"])) for row in dp.to_json()["base"]]
    assert kept == ["my1", "Izz1", "m2", "mx2", "my2", "Izz2"]


def test_dp_falls_back_to_qr_pivoting_when_the_leftmost_columns_are_ill_conditioned():
    """Columns a, a + 1e-5 b, b, a + b (rank 2): the leftmost pair (a, a + 1e-5 b) is
    independent, but eliminating b and a + b through it makes cond(V22) about 1e5; dp keeps
    QR pivoting's choice and says why."""
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((2, 30))
    W = np.column_stack([a, a + 1e-5 * b, b, a + b])
    res, pivoted = dp_gautier(W, scale=False), dp_gautier(W, scale=False, pivoting="qr")
    assert res.rank == 2 and res.kept == pivoted.kept != [0, 1]
    assert "QR pivoting" in res.kept_note and res.v22_condition < 10
    assert dp_gautier(np.column_stack([a, b, a + b, a - b]), scale=False).kept == [0, 1]
