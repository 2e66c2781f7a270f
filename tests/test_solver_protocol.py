"""The typed solver contract (baseparams.solvers.protocol) and the result's typed parts.

- Every registered solver satisfies the Solver protocol; its declared options pass
  check_options with their defaults; anything else is an InputError (exit 2 in the CLI)
  naming the solver, the option and the accepted ones.
- exact on a closed loop is "not applicable", with the reason, before any solving.
- Coefficients as data agree with their strings: exact Fractions (exact, symbolic) equal
  the printed rationals and the planar 2R arm's closed form (mx1 + L1 m2, Izz1 + L1^2 m2,
  L1 = 3/5); dp's and vp's decimals carry digits that an independent solver (exact)
  confirms; vp's recovered rationals equal exact's.
- The JSON of every solver has every documented key (docs/cli.md lists them).
"""

import inspect
import json
import math
from fractions import Fraction
from pathlib import Path

import mpmath
import pytest
from click.testing import CliRunner
from flint import fmpq, fmpq_mat

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.io.loader import resolve
from baseparams.solvers.protocol import (Capabilities, NotApplicable, Solver, SolverOption,
                                         check_options, options_from_text, require_applicable)
from baseparams.solvers.run import run_solver
from baseparams.solvers.result import (JSON_KEYS, OPTIONAL_JSON_KEYS, BaseParameterResult,
                                       Coefficient, Diagnostics, significant_digits)

SOLVERS = sorted(registry.solvers())
DOCS = Path(__file__).resolve().parents[1] / "docs"


def solver(name):
    return registry.solvers()[name].item


def run(*args, code=0):
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == code, result.output
    return result


_RESULTS = {}


def solved(name, mech_name, **options):
    """One solve per (solver, mechanism, options) for the whole module."""
    key = (name, mech_name, tuple(sorted(options.items())))
    if key not in _RESULTS:
        _RESULTS[key] = solver(name).solve(resolve(mech_name), **options)
    return _RESULTS[key]


# ----- the protocol -----------------------------------------------------------------
def test_builtin_solvers_are_registered():
    assert set(SOLVERS) >= {"dp", "vp", "exact", "symbolic"}


@pytest.mark.parametrize("name", SOLVERS)
def test_every_solver_satisfies_the_protocol(name):
    s = solver(name)
    assert isinstance(s, Solver)
    assert s.name == name and isinstance(s.description, str) and s.description
    assert isinstance(s.capabilities, Capabilities)
    assert isinstance(s.options, tuple) and all(isinstance(o, SolverOption) for o in s.options)
    names = [o.name for o in s.options]
    assert len(names) == len(set(names)) and "progress" not in names
    defaults = check_options(s, {})
    assert defaults == {o.name: o.default for o in s.options}
    assert check_options(s, defaults) == defaults            # the defaults are valid values
    assert s.applicable(resolve("pendulum")) is None


def test_capabilities_of_the_builtins():
    caps = {name: solver(name).capabilities for name in ("dp", "vp", "exact", "symbolic")}
    assert [n for n, c in caps.items() if c.closed_loops] == ["dp", "vp", "symbolic"]
    assert [n for n, c in caps.items() if c.certifies] == ["vp", "exact", "symbolic"]
    assert [n for n, c in caps.items() if c.derivation] == ["symbolic"]
    assert caps["exact"].needs_rational_geometry and caps["exact"].exact_coefficients
    assert caps["symbolic"].symbolic_coefficients and not caps["dp"].exact_coefficients


def test_declared_options_match_the_brief():
    assert {o.name for o in solver("dp").options} >= {"samples", "scale", "rank", "seed"}
    assert {o.name for o in solver("vp").options} >= {"digits", "samples", "ladder", "pivoting",
                                                       "recover", "kept", "seed"}
    assert {o.name for o in solver("exact").options} >= {"samples", "seed"}
    assert {o.name for o in solver("symbolic").options} >= {"keep", "eliminate_first", "certify",
                                                             "digits", "samples", "seed"}


@pytest.mark.parametrize("name", SOLVERS)
def test_unknown_option_is_an_input_error_naming_it(name):
    s = solver(name)
    with pytest.raises(InputError) as caught:
        check_options(s, {"colour": "blue"})
    message = str(caught.value)
    assert repr(name) in message and "'colour'" in message
    assert all(o.name in message for o in s.options)       # the accepted ones
    with pytest.raises(InputError, match="colour"):          # the front door's one sequence refuses too
        run_solver(s, resolve("pendulum"), {"colour": "blue"})


