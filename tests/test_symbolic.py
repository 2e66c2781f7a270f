"""The symbolic solver against the seed paper's tables and against ball-arithmetic ranks.

- SLA: 13 parameters without effect (Tab. 4), 16 transfers (Tab. 5), 41 base parameters
  identical, term by term, to the paper's table (tests/seed_tables.py) and with the same
  row space exactly (Fractions) once the geometry is substituted; the appendix's first
  transfers reproduced.
- Every built-in mechanism: the result's row space is that of W, checked independently:
  W annihilates the exact null space of the result's coefficient matrix (40 digits) and
  the shared ball analysis (baseparams.numeric.certify) proves the same rank.
- Options, the upper-bound path (rules removed), JSON consistency, reports and the CLI.
- The rank check: generators with square roots (a non-unit axis) are tested too, and a
  generator that is not a null vector fails the check without being called an upper bound.
"""

from fractions import Fraction

import pytest
import sympy
from click.testing import CliRunner
from flint import arb_mat, fmpq, fmpq_mat

from baseparams.numeric import certify
from baseparams import registry
from baseparams.numeric.backends import Arb
from baseparams.cli.commands import main
from baseparams.io.loader import resolve
from baseparams.cli.report import render
from baseparams.solvers.compare import same_row_space
from baseparams.solvers.result import parse_coefficient
from baseparams.plugins.solvers.symbolic.elimination import solve
from baseparams.dynamics.trajectory import Trajectory, observation_matrix

from seed_tables import NO_EFFECT, TRANSFERS, symbolic_base_matrix

_RESULTS = {}


def result(name, certify=False):
    key = (name, certify)
    if key not in _RESULTS:
        _RESULTS[key] = solve(resolve(name), certify_rank=certify)
    return _RESULTS[key]


# ----- the seed paper ---------------------------------------------------------------------
def test_sla_rank_and_certificate():
    r = result("sla_suspension", certify=True)
    assert r.solver == "symbolic" and r.rank == 41 and len(r.eliminated) == 29
    assert r.certified and not r.rank_is_upper_bound
    assert r.diagnostics["certificate"]["rank_lower_bound"] == 41
    assert len(r.diagnostics["conditions"]) == 13 and len(r.diagnostics["transfers"]) == 16


def test_sla_parameters_without_effect_are_the_papers_table_4():
    r = result("sla_suspension")
    found = {}
    for c in r.diagnostics["conditions"]:
        found.setdefault(c["bodies"][0], {}).setdefault(c["condition"], []).append(c["eliminated"])
    assert {b: {k: sorted(v) for k, v in d.items()} for b, d in found.items()} == \
        {b: {k: sorted(v) for k, v in d.items()} for b, d in NO_EFFECT.items()}


def test_sla_transfers_are_the_papers_table_5():
    r = result("sla_suspension")
    ours = {}
    for t in r.diagnostics["transfers"]:
        key = (frozenset((t["donor"], t["acceptor"])), t["joint_type"])
        entry = ours.setdefault(key, [set(), set()])
        entry[0].add(t["condition"])
        entry[1].add(t["eliminated"])
    paper = {(frozenset(b), jt): [set(c), set(e)] for b, jt, c, e in TRANSFERS}
    assert ours == paper


def test_sla_expressions_equal_the_papers_symbolic_table():
    """Same eliminated set as the paper, so every row must be identical, term by term."""
    mech = resolve("sla_suspension")
    r = result("sla_suspension")
    paper = symbolic_base_matrix()
    assert len(r.base) == len(paper) == 41
    for row, b in zip(paper, r.base):
        for p, expected in zip(mech.parameters, row):
            ours = sympy.sympify(b["expression"].get(p, "0"))
            assert sympy.simplify(ours - expected) == 0, (b["name"], p, ours, expected)


def test_sla_row_space_equals_the_papers_exactly():
    mech = resolve("sla_suspension")
    r = result("sla_suspension")
    ours = r.coefficient_matrix(values=True)
    assert all(isinstance(v, Fraction) for row in ours for v in row)
    assert same_row_space(symbolic_base_matrix(mech.geometry), ours)
    # and a perturbed table is told apart (the comparison can fail)
    wrong = [list(row) for row in symbolic_base_matrix(mech.geometry)]
    wrong[0][mech.parameters.index("m7")] += Fraction(1, 1000)
    assert not same_row_space(wrong, ours)


