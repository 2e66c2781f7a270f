"""The dp, vp and exact solvers against closed forms, each other and the seed paper.

- Closed forms derived by hand: the pendulum (tau = Izz1 th'' + g (mx1 sin th + my1 cos th):
  base parameters mx1, my1, Izz1) and the planar 2R arm (m2 moved to joint 2, which sits
  at x1 = L1 on link 1: Izz1 + L1^2 m2, mx1 + L1 m2, my1, Izz2, mx2, my2).
- Open chains: exact (rationals) and vp (balls) must give the same kept parameters and
  every printed vp digit must match the exact rational.
- Closed loops: vp's base parameters, computed on the default trajectory, must explain
  the float64 W of another trajectory (states never used by vp).
- The SLA: vp's rank 41 and its expressions against the seed paper's symbolic table
  (tests/seed_tables.py, evaluated exactly with the geometry).
- The numeric cores on synthetic matrices whose rank and beta are known exactly.
- Trajectories that do not excite the mechanism (2 or 4 samples): the independent random
  batch must raise the rank to the closed form's (pendulum 3, planar 2R 6, four-bar 8),
  with a warning, in every solver.
"""

import json
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from flint import arb, arb_mat, fmpq, fmpq_mat

from baseparams.numeric import certify
from baseparams.plugins.solvers.vp import balls
from baseparams import registry
from baseparams.numeric.backends import Arb, Float64
from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.plugins.solvers.dp.gautier import dp_gautier
from baseparams.plugins.solvers.exact.states import rref_pivots as pivots_of
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.plugins.solvers.exact import solver as exact_solver
from baseparams.plugins.solvers.vp import solver as vp_solver
from baseparams.plugins.solvers.vp.solver import compare_runs
from baseparams.solvers.compare import same_row_space
from baseparams.solvers.run import run_solver
from baseparams.dynamics.trajectory import Trajectory, observation_matrix

from seed_tables import symbolic_base_matrix


def solver(name):
    return registry.solvers()[name].item


def rows_of(parameters, rows):
    """Coefficient rows over ``parameters`` from {name: Fraction} dicts."""
    return [[Fraction(row.get(p, 0)) for p in parameters] for row in rows]


def exact_rref(rows):
    m = fmpq_mat(len(rows), len(rows[0]), [fmpq(v.numerator, v.denominator) for r in rows for v in r])
    R, rank = m.rref()
    return R, rank


def printed_digits(text):
    mantissa = text.lower().split("e")[0].lstrip("-").replace(".", "").lstrip("0")
    return len(mantissa)


def assert_digits_match(result, R, rank, pivots=None):
    """Every coefficient of ``result`` equals the exact rref value to the digits it prints,
    and every coefficient it omits is exactly zero (or below the solver's noise, if it
    says so). ``pivots``: R's identity columns when R is not in echelon form."""
    params = result.parameters
    pivots = pivots_of(R, rank) if pivots is None else pivots
    dropped = result.diagnostics.get("coefficients_below_noise_dropped", 0) + len(
        result.diagnostics.get("untrusted", []))
    assert result.kept == [params[j] for j in pivots]
    for i, row in enumerate(result.base):
        expr = row["expression"]
        for j, p in enumerate(params):
            exact = Fraction(int(R[i, j].p), int(R[i, j].q))
            if p not in expr:
                assert exact == 0 or dropped, (row["name"], p)
                continue
            text = expr[p]
            value = Fraction(text)
            assert exact != 0, (row["name"], p, text)
            tolerance = abs(exact) * Fraction(10) ** (1 - printed_digits(text))
            assert abs(value - exact) <= tolerance, (row["name"], p, text, float(exact))


# ----- closed forms ------------------------------------------------------------------
PENDULUM = [{"mx1": 1}, {"my1": 1}, {"Izz1": 1}]


def planar_2r_rows(mech):
    L1 = mech.geometry["L1"]
    return [{"Izz1": 1, "m2": L1 * L1}, {"mx1": 1, "m2": L1}, {"my1": 1},
            {"Izz2": 1}, {"mx2": 1}, {"my2": 1}]