@pytest.mark.parametrize("name", SOLVERS)
def test_solve_takes_exactly_the_declared_options_with_their_defaults(name):
    """``solve``'s keyword parameters are the declared options (and progress), each with
    its declared default: a direct call without options solves with the defaults, and an
    option declared but not used (dp's and exact's former ``digits``) cannot hide."""
    s = solver(name)
    params = inspect.signature(s.solve).parameters
    declared = {o.name: o.default for o in s.options}
    keywords = {k: p.default for k, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}
    assert keywords.pop("progress") is None
    assert keywords == declared


@pytest.mark.parametrize("name, option, value, want", [
    ("dp", "samples", "many", "an integer"),
    ("dp", "samples", True, "an integer"),                   # bool is an int subclass
    ("dp", "samples", 1, "at least 2"),
    ("dp", "scale", 1, "true or false"),
    ("vp", "pivoting", "sideways", "one of natural, complete"),
    ("vp", "ladder", [30, "sixty"], "a list of int"),
    ("vp", "seed", None, "an integer"),                      # None only where the default is None
    ("symbolic", "digits", 5, "at least 10"),
])
def test_wrong_types_are_input_errors(name, option, value, want):
    with pytest.raises(InputError) as caught:
        check_options(solver(name), {option: value})
    assert want in str(caught.value) and repr(option) in str(caught.value)


def test_values_are_normalised():
    vp = solver("vp")
    got = check_options(vp, {"ladder": [30, 60], "kept": None, "digits": 40})
    assert got["ladder"] == (30, 60) and got["kept"] is None and got["digits"] == 40
    assert check_options(solver("symbolic"), {"keep": "Izz1, mx1"})["keep"] == ("Izz1", "mx1")


def test_options_from_text():
    vp = solver("vp")
    got = options_from_text(vp, ["ladder=30,60", "recover=no", "kept=none", "pivoting=complete"])
    assert got == {"ladder": (30, 60), "recover": False, "kept": None, "pivoting": "complete"}
    assert check_options(vp, got)["ladder"] == (30, 60)
    for bad, word in (["recover=perhaps"], "true or false"), (["seed"], "NAME=VALUE"), \
                     (["seed=1", "seed=2"], "twice"), (["colour=red"], "no option 'colour'"):
        with pytest.raises(InputError, match=word):
            options_from_text(vp, bad)


# ----- not applicable ---------------------------------------------------------------
def test_exact_is_not_applicable_to_a_closed_loop():
    exact, four_bar = solver("exact"), resolve("four_bar")
    reason = exact.applicable(four_bar)
    assert reason and "closed loop" in reason
    with pytest.raises(NotApplicable) as caught:
        require_applicable(exact, four_bar)
    assert isinstance(caught.value, InputError)
    assert caught.value.file == four_bar.path and reason in caught.value.message
    with pytest.raises(NotApplicable, match="closed loop"):
        run_solver(exact, four_bar)
    with pytest.raises(NotApplicable, match="closed loop"):
        run_solver("exact", four_bar)
    for name in ("dp", "vp", "symbolic"):
        assert solver(name).applicable(four_bar) is None


def test_cli_says_not_applicable_and_exits_2():
    result = run("solve", "four_bar", "--solver", "exact", code=2)
    assert result.stdout == ""
    line = result.stderr.strip()
    assert line.startswith("error: ") and "four_bar.toml" in line and "\n" not in line
    assert "not applicable: " in line and "closed loop" in line and "Traceback" not in result.output


def test_cli_unknown_and_wrong_options_exit_2():
    result = run("solve", "pendulum", "--solver", "dp", "-O", "colour=red", code=2)
    assert "'colour'" in result.stderr and "samples, scale, rank, seed, pivoting" in result.stderr
    result = run("solve", "pendulum", "--solver", "vp", "-O", "recover=perhaps", code=2)
    assert "'recover'" in result.stderr and "true or false" in result.stderr
    result = run("solve", "pendulum", "--solver", "dp", "--samples", "50", "-O", "samples=60", code=2)
    assert "both given" in result.stderr
    for verb in (["solve", "pendulum", "--solver", "dp", "-O", "colour=red"],
                 ["report", "pendulum", "--solver", "dp"]):
        assert "Traceback" not in run(*verb, code=2).output


def test_cli_digits_to_dp_is_a_warning():
    """--digits means nothing to dp (it declares no digits option): a warning, not an
    error, and dp is not passed it; -O digits=30, an option meant for dp itself, is an error."""
    result = run("solve", "pendulum", "--solver", "dp", "--digits", "30")
    assert "warning: dp ignores digits: not one of its options" in result.stderr
    assert "'digits'" in run("solve", "pendulum", "--solver", "dp", "-O", "digits=30", code=2).stderr