def test_sla_appendix_transfers():
    """Joint 0-1: m01 = -(Iyy1 + m7 D13^2)/(D12 + D13)^2; joint 0-4: Izz4' = Izz4 - Iyy4."""
    r = result("sla_suspension")
    der = r.derivation
    f = der.field
    D12, D13, L10 = sympy.symbols("D12 D13 L10")
    m7, Iyy1, Iyy4, Izz4 = sympy.symbols("m7 Iyy1 Iyy4 Izz4")

    def form(lin):
        return sum(f.to_sympy(c) * sympy.Symbol(p) for p, c in lin.items())

    j01 = next(s for s in der.steps if s.generator.joint_name == "J01")
    assert j01.pivot == "Iyy1"
    # the body (the child of J01) gains minus the step's coefficient
    assert sympy.simplify(-form(j01.amount) + (Iyy1 + m7 * D13 ** 2) / (D12 + D13) ** 2) == 0
    j04 = next(s for s in der.steps if s.generator.joint_name == "J04")
    assert sympy.simplify(form(j04.changes["Izz4"]) - (Izz4 - Iyy4)) == 0
    assert sympy.simplify(form(j04.changes["mx4"]) - (sympy.Symbol("mx4") - Iyy4 / L10)) == 0


def test_sla_json_values_match_expressions():
    mech = resolve("sla_suspension")
    r = result("sla_suspension")
    data = r.to_json()
    assert data["solver"] == "symbolic" and data["rank"] == 41
    assert data["base"][0]["expression"]["Iyy1"] == "1/(D12 + D13)"
    for b, v in zip(data["base"], data["expression_values"]):
        assert set(b["expression"]) == set(v)
        for p, text in b["expression"].items():
            assert parse_coefficient(text, mech.geometry) == Fraction(v[p])


# ----- every built-in mechanism -------------------------------------------------------------
def _null_space(rows):
    """Exact basis of {n : C n = 0} for Fraction rows."""
    m, ncols = len(rows), len(rows[0])
    R, rank = fmpq_mat(m, ncols, [fmpq(v.numerator, v.denominator) for row in rows for v in row]).rref()
    pivots, r = [], 0
    for c in range(ncols):
        if r < rank and R[r, c] != 0:
            pivots.append(c)
            r += 1
    basis = []
    for free in (c for c in range(ncols) if c not in pivots):
        n = [fmpq(0)] * ncols
        n[free] = fmpq(1)
        for i, p in enumerate(pivots):
            n[p] = -R[i, free]
        basis.append(n)
    return basis


@pytest.mark.parametrize("name", sorted(registry.mechanisms()))
def test_symbolic_matches_the_ball_arithmetic_rank(name):
    mech = resolve(name)
    if mech.couplings:      # the solver declines them (its transfer rules assume free joints)
        assert "--solver vp" in (registry.solvers()["symbolic"].item.applicable(mech) or "")
        return
    r = result(name)
    ours = r.coefficient_matrix(values=True)
    assert len(ours) == r.rank
    null = _null_space(ours)
    assert len(null) == len(mech.parameters) - r.rank          # rows independent
    digits = 40
    backend = Arb(digits)
    W, _ = observation_matrix(mech, backend, Trajectory.default(mech, samples=60))
    with backend.activate():
        N = arb_mat(len(mech.parameters), len(null), [null[j][i] for i in range(len(mech.parameters))
                                                      for j in range(len(null))])
        R = W * N
        wmax = max(abs(float(W[i, j].mid())) for i in range(W.nrows()) for j in range(W.ncols()))
        for j in range(len(null)):
            nmax = max(abs(float(x)) for x in null[j])
            worst = max(float(abs(R[i, j]).upper()) for i in range(R.nrows()))
            assert worst < 1e-30 * wmax * nmax, (name, j)     # row(W) within our row space
        proven = certify.analyse(W, digits, approximate_spectrum=False).rank
    assert proven == r.rank, (name, proven, r.rank)              # and of the same dimension


# ----- options and the upper-bound path --------------------------------------------------------
def test_keep_and_eliminate_first_change_the_choice_not_the_row_space():
    mech = resolve("sla_suspension")
    default = result("sla_suspension")
    kept = solve(mech, keep=["Iyy4"], eliminate_first=["mx1"], certify_rank=False)
    assert "Iyy4" not in kept.eliminated and "Izz4" in kept.eliminated
    # the first transfer that can, J71's monopole, now removes mx1 and m7 stays
    assert "mx1" in kept.eliminated and "m7" not in kept.eliminated
    assert kept.rank == default.rank
    assert same_row_space(kept.coefficient_matrix(values=True), default.coefficient_matrix(values=True))