@pytest.mark.parametrize("name", ["dp", "vp", "exact"])
def test_pendulum_closed_form(name):
    mech = resolve("pendulum")
    res = solver(name).solve(mech, **({"digits": 30, "recover": False} if name == "vp" else {}))
    expected = rows_of(mech.parameters, PENDULUM)
    assert res.rank == 3
    assert res.kept == ["mx1", "my1", "Izz1"]
    if name == "dp":
        assert same_row_space(res.coefficient_matrix(), expected, tol=1e-10)
    else:
        assert res.certified
        assert same_row_space(res.coefficient_matrix(), expected)      # exact (Fractions)


@pytest.mark.parametrize("name", ["dp", "vp", "exact"])
def test_planar_2r_closed_form(name):
    mech = resolve("planar_2r")
    res = solver(name).solve(mech, **({"digits": 30, "recover": False} if name == "vp" else {}))
    expected = rows_of(mech.parameters, planar_2r_rows(mech))
    assert res.rank == 6
    if name == "exact":
        assert same_row_space(res.coefficient_matrix(), expected)      # exact rank test
    else:
        assert same_row_space(res.coefficient_matrix(), expected, tol=1e-9 if name == "dp" else 1e-25)


# ----- trajectories that do not excite the mechanism ---------------------------------
UNDER_EXCITED = [("pendulum", 2, 3), ("planar_2r", 2, 6), ("four_bar", 4, 8)]


@pytest.mark.parametrize("mech_name,samples,true_rank", UNDER_EXCITED)
def test_vp_under_excited_trajectory_is_caught(mech_name, samples, true_rank):
    """With 2 or 4 samples W has a clean ridge at a lower rank (its missing directions are
    exact zeros): only the independent random batch shows it, and the rank it gives must be
    the closed form's, with a warning."""
    mech = resolve(mech_name)
    W, _ = observation_matrix(mech, Float64(), Trajectory.default(mech, samples=samples))
    assert np.linalg.matrix_rank(W) < true_rank            # the trajectory alone is deficient
    res = solver("vp").solve(mech, samples=samples, recover=False)
    assert res.rank == true_rank
    assert any("does not excite" in w and "raised from" in w and f"to {true_rank}" in w
               for w in res.warnings), res.warnings
    checks = res.diagnostics["excitation_checks"]
    assert not checks[0]["passed"] and checks[0]["rank"] < true_rank
    assert checks[-1]["passed"] and res.diagnostics["random_states_in_W"] > 0
    if mech_name == "planar_2r":                            # and the closed form's row space
        expected = rows_of(mech.parameters, planar_2r_rows(mech))
        assert same_row_space(res.coefficient_matrix(), expected, tol=1e-25)


def test_vp_excitation_check_cannot_be_passed_is_not_certified(monkeypatch):
    """No batch may be added to W: the first rank (2) stays, uncertified, with a warning."""
    monkeypatch.setattr(vp_solver, "CHECK_ROUNDS", 0)
    res = solver("vp").solve(resolve("pendulum"), samples=2, recover=False)
    assert res.rank == 2 and not res.certified
    assert any(w.startswith("excitation check failed") for w in res.warnings), res.warnings


@pytest.mark.parametrize("name,mech_name,samples,true_rank",
                         [("dp", *case) for case in UNDER_EXCITED] + [("exact", *case) for case in UNDER_EXCITED[:2]])
def test_dp_and_exact_under_excited_warn(name, mech_name, samples, true_rank):
    res = solver(name).solve(resolve(mech_name), samples=samples)
    assert res.rank == true_rank
    assert any("raised from" in w and f"to {true_rank}" in w for w in res.warnings), res.warnings


def test_exact_unsettled_rank_is_not_certified(monkeypatch):
    """The rank still rising at the last allowed batch: a lower bound only."""
    monkeypatch.setattr(exact_solver, "EXACT_ROUNDS", 1)
    res = solver("exact").solve(resolve("puma560"), samples=2)
    assert not res.certified
    assert any("still rose" in w for w in res.warnings), res.warnings
    assert "not certified" in res.diagnostics["summary"][1]