def test_cli_passes_declared_options():
    data = json.loads(run("solve", "pendulum", "--solver", "dp", "-O", "seed=11", "-O", "scale=false",
                          "--format", "json").stdout)
    assert data["diagnostics"]["excitation_check"]["seed"] == 11
    assert data["diagnostics"]["column_scaling"] == "none"


def test_solve_help_lists_every_registered_solver_and_its_options():
    text = run("solve", "--help").stdout
    for name in SOLVERS:
        assert f"\n  {name}  " in text, name
        for o in solver(name).options:
            assert f"-O {o.name}" in text


# ----- report: any solver with a derivation -----------------------------------------------
def test_report_needs_a_solver_with_a_derivation():
    result = run("report", "pendulum", "--solver", "vp", code=2)
    assert "gives no derivation" in result.stderr and "symbolic" in result.stderr
    text = run("report", "pendulum", "--solver", "symbolic", "--no-certify").stdout
    assert "pendulum" in text and "Izz1" in text


def test_derivation_is_typed_and_not_in_json():
    r = solved("symbolic", "pendulum")
    assert r.diagnostics.derivation is not None and r.derivation is r.diagnostics.derivation
    assert "derivation" not in r.to_json()["diagnostics"]
    for name in ("dp", "vp", "exact"):
        assert solved(name, "pendulum").diagnostics.derivation is None


# ----- coefficients as data ---------------------------------------------------------------
PLANAR_2R_CLOSED_FORM = {"mx1": {"m2": Fraction(3, 5)}, "Izz1": {"m2": Fraction(9, 25)}}


def _by_kept(result):
    return {next(iter(b["expression"])): (b, c) for b, c in zip(result.base, result.coefficients)}


def _check_layout(result):
    assert len(result.coefficients) == len(result.base)
    for b, c in zip(result.base, result.coefficients):
        assert list(c) == list(b["expression"])
        assert all(isinstance(v, Coefficient) and v.text == b["expression"][p] for p, v in c.items())
        kept = next(iter(c.values()))
        assert kept.exact and kept.value == 1


@pytest.mark.parametrize("name", ["exact", "symbolic"])
def test_exact_coefficients_equal_their_strings_and_the_closed_form(name):
    r = solved(name, "planar_2r", **({"certify": False} if name == "symbolic" else {}))
    _check_layout(r)
    for row, values in zip(r.coefficients, r.expression_values or [None] * r.rank):
        for p, c in row.items():
            assert c.exact and c.digits is None and isinstance(c.value, Fraction)
            # exact: the printed rational; symbolic: the expression at the geometry
            assert c.value == (Fraction(c.text) if name == "exact" else Fraction(values[p]))
            assert c.value == r.coefficient_matrix(values=True)[r.coefficients.index(row)][
                r.parameters.index(p)]
    rows = _by_kept(r)
    for kept, others in PLANAR_2R_CLOSED_FORM.items():
        _, data = rows[kept]
        assert {p: c.value for p, c in data.items() if p != kept} == others


def _ulp(text, digits):
    """One unit in the last printed place of a decimal with ``digits`` significant digits."""
    value = Fraction(text)
    return Fraction(10) ** (math.floor(math.log10(abs(value))) - digits + 1)


def exact_beta(mech_name, kept):
    """exact's base parameters re-expressed with ``kept`` as the kept parameters (rationals):
    R = C_K^-1 C for exact's coefficient rows C, so that R_K = I. {kept: {param: Fraction}}."""
    ex = solved("exact", mech_name)
    params = ex.parameters
    C = ex.coefficient_matrix()
    r, n = len(C), len(params)
    cols = [params.index(k) for k in kept]
    CK = fmpq_mat(r, r, [_q(C[i][j]) for i in range(r) for j in cols])
    R = CK.solve(fmpq_mat(r, n, [_q(v) for row in C for v in row]))
    return {k: {params[j]: Fraction(int(R[i, j].p), int(R[i, j].q)) for j in range(n)}
            for i, k in enumerate(kept)}


def _q(v):
    return fmpq(v.numerator, v.denominator)