def test_bad_option_names_are_input_errors():
    from baseparams.errors import InputError
    with pytest.raises(InputError, match="Foo"):
        solve(resolve("pendulum"), keep=["Foo"], certify_rank=False)


def test_missing_rules_make_the_rank_an_upper_bound(monkeypatch):
    """Without the S-joint rules the symbolic count is too high; the numeric check says so."""
    original = registry.transfer_rules
    monkeypatch.setattr(registry, "transfer_rules",
                        lambda name: None if name == "S" else original(name))
    r = solve(resolve("sla_suspension"), trajectory=Trajectory.default(resolve("sla_suspension"), samples=40))
    assert r.rank > 41 and not r.certified and r.rank_is_upper_bound
    cert = r.diagnostics["certificate"]
    assert cert["rank_lower_bound"] == 41 and not cert["generators_failed"]
    assert cert["generators_passed"] == cert["generators"] == 70 - r.rank
    assert any("no plugin gives transfer rules" in w for w in r.warnings)
    assert any("upper bound" in w for w in r.warnings)
    assert f"= {r.rank} base parameters (an upper bound: not certified)." in render(r)


# ----- the rank check: irrational generators, and a generator that is wrong ----------------------
def _tilted_pendulum():
    """The pendulum with its axis along (0, 1, 1) in the rod's axes: the dipole along the
    axis is (0, 1, 1)/sqrt(2), so generators carry square roots of non-squares."""
    from pathlib import Path

    from baseparams.io.loader import parse_mechanism
    text = Path(registry.mechanisms()["pendulum"].item.path).read_text()
    old = 'child_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }'
    assert text.count(old) == 1
    return parse_mechanism(text.replace(old, old.replace('axis = ["0", "0", "1"]', 'axis = ["0", "1", "1"]')),
                           "tilted_pendulum.toml")


def test_irrational_generators_are_tested():
    mech = _tilted_pendulum()
    r = solve(mech)
    der = r.derivation
    irrational = [s for s in der.steps
                  if any(not sympy.sympify(der.field.value(v)).is_Rational for v in s.vector.values())]
    assert [s.generator.multipole for s in irrational] == ["dipole"]     # (my1 + mz1)/sqrt(2)
    cert = r.diagnostics["certificate"]
    assert cert["generators"] == cert["generators_tested"] == cert["generators_passed"] == 7
    assert not cert["generators_untested"] and float(cert["generator_residual"]) < 1e-30
    # a rotation about one fixed axis: the pendulum's 3 base parameters, proven
    assert r.rank == 3 and cert["rank_lower_bound"] == 3 and r.certified and not r.rank_is_upper_bound


def _corrupt(monkeypatch, pivot, change):
    """Make ``solve`` check a wrong generator: ``change(vector, field)`` edits the reduced
    vector of the step eliminating ``pivot``, after the elimination."""
    import baseparams.plugins.solvers.symbolic.elimination as symbolic
    original = symbolic.eliminate

    def eliminate(*args, **kwargs):
        der = original(*args, **kwargs)
        step = next(s for s in der.steps if s.pivot == pivot)
        change(step.vector, der.field)
        return der

    monkeypatch.setattr(symbolic, "eliminate", eliminate)


@pytest.mark.parametrize("tilted", [False, True])
def test_a_generator_that_is_not_null_fails_the_check(monkeypatch, tilted):
    """The count is then possibly too LOW: not certified, and not called an upper bound."""
    if tilted:      # the dipole along the axis turned to (0, 1, -1)/sqrt(2): a first moment off the axis
        mech, pivot = _tilted_pendulum(), "my1"
        change = lambda v, f: v.__setitem__("mz1", -v["mz1"])  # noqa: E731
    else:           # the monopole at the pivot plus a first moment along the rod
        mech, pivot = resolve("pendulum"), "m1"
        change = lambda v, f: v.__setitem__("mx1", f.convert(1))  # noqa: E731
    _corrupt(monkeypatch, pivot, change)
    r = solve(mech)
    cert = r.diagnostics["certificate"]
    assert [g["source"].split(" condition")[0] for g in cert["generators_failed"]] == ["body 1"]
    assert float(cert["generators_failed"][0]["residual"]) > 1e-3
    assert cert["generators_tested"] == 7 and cert["generators_passed"] == 6
    assert not r.certified and not r.rank_is_upper_bound and "rank_is_upper_bound" not in r.to_json()
    assert any("failed the null-vector check" in w for w in r.warnings)
    text = render(r)
    assert "(not certified: a generator failed its null-vector check)." in text
    assert "6 of the 7 generators" in text and "upper bound" not in text