def test_normal_runs_pass_the_excitation_check():
    mech = resolve("planar_2r")
    res = solver("vp").solve(mech, recover=False)
    assert res.certified and res.warnings == [] and res.rank == 6
    (check,) = res.diagnostics["excitation_checks"]
    assert check["passed"] and check["proven_nonzero"] == 0 and check["rows"] >= len(mech.parameters)
    assert res.diagnostics["random_states_in_W"] == 0
    assert any(line.startswith("rank >= 6 proven") for line in res.diagnostics["summary"])
    dp = solver("dp").solve(mech)
    assert dp.diagnostics["excitation_check"]["rank_with_batch"] == dp.rank == 6
    assert not any("does not excite" in w for w in dp.warnings)


def test_certify_excitation_check_on_synthetic_rows():
    """W spans 2 of the 3 directions of a rank-3 space: its analysis (rank 2, clean ridge)
    is refuted by rows from the whole space, and not by rows from W's own span."""
    rng = np.random.default_rng(5)
    basis = rng.integers(-9, 10, size=(3, 7))
    W = rng.integers(-9, 10, size=(12, 2)) @ basis[:2]
    inside = rng.integers(-9, 10, size=(8, 2)) @ basis[:2]
    whole = rng.integers(-9, 10, size=(8, 3)) @ basis
    with Arb(30).activate():
        a = certify.analyse(_arb_matrix(W, 30), 30)
        assert a.rank == 2 and a.ridge_log10 > 10
        _, nonzero, decades = balls.excitation_check(_arb_matrix(inside, 30), a)
        assert nonzero == 0 and decades > 10
        _, nonzero, decades = balls.excitation_check(_arb_matrix(whole, 30), a)
        assert nonzero > 0 and decades < 3


def test_exact_and_dp_declare_no_digits_and_the_front_door_says_it_ignores_it():
    """Solvers declare only the options they use: dp and exact work in double precision
    and in rationals, so they declare no ``digits``; offered as a common option,
    run_solver drops it and says so; given as their own option, it is refused."""
    for name in ("dp", "exact"):
        assert "digits" not in {o.name for o in solver(name).options}, name
        res = run_solver(name, resolve("pendulum"), common={"digits": 40})
        assert any(w.startswith(f"{name} ignores digits") for w in res.warnings), name
        with pytest.raises(InputError, match="has no option 'digits'"):
            run_solver(name, resolve("pendulum"), {"digits": 40})


def test_vp_untrusted_coefficients_are_listed_not_printed():
    """A ball with no trusted digit is left out of its expression and listed; the others
    carry exactly their trusted digits."""
    with Arb(30).activate():
        beta = arb_mat(1, 3, [arb("1.25", "0.5"), arb(1) / 3, arb("0", "1e-40")])
        analysis = SimpleNamespace(beta=beta, kept=[0], eliminated=[1, 2, 3])
        final = SimpleNamespace(analysis=analysis, digits=30,
                                digits_of=[[balls.radius_digits(beta[0, j]) for j in range(3)]])
        rows, printed, untrusted = vp_solver._vp_coefficients(final, None, ["a", "b", "c", "d"])
    assert rows == [{"name": "phi_b01", "expression": {"a": "1", "c": "0." + "3" * 30}}]
    assert printed == [30]
    assert untrusted == [{"base": "phi_b01", "parameter": "b", "ball": untrusted[0]["ball"]}]
    assert "+/-" in untrusted[0]["ball"]