@pytest.mark.parametrize("name, options", [("dp", {}), ("vp", {"recover": False}), ("vp", {})])
def test_decimal_coefficients_carry_digits_an_exact_solver_confirms(name, options):
    """dp's and vp's printed digits against exact's rationals (an independent solver,
    re-expressed in the same kept parameters): every printed coefficient is within one
    unit of its last digit (within 2 for dp, whose digits come from a first-order estimate)."""
    r = solved(name, "planar_2r", **options)
    _check_layout(r)
    truth = exact_beta("planar_2r", list(_by_kept(r)))
    checked = 0
    for kept, (_, row) in _by_kept(r).items():
        assert truth[kept][kept] == 1
        for p, c in list(row.items())[1:]:
            true = truth[kept][p]
            if c.exact:             # vp's recovered rationals: exact's rationals, written exactly (issue 45)
                assert name == "vp" and c.value == true == Fraction(c.text) and c.digits >= 1
            else:
                assert c.digits == significant_digits(c.text) and c.digits >= 1
                assert abs(Fraction(c.text) - true) <= (2 if name == "dp" else 1) * _ulp(c.text, c.digits)
                assert c.value == Fraction(c.text)
            checked += 1
    assert checked == 2                                     # e.g. m2 in mx1's and Izz1's rows
    for kept, row in truth.items():                         # nothing left out (all trusted here)
        assert {p for p, v in row.items() if v and p != kept} == set(_by_kept(r)[kept][1]) - {kept}
    recovered = options.get("recover", True) and name == "vp"
    assert all(c.exact for row in r.coefficients for c in row.values()) is recovered


def test_dp_and_vp_agree_within_their_digits_on_puma560():
    dp = solved("dp", "puma560")
    params = dp.parameters
    kept = tuple(sorted(params.index(k) for k in _by_kept(dp)))
    vp = solved("vp", "puma560", digits=30, samples=60, recover=False, kept=kept)   # dp's choice
    assert dp.rank == vp.rank == 36
    vp_rows = _by_kept(vp)
    assert set(_by_kept(dp)) == set(vp_rows)
    compared = 0
    for kept, (_, row) in _by_kept(dp).items():
        for p, c in list(row.items())[1:]:
            other = vp_rows[kept][1].get(p)
            assert other is not None, (kept, p)
            assert other.digits >= c.digits
            assert abs(c.value - other.value) <= 2 * _ulp(c.text, c.digits), (kept, p, c, other)
            compared += 1
    assert compared > 20


def test_symbolic_algebraic_values_are_decimals():
    c = Coefficient(text="sqrt(2)/3", value=mpmath.sqrt(2) / 3, exact=False, digits=50)
    assert not c.exact and c.digits == 50


def test_significant_digits():
    assert [significant_digits(t) for t in ("0.50000", "100.00", "-3.3e-21", "6.6667e24", "7")] == \
        [5, 5, 2, 5, 1]


# ----- JSON: every documented key, from every solver ------------------------------------------
@pytest.mark.parametrize("name", SOLVERS)
def test_json_of_every_solver_has_every_documented_key(name):
    data = json.loads(run("solve", "pendulum", "--solver", name, "--format", "json").stdout)
    assert set(JSON_KEYS) <= set(data) <= set(JSON_KEYS) | set(OPTIONAL_JSON_KEYS)
    numeric = name in ("dp", "vp")
    assert (data["singular_values"] is not None) is numeric
    assert (data["digits"] is not None) is (name == "vp")
    assert (data["expression_values"] is not None) is (name == "symbolic")
    assert isinstance(data["diagnostics"]["summary"], list) and data["diagnostics"]["summary"]
    assert data["rank"] == 3 and isinstance(data["warnings"], list)


def test_cli_md_documents_every_json_key():
    text = (DOCS / "cli.md").read_text(encoding="utf-8")
    for key in JSON_KEYS + OPTIONAL_JSON_KEYS + ("rank_tolerance", "tail_bound", "sigma_r_lower",
                                                  "ridge_decades", "certificate"):
        assert f"`{key}`" in text, key


# ----- typed diagnostics ---------------------------------------------------------------------
def test_dp_rank_tolerance_cuts_its_singular_values():
    r = solved("dp", "pendulum")
    tol = r.diagnostics.rank_tolerance
    assert tol > 0 and r.diagnostics.tail_bound is None
    assert sum(float(s) > tol for s in r.singular_values) == r.rank == 3