def test_scara_quill_dipoles_are_found_by_sampling():
    """Across the SCARA's vertical P joint the angular velocity is parallel to the sliding
    axis, so dipoles cross in every direction: no P rule says so, the sampling does."""
    r = result("scara")
    sampled = [t for t in r.diagnostics["transfers"] if t["condition"] == 0]
    assert {t["joint"] for t in sampled} == {"J3"}
    assert {t["eliminated"] for t in sampled} == {"mx3", "my3"}
    assert r.rank == 8


def test_body_motion_classification():
    r = result("slider_crank")
    motions = {m.label: m.motion for m in r.derivation.bodies}
    assert motions == {1: "rotation about a fixed axis", 2: "planar (constant rotation axis direction)",
                       3: "translation"}
    slider = [c for c in r.diagnostics["conditions"] if c["bodies"] == [3]]
    assert sorted(c["condition"] for c in slider) == [4, 4, 4, 6, 6, 6, 6, 6, 6]


# ----- reports and CLI ---------------------------------------------------------------------------
def test_reports_in_three_formats():
    r = result("sla_suspension")
    text = render(r, "text")
    assert "70 - 13 - 16 = 41" in text and "J71" in text and "m1' = m1 + m7" in text
    md = render(r, "markdown")
    assert "| 7 -> 1 | J71 | S | 1 | m | m7 |" in md
    assert "| 5 -> 3 | J35 | R | 1,2,5 | m, d, q | m5 mx5 Izz5 |" in md
    tex = render(r, "latex")
    assert "\\begin{tabular}" in tex and "$\\mathit{Iyy}_{1}$" in tex and "\\frac{" in tex
    with pytest.raises(ValueError):
        render(r, "html")


def test_cli_report_verb(tmp_path):
    runner = CliRunner()
    out = runner.invoke(main, ["report", "planar_2r", "--format", "markdown", "--no-certify"])
    assert out.exit_code == 0, out.output
    assert "| 2 -> 1 | J2 | R | 1 | m | m2 |" in out.output
    target = tmp_path / "r.tex"
    out = runner.invoke(main, ["report", "pendulum", "--format", "latex", "-o", str(target)])
    assert out.exit_code == 0 and "\\section*" in target.read_text()
    out = runner.invoke(main, ["report", "pendulum", "--keep", "Foo"])
    assert out.exit_code == 2 and "Foo" in out.output