# ----- open chains: exact against vp, digit by digit -------------------------------
@pytest.mark.parametrize("mech_name", ["puma560", "scara"])
def test_exact_and_vp_agree_digit_by_digit(mech_name):
    mech = resolve(mech_name)
    exact = solver("exact").solve(mech)
    vp = solver("vp").solve(mech, digits=30, samples=60, recover=False)
    assert exact.certified and vp.certified
    assert exact.rank == vp.rank
    rows = exact.coefficient_matrix()
    R, rank = exact_rref(rows)
    assert rank == exact.rank
    assert_digits_match(vp, R, rank)
    dp = solver("dp").solve(mech)
    assert dp.rank == exact.rank          # with the zero-column guard (PUMA: mz2 is 5.6e-15)


def test_puma560_base_parameter_count():
    """36 = 6 links x 7 (each revolute joint groups m, mz and Iyy of its link into the
    previous one) - 6 (link 1 turns about the vertical: only Izz1 acts), with the 60
    standard link parameters and no motor inertias."""
    mech = resolve("puma560")
    res = solver("exact").solve(mech)
    assert res.rank == 36
    assert [p for p in res.kept if p.endswith("1")] == ["Izz1"]


def test_exact_refuses_closed_loops_and_irrational_geometry():
    with pytest.raises(InputError, match="closed loop"):
        solver("exact").solve(resolve("four_bar"))
    text = open(resolve("pendulum").path).read().replace(
        'axis = ["0", "-1", "0"], ref = ["0", "0", "-1"]', 'axis = ["1", "-1", "0"], ref = ["0", "0", "-1"]')
    assert '["1", "-1", "0"]' in text
    tilted = parse_mechanism(text, "tilted_pendulum.toml")
    with pytest.raises(InputError, match="rational"):
        solver("exact").solve(tilted)


# ----- closed loops: base parameters that explain another trajectory -----------------
@pytest.mark.parametrize("mech_name", ["four_bar", "slider_crank", "stewart_platform"])
def test_vp_base_parameters_explain_another_trajectory(mech_name):
    mech = resolve(mech_name)
    vp = solver("vp").solve(mech, digits=30, recover=False)
    assert vp.certified and not vp.warnings
    spec = mech.trajectory
    other = Trajectory.default(mech, samples=97, t_start=spec.t_start + Fraction(1, 7),
                               t_end=spec.t_start + (spec.t_end - spec.t_start) * Fraction(3, 4))
    W, _ = observation_matrix(mech, Float64(), other)
    assert dp_gautier(W).rank == vp.rank
    assert vp.diagnostics["excitation_checks"][-1]["passed"]
    # every null vector of the base coefficient matrix must be a null vector of W
    C = np.array([[float(v) for v in row] for row in vp.coefficient_matrix()])
    null = np.linalg.svd(C)[2][vp.rank:].T
    assert null.shape[1] == len(mech.parameters) - vp.rank
    residual = np.abs(W @ null).max() / (np.abs(W).max() * np.abs(null).max())
    assert residual < 1e-10, residual


# ----- the SLA against the seed paper ------------------------------------------------
@pytest.fixture(scope="module")
def sla_vp():
    mech = resolve("sla_suspension")
    return mech, solver("vp").solve(mech)


def test_sla_vp_rank_41_certified(sla_vp):
    mech, res = sla_vp
    assert res.rank == 41
    assert res.certified
    assert res.warnings == []
    d = res.diagnostics
    assert d["ridge_decades"] >= 3
    runs = d["runs"]
    assert len(runs) >= 2 and runs[-1]["rank"] == runs[-2]["rank"] == 41


def test_sla_vp_equals_the_symbolic_table(sla_vp):
    """Row space of vp's decimals = the paper's table at the trusted digits; the kept
    parameters and every printed digit = the exact rref of the table."""
    mech, res = sla_vp
    table = symbolic_base_matrix(mech.geometry)
    R, rank = exact_rref(table)
    assert rank == 41
    assert same_row_space(res.coefficient_matrix(), table, tol=1e-12)
    assert_digits_match(res, R, rank)