def test_vp_proven_bounds_bracket_its_singular_values():
    r = solved("vp", "pendulum")
    d = r.diagnostics
    assert d.rank_tolerance is None and d.certificate
    lower, tail = mpmath.mpf(d.sigma_r_lower), mpmath.mpf(d.tail_bound)
    s = [mpmath.mpf(v) for v in r.singular_values]
    assert s[r.rank - 1] >= lower * (1 - mpmath.mpf(10) ** -5)
    assert all(v <= tail * (1 + mpmath.mpf(10) ** -5) for v in s[r.rank:])
    expected = math.inf if tail == 0 else float(mpmath.log10(lower / tail))
    assert d.ridge_decades == pytest.approx(expected, abs=0.01) and d.ridge_decades >= 3
    j = r.to_json()["diagnostics"]
    assert j["tail_bound"] == d.tail_bound and j["certificate"] == d.certificate


def test_diagnostics_json_and_mapping_view():
    d = Diagnostics(summary=["one line"], rank_tolerance=1e-12, ridge_decades=math.inf,
                    details={"runs": [1, 2]})
    assert d.to_json() == {"runs": [1, 2], "rank_tolerance": 1e-12, "ridge_decades": "inf",
                           "summary": ["one line"]}
    assert d["runs"] == [1, 2] and d.get("missing") is None and "summary" in d
    with pytest.raises(ValueError, match="rank_tolerance"):
        Diagnostics(rank_tolerance=1.0, details={"rank_tolerance": 2.0}).to_json()


def test_untyped_results_still_work():
    """A solver that gives a plain diagnostics dict and no coefficient data (an older plugin)."""
    r = BaseParameterResult(mechanism="m", solver="old", parameters=["a", "b"], rank=1,
                            base=[{"name": "phi_b01", "expression": {"a": "1", "b": "0.25"}}],
                            eliminated=["b"], diagnostics={"summary": ["s"], "extra": 1})
    assert r.diagnostics.summary == ["s"] and r.diagnostics["extra"] == 1
    a, b = r.coefficients[0].values()
    assert a.exact and a.value == 1 and not b.exact and b.value == Fraction(1, 4) and b.digits is None
    assert set(JSON_KEYS) <= set(r.to_json())


def test_plugins_json_describes_solvers():
    data = json.loads(run("plugins", "--format", "json").stdout)
    for entry in data["solvers"]:
        s = solver(entry["name"])
        assert entry["capabilities"]["derivation"] is s.capabilities.derivation
        assert [o["name"] for o in entry["options"]] == [o.name for o in s.options]


def test_a_solver_without_the_protocol_is_refused(monkeypatch):
    class Old:
        name, description = "old", "an untyped solver"

        def solve(self, mechanism, **options):
            raise AssertionError("never called")

    found = dict(registry.solvers())
    found["old"] = registry.Registered(Old(), "bp-old")
    monkeypatch.setattr(registry, "solvers", lambda: found)
    result = run("solve", "pendulum", "--solver", "old", code=2)
    assert "bp-old" in result.stderr and "capabilities" in result.stderr and "applicable" in result.stderr
    assert "not a Solver" in run("solve", "--help").stdout


def test_the_documented_example_solver_works():
    """docs/solvers.md, "Writing a solver": its code satisfies the protocol and solves."""
    text = (DOCS / "solvers.md").read_text(encoding="utf-8")
    section = text[text.index("## Writing a solver"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")]
    namespace = {}
    exec(compile(code, "docs/solvers.md", "exec"), namespace)
    example = namespace["baseparams_solvers"]()[0]
    assert isinstance(example, Solver)
    r = example.solve(resolve("pendulum"), seed=2)
    assert r.rank == 10 and set(JSON_KEYS) <= set(r.to_json())
    assert r.to_json()["diagnostics"] == {"seed": 2, "summary": ["no reduction attempted"]}
    with pytest.raises(InputError, match="'seeds'"):
        run_solver(example, resolve("pendulum"), {"seeds": 2})
    assert run_solver(example, resolve("pendulum"), {"seed": 2}).to_json()["diagnostics"]["seed"] == 2


def test_run_solver_finds_checks_and_refuses_in_one_sequence():
    """run_solver: an unknown name lists the registered solvers; an option given both as
    a common and as the solver's own is refused; a common option the solver declares is
    passed (vp at 40 digits), and the checked defaults reach solve."""
    with pytest.raises(InputError, match="unknown solver 'nope'; registered solvers: .*vp"):
        run_solver("nope", resolve("pendulum"))
    with pytest.raises(InputError, match="'seed' both given"):
        run_solver("dp", resolve("pendulum"), {"seed": 3}, common={"seed": 4})
    result = run_solver("vp", resolve("pendulum"), {"recover": False}, common={"digits": 40, "samples": None})
    assert result.digits == 40 and not any("ignores" in w for w in result.warnings)
    assert result.diagnostics["rational_recovery"] == {"attempted": False}