def test_cli_solve_json_has_the_papers_row_space():
    """`baseparams solve sla_suspension --solver symbolic --format json`: 41 expressions whose
    exact values span the paper's rows."""
    import json
    mech = resolve("sla_suspension")
    out = CliRunner().invoke(main, ["solve", "sla_suspension", "--solver", "symbolic", "--samples", "60",
                                    "--format", "json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output[out.output.index("{"):])
    assert data["solver"] == "symbolic" and data["rank"] == 41 and data["certified"]
    rows = [[Fraction(v.get(p, "0")) for p in data["parameters"]] for v in data["expression_values"]]
    assert same_row_space(rows, symbolic_base_matrix(mech.geometry))


# ----- special geometry, found without being told --------------------------------------------------
def _sla_with_special_geometry():
    """The SLA with the two special choices of a first rebuild (docs/sla_geometry.md):
    the damper mount C in the plane where H moves, and a vertical first axis at J."""
    from pathlib import Path

    from baseparams.io.loader import parse_mechanism
    path = registry.mechanisms()["sla_suspension"].item.path
    text = Path(path).read_text()
    swaps = [
        ('Cz = "0.3"', 'Cz = "0.36"'),
        ('LD = "0.35"', 'LD = "0.39"'),                    # 0.15^2 + 0.36^2 = 0.39^2
        ('parent_frame = { point = ["-Cx", "D12 - Cy", "Cz"], axis = ["3", "-6", "-2"], ref = ["-6", "-2", "-3"] }',
         'parent_frame = { point = ["0", "D12 - Cy", "Cz"], axis = ["1", "0", "0"], ref = ["0", "-Cz", "-Cy"] }'),
        ('parent_frame = { point = ["-D31", "D12 + D13 - L10", "L7/2"], axis = ["1", "0", "0"], ref = ["0", "0", "1"] }',
         'parent_frame = { point = ["-D31", "D12 + D13 - L10", "L7/2"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }'),
        ('child_frame = { point = ["L10", "0", "0"], axis = ["0", "1", "0"], ref = ["0", "0", "1"] }',
         'child_frame = { point = ["L10", "0", "0"], axis = ["0", "0", "1"], ref = ["0", "1", "0"] }'),
    ]
    for old, new in swaps:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return parse_mechanism(text, "sla_special.toml")


def test_special_geometry_conditions_are_found_and_certified():
    mech = _sla_with_special_geometry()
    r = solve(mech, trajectory=Trajectory.default(mech, samples=60))
    conds = {(c["bodies"][0], c["eliminated"]): c["condition"] for c in r.diagnostics["conditions"]}
    # the damper swings about a fixed direction: dipole along it and five quadrupoles per body
    assert conds[(6, "mx6")] == 2 and conds[(7, "mx7")] == 2
    assert {p for (b, p) in conds if b == 7} >= {"Ixy7", "Ixz7", "Iyy7", "Iyz7", "Izz7"}
    # J at rest and g . y4 constant: the dipole along y4 at J (my4 - L10 Ixy4) has no effect
    assert conds[(4, "my4")] == 4
    assert r.certified and r.rank == 33
    # the paper's 29 null directions still hold, so our rows lie in the paper's row space
    paper = symbolic_base_matrix(mech.geometry)
    ours = r.coefficient_matrix(values=True)
    both = fmpq_mat(len(paper) + len(ours), len(paper[0]),
                    [fmpq(v.numerator, v.denominator) for row in paper + ours for v in row])
    assert both.rank() == 41


# ----- mechanisms written without [geometry] (issue 8) ---------------------------------------------
def _plain_6r(with_ref):
    """A 6R chain with every number inline (no [geometry]) and axes along z, y, x, z, y, x:
    the generators hold no geometry symbol and no square root, so the exact field had no
    symbol of its own. ``with_ref`` adds explicit x axes (the crash did not depend on it)."""
    from baseparams.io.loader import parse_mechanism
    axes = [("0", "0", "1"), ("0", "1", "0"), ("1", "0", "0")] * 2
    offsets = [("0", "0", "0"), ("0.1", "0", "0.2"), ("0.3", "0.05", "0"),
               ("0", "0.1", "0.2"), ("0.1", "0", "0.1"), ("0", "0.1", "0.1")]
    lines = ['[mechanism]\nname = "plain_6r"\n']
    for b in range(1, 7):
        lines.append(f'[[bodies]]\nlabel = {b}\nmass = "{b}"\ncom = ["0.1", "0.05", "0.02"]\n'
                     f'inertia_com = ["0.3", "0.01", "0.02", "0.35", "0.03", "0.25"]\n')
    for b, (axis, point) in enumerate(zip(axes, offsets), start=1):
        ref = ', ref = ["0", "0", "1"]' if with_ref and axis == ("1", "0", "0") else \
            ', ref = ["1", "0", "0"]' if with_ref else ""
        a = ", ".join(f'"{c}"' for c in axis)
        p = ", ".join(f'"{c}"' for c in point)
        lines.append(f'[[joints]]\ntype = "R"\nparent = {b - 1}\nchild = {b}\n'
                     f'parent_frame = {{ point = [{p}], axis = [{a}]{ref} }}\n'
                     f'child_frame = {{ point = ["0", "0", "0"], axis = [{a}]{ref} }}\n')
    q = ", ".join(f'J{b - 1}_{b} = "sin({b}*t/3) + {b}/10"' for b in range(1, 7))
    lines.append(f'[trajectory]\nt_end = "10"\nsamples = 60\nq = {{ {q} }}\n')
    return parse_mechanism("\n".join(lines), "plain_6r.toml")


@pytest.mark.parametrize("with_ref", [False, True])
def test_mechanism_without_geometry_symbols(with_ref):
    """Regression: the symbolic solver raised KeyError('_unit') when no generator held a
    geometry symbol or a radical. Rank 36 (exact solver, independently) and the same row
    space, exactly."""
    mech = _plain_6r(with_ref)
    assert not mech.geometry
    r = solve(mech)
    exact = registry.solvers()["exact"].item.solve(mech)
    assert exact.rank == 36 and r.rank == 36 and r.certified
    assert same_row_space(r.coefficient_matrix(values=True), exact.coefficient_matrix())