def test_sla_vp_rational_recovery_is_the_symbolic_table_exactly(sla_vp):
    mech, res = sla_vp
    rec = res.diagnostics["rational_recovery"]
    assert rec["succeeded"], rec
    assert rec["confirmed_at_digits"] == 2 * res.digits
    rows = [[Fraction(row["expression"].get(p, "0")) for p in res.parameters] for row in rec["base"]]
    assert same_row_space(rows, symbolic_base_matrix(mech.geometry))     # exact rational ranks


def test_sla_json_follows_design(sla_vp):
    _, res = sla_vp
    data = json.loads(json.dumps(res.to_json()))
    for key in ("mechanism", "solver", "parameters", "rank", "base", "eliminated", "certified",
                "digits", "singular_values", "geometry", "warnings", "elapsed_s"):
        assert key in data
    assert data["geometry"]["D12"] == "0.3196"
    assert len(data["singular_values"]) == 70
    assert len(data["base"]) == 41 and len(data["eliminated"]) == 29
    assert data["base"][0]["name"] == "phi_b01"


@pytest.mark.parametrize("samples,scale", [(200, True), (200, False), (50, True), (1000, False)])
def test_sla_dp_never_silently_wrong(samples, scale):
    """Whatever DP's verdict, a rank other than the certified 41, or a tolerance cut away
    from a clear ridge, must come with a warning; at rank 41 every printed coefficient
    equals the paper's table (exact, for dp's own kept parameters) to its printed digits,
    and coefficients with no trusted digit are listed with a warning, never printed."""
    mech = resolve("sla_suspension")
    res = solver("dp").solve(mech, samples=samples, scale=scale)
    ridge = res.diagnostics["ridge"]
    if res.rank != 41 or not ridge["clear"]:
        assert any("ridge" in w for w in res.warnings), res.warnings
    assert res.diagnostics["column_scaling"] != "none" if scale else res.diagnostics["column_scaling"] == "none"
    if res.diagnostics["untrusted"]:
        assert any("no trusted digit" in w for w in res.warnings)
    if res.rank == 41:
        table = symbolic_base_matrix(mech.geometry)
        kept = [mech.parameters.index(p) for p in res.kept]
        T = fmpq_mat(41, 70, [fmpq(v.numerator, v.denominator) for row in table for v in row])
        TK = fmpq_mat(41, 41, [T[i, j] for i in range(41) for j in kept])
        assert_digits_match(res, TK.solve(T), 41, pivots=kept)


# ----- numeric cores on matrices with known rank ---------------------------------------
def _low_rank(rng, rows, cols, rank, scale_cols=True):
    A = rng.integers(-9, 10, size=(rows, rank))
    B = rng.integers(-9, 10, size=(rank, cols))
    W = A @ B
    if scale_cols:
        W = W * (10.0 ** rng.integers(-3, 4, size=cols))[None, :]
    return W


def test_dp_clear_ridge_and_zero_column_guard():
    rng = np.random.default_rng(1)
    W = _low_rank(rng, 60, 12, 7).astype(float)
    W[:, 3] = 1e-17 * rng.standard_normal(60)       # rounding noise of a zero column
    res = dp_gautier(W)
    assert 3 in res.zero_columns
    assert res.rank == 7 and res.clear_ridge and not res.warnings


def test_dp_warns_without_a_ridge():
    rng = np.random.default_rng(2)
    q1, _ = np.linalg.qr(rng.standard_normal((80, 20)))
    q2, _ = np.linalg.qr(rng.standard_normal((20, 20)))
    s = 10.0 ** (-0.9 * np.arange(20))              # a smooth decay through the tolerance
    res = dp_gautier(q1 @ np.diag(s) @ q2.T, scale=False)
    assert not res.clear_ridge
    assert any(w.startswith("no clear ridge") for w in res.warnings)


def _arb_matrix(W, digits):
    with Arb(digits).activate():
        return arb_mat(W.shape[0], W.shape[1], [arb(fmpq(int(v))) for v in W.ravel()])


def test_certify_exact_rank_and_beta():
    rng = np.random.default_rng(3)
    W = _low_rank(rng, 40, 10, 6, scale_cols=False)
    Q = fmpq_mat(40, 10, [fmpq(int(v)) for v in W.ravel()])
    R, rank = Q.rref()
    with Arb(30).activate():
        a = certify.analyse(_arb_matrix(W, 30), 30)
        assert a.rank == rank == 6
        assert a.kept == pivots_of(R, rank)
        for i in range(rank):
            for b, j in enumerate(a.eliminated):
                assert a.beta[i, b].contains(arb(R[i, j]))
        assert a.ridge_log10 > 10


def test_certify_hidden_singular_value_needs_more_digits():
    """True rank 7 with s_7 ~ 1e-25 s_1: at 20 digits it hides in the noise (rank 6 is
    still a proven lower bound), at 60 it is proven; the solver's two-precision rule
    refuses to accept the pair."""
    rng = np.random.default_rng(4)
    A = _low_rank(rng, 50, 9, 6, scale_cols=False)
    extra = np.outer(rng.integers(1, 9, 50), rng.integers(1, 9, 9))
    W_exact = [[fmpq(int(a)) + fmpq(int(e), 10 ** 25) for a, e in zip(ra, re)] for ra, re in zip(A, extra)]
    runs = []
    for digits in (20, 60):
        with Arb(digits).activate():
            W = arb_mat(50, 9, [arb(v) for row in W_exact for v in row])
            a = certify.analyse(W, digits)
        runs.append(SimpleNamespace(digits=digits, analysis=a, rank=a.rank))
    assert [r.rank for r in runs] == [6, 7]
    ok, _, reasons = compare_runs(runs[0], runs[1])
    assert not ok and "rank 6 at 20 digits, 7 at 60" in reasons[0]


def test_rational_recovery():
    with Arb(40).activate():
        x = arb(625) / 251
        assert balls.recover_rational(x, 35) == Fraction(625, 251)
        root = arb(2).sqrt()
        guess = balls.recover_rational(root, 30)
    with Arb(80).activate():
        assert guess is None or not balls.contains_rational(arb(2).sqrt(), guess)


# ----- command line --------------------------------------------------------------------
def run(*args, code=0):
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == code, result.output
    return result


def test_cli_solve_json():
    data = json.loads(run("solve", "planar_2r", "--solver", "exact", "--format", "json").stdout)
    assert data["solver"] == "exact" and data["rank"] == 6 and data["certified"] is True
    # the closed form through the CLI: mass m2 moved to joint 2 at x1 = L1 = 3/5
    assert data["base"][0] == {"name": "phi_b01", "expression": {"mx1": "1", "m2": "0.6"}, "decimals": {}}
    assert data["base"][2] == {"name": "phi_b03", "expression": {"Izz1": "1", "m2": "0.36"}, "decimals": {}}
    text = run("solve", "pendulum", "--solver", "vp", "--digits", "30").stdout
    assert "rank 3 (certified)" in text and "phi_b03 = Izz1" in text


def test_cli_solve_errors():
    result = run("solve", "pendulum", "--solver", "nope", code=2)
    for name in registry.solvers():
        assert name in result.output
    result = run("solve", "four_bar", "--solver", "exact", code=2)
    assert "closed loop" in result.output and "four_bar.toml" in result.output


def test_cli_plot_singular_values(tmp_path):
    out = tmp_path / "sv.png"
    run("plot", "singular-values", "pendulum", "-o", str(out))
    assert out.stat().st_size > 1000


def test_dp_warns_when_an_independent_batch_lowers_its_rank(monkeypatch):
    """More rows can only raise the true rank: a lower count exposes a fragile tolerance cut."""
    dp = solver("dp")
    fake = {"seed": 1, "states": 5, "rows": 5, "rank": 3, "rank_with_batch": 2, "raised": False}
    monkeypatch.setattr(type(dp), "_excitation_check", staticmethod(lambda *args: (fake, None, None)))
    res = dp.solve(resolve("pendulum"))
    assert res.rank == 3
    assert any(w.startswith("the rank cut is fragile") and "rank 2" in w for w in res.warnings), res.warnings
