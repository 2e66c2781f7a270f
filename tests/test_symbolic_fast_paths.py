"""The symbolic solver's fast paths (issue 12) against the paths they replace.

- Whole solver, on generated chains, trees, a spherical/irrational chain and a four-bar:
  every fast path on (rationals as fmpq, the float64-chosen rank proof with balls only at
  its states, exact pivot counts in the one numerical rank, the numeric prefilter of sampled transfers) gives the
  same JSON result and the same derivation report, text for text, as every one off
  (sympy's field, balls at every state and the shared ball analysis, mpmath's SVD, every
  try built exactly), except where the certificate's balls were computed (states, rows)
  and the residual they give.
- Pieces, each against an independent computation (the rank's exact pivot count against
  mpmath's SVD: tests/test_rank.py); columns_independent against dependent columns (it must refuse)
  and against the shared analysis; residual against mpmath's dot products; dedupe against
  the pairwise working-precision comparison it abbreviates; to_fmpq exactly.
"""

import json
import random
import re

import mpmath
import numpy as np
import pytest
from flint import arb_mat

from baseparams.cli.report import render
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import Subset, observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric.backends import Arb, Float64
from baseparams.numeric import rank
from baseparams.numeric.certify import analyse
from baseparams.plugins.solvers.symbolic import body_conditions, elimination, sampled_transfers
from baseparams.plugins.solvers.symbolic.rank_bound import columns_independent

CASES = {
    "chain": lambda: generate.serial_chain(2),
    "tree": lambda: generate.tree(4),
    "spherical-irrational chain": lambda: generate.serial_chain(3, spherical=0.3, irrational=0.3),
    "four-bar": lambda: generate.four_bar(1),
}


def _mechanism(case):
    return parse_mechanism(CASES[case](), f"{case}.toml")


# where the certificate's balls are computed: at the rank proof's states (fast) or at every
# state (the shared analysis); what it concludes is compared, these are not
_WHERE = ("samples", "rows", "generator_residual")


def _canonical(result):
    data = json.loads(json.dumps(result.to_json(), default=str))        # a copy
    data.pop("elapsed_s", None)
    certificate = data["diagnostics"]["certificate"]
    where = {key: certificate.pop(key) for key in _WHERE}
    text, count = re.subn(r"on \d+ states \((\d+) drawn at random, \d+ of the trajectory; \d+ rows\)",
                          r"on N states (\1 drawn at random, N of the trajectory; N rows)", render(result, "text"))
    text, residuals = re.subn(r"\|W n\| <= \S+ max", "|W n| <= R max", text)
    assert count == residuals == 1
    data["diagnostics"]["summary"] = [re.sub(r"on \d+ states proves", "on N states proves", line)
                                      for line in data["diagnostics"]["summary"]]
    return json.dumps(data, sort_keys=True), text, where


class _Reference(elimination.ExactField):
    """The reference field: sympy's even when the generators are all rational."""

    def __init__(self, mechanism, expressions):
        super().__init__(mechanism, expressions, rationals=False)


@pytest.mark.parametrize("case", sorted(CASES))
def test_fast_paths_give_the_reference_result(monkeypatch, case):
    # a fresh mechanism for each run: a closed loop's W in balls depends (in the last digit
    # of its radii, hence of the generator residual) on the float64 positions a mechanism
    # object has already cached
    fast = _canonical(elimination.solve(_mechanism(case)))
    mech = _mechanism(case)
    with monkeypatch.context() as m:
        m.setattr(elimination, "ExactField", _Reference)
        m.setattr(elimination, "columns_independent", lambda *args: False)
        m.setattr(rank, "_pivot_count", lambda *args, **kwargs: None)
        m.setattr(sampled_transfers, "PREFILTER", mpmath.inf)
        reference = _canonical(elimination.solve(mech))
    assert fast[0] == reference[0]
    assert fast[1] == reference[1]
    # balls at the random states and the proof's trajectory states only, not at all of them
    assert fast[2]["samples"] < reference[2]["samples"] and fast[2]["rows"] < reference[2]["rows"]
    assert float(fast[2]["generator_residual"]) < 1e-30 and float(reference[2]["generator_residual"]) < 1e-30


def test_the_reference_field_is_sympys_and_the_fast_one_rational():
    mech = _mechanism("chain")
    der = elimination.eliminate(mech)
    assert der.field.constant and der.field.K is None
    exprs = [v for s in der.steps for v in s.generator.vector.values()]
    assert not _Reference(mech, exprs).constant


# ----- pieces ------------------------------------------------------------------------------
def test_residual_is_the_dot_products_rounded_once():
    rng = random.Random(3)
    with mpmath.workdps(28):
        rows = body_conditions.Rows([[mpmath.mpf(rng.uniform(-1, 1)) for _ in range(20)] for _ in range(23)])
        for _ in range(20):
            n = [mpmath.mpf(rng.uniform(-1, 1)) for _ in range(20)]
            with mpmath.workdps(80):
                ref = max(abs(mpmath.fsum(a * b for a, b in zip(row, n))) for row in rows) / \
                    mpmath.sqrt(mpmath.fsum(x * x for x in n))
            got = body_conditions.residual(rows, n)
            assert abs(got - ref) <= mpmath.mpf(10) ** -26 * ref


def test_to_fmpq_is_exact():
    with mpmath.workdps(40):
        for x in [mpmath.mpf(1) / 3, -mpmath.mpf(2) ** -200 * 7, mpmath.mpf(10) ** 30, mpmath.mpf(0)]:
            q = rank.to_fmpq(x)
            with mpmath.workdps(400):
                assert mpmath.mpf(int(q.p)) / int(q.q) == x


def _dedupe_reference(items, subs, directions):
    """The pairwise comparison at working precision, without the float64 shortcut."""
    out, seen = [], []
    for name, vec in items:
        num = [body_conditions.to_number(c, subs, 28) for c in vec]
        key = num
        if directions:
            norm = mpmath.sqrt(sum(x * x for x in num))
            if norm == 0:
                continue
            key = [x / norm for x in num]
        dup = any(abs(abs(mpmath.fsum(a * b for a, b in zip(key, o))) - 1) < mpmath.mpf(10) ** -20 if directions
                  else max(abs(a - b) for a, b in zip(key, o)) < mpmath.mpf(10) ** -20 for o in seen)
        if not dup:
            seen.append(key)
            out.append(name)
    return out


@pytest.mark.parametrize("directions", [True, False])
def test_dedupe_keeps_what_the_pairwise_comparison_keeps(directions):
    import sympy
    rng = random.Random(11)
    base = [[sympy.Rational(rng.randint(-9, 9), rng.randint(1, 9)) for _ in range(3)] for _ in range(8)]
    items = []
    for k, v in enumerate(base):
        items.append((f"v{k}", v))
        items.append((f"v{k} again", [c * (-2 if directions else 1) for c in v]))              # same line / point
        items.append((f"v{k} nudged", [v[0] + sympy.Rational(1, 10 ** 15)] + v[1:]))         # different at 1e-20
    items.append(("zero", [sympy.Integer(0)] * 3))
    rng.shuffle(items)
    with mpmath.workdps(28):
        got = [name for name, _, _ in body_conditions.dedupe(items, {}, 28, directions=directions)]
        assert got == _dedupe_reference(items, {}, directions)
    assert any("nudged" in n for n in got) and not all("again" in n for n in got)


def _arb_w(mech, digits=40):
    backend = Arb(digits)
    trajectory = Trajectory.default(mech)
    batch = random_batch(mech, trajectory, seed=7919)
    blocks = [observation_matrix(mech, backend, s)[0] for s in (trajectory, batch)]
    wf = np.vstack([observation_matrix(mech, Float64(), s)[0] for s in (trajectory, batch)])
    return backend, blocks, wf


@pytest.mark.parametrize("case", ["tree", "four-bar"])
def test_rank_proof_proves_kept_columns_and_refuses_dependent_ones(case):
    mech = _mechanism(case)
    der = elimination.eliminate(mech)
    params = list(mech.parameters)
    kept = [params.index(p) for p in der.base]
    backend, blocks, wf = _arb_w(mech)
    stacked = backend.stack(*blocks)
    with backend.activate():
        assert columns_independent(blocks, wf, kept)
        assert analyse(stacked, 40, kept=kept, approximate_spectrum=False).rank == len(kept)
        # one eliminated column more: dependent on the kept ones (a generator says so)
        extra = params.index(der.eliminated[0])
        assert not columns_independent(blocks, wf, sorted(kept + [extra]))
        # a column twice is dependent whatever the rows
        assert not columns_independent(blocks, wf, kept + [kept[0]])
    # the float64 copy is W's midpoints (it only chooses rows and scales the residual)
    mids = np.array([[float(stacked[i, j].mid()) for j in range(stacked.ncols())] for i in range(stacked.nrows())])
    assert np.max(np.abs(mids - wf)) <= 1e-9 * np.max(np.abs(mids))


def test_rank_proof_refuses_a_wrong_float_copy():
    """The float64 copy only guides: a copy of another W gives no proof, never a false one."""
    mech = _mechanism("chain")
    der = elimination.eliminate(mech)
    params = list(mech.parameters)
    kept = [params.index(p) for p in der.base]
    backend, blocks, wf = _arb_w(mech)
    zero = [arb_mat(b.nrows(), b.ncols()) for b in blocks]
    with backend.activate():
        assert not columns_independent(zero, wf, kept)
        assert not columns_independent(blocks, wf[:-1], kept)


@pytest.mark.parametrize("case", ["four-bar", "spherical-irrational chain"])
def test_balls_at_some_states_are_the_rows_of_balls_at_all(case):
    """The certificate computes W in balls at the proof's trajectory states only (Subset):
    the same balls, digit for digit, as those rows of W at the whole trajectory."""
    mech = _mechanism(case)
    backend, trajectory = Arb(40), Trajectory.default(mech)
    whole = observation_matrix(mech, backend, trajectory)[0]
    states = (0, 3, trajectory.count - 1)
    some = observation_matrix(mech, backend, Subset(trajectory, states))[0]
    width = whole.nrows() // trajectory.count
    rows = [s * width + k for s in states for k in range(width)]
    assert some.nrows() == len(rows) and some.ncols() == whole.ncols()
    for a, i in enumerate(rows):
        for j in range(whole.ncols()):
            assert some[a, j].str(45, radius=True) == whole[i, j].str(45, radius=True)
    floats = observation_matrix(mech, Float64(), Subset(trajectory, states))[0]
    assert np.array_equal(floats, observation_matrix(mech, Float64(), trajectory)[0][rows])


def _steady_pendulum():
    """The pendulum turning at constant speed along its trajectory: no acceleration, so
    the trajectory's W cannot see Izz1 (a single fixed axis: no velocity terms either)."""
    from pathlib import Path

    from baseparams import registry
    text = Path(registry.mechanisms()["pendulum"].item.path).read_text()
    old = 'q = { theta = "0.8*sin(1.3*t) + 0.4*sin(3.1*t)" }'
    assert text.count(old) == 1
    return parse_mechanism(text.replace(old, 'q = { theta = "0.3*t" }'), "steady_pendulum.toml")


def test_a_generator_null_on_the_trajectory_only_fails_at_the_random_states(monkeypatch):
    """The generators' evidence comes from the random states: a vector that W of a
    non-exciting trajectory annihilates, but the mechanism's W does not, is caught."""
    mech = _steady_pendulum()
    trajectory = Trajectory.default(mech)
    izz = list(mech.parameters).index("Izz1")
    assert not np.any(observation_matrix(mech, Float64(), trajectory)[0][:, izz])
    original = elimination.eliminate

    def eliminate(*args, **kwargs):            # the monopole at the pivot, plus Izz1
        der = original(*args, **kwargs)
        step = next(s for s in der.steps if s.pivot == "m1")
        step.vector["Izz1"] = der.field.convert(1)
        return der

    monkeypatch.setattr(elimination, "eliminate", eliminate)
    r = elimination.solve(mech)
    cert = r.diagnostics["certificate"]
    assert [g["source"] for g in cert["generators_failed"]] == ["body 1 condition 1 (monopole at origin)"]
    assert cert["generators_passed"] == cert["generators"] - 1 and not r.certified
    # without the corruption: the same trajectory, certified by the random states
    monkeypatch.setattr(elimination, "eliminate", original)
    clean = elimination.solve(_steady_pendulum())
    assert clean.rank == 3 and clean.certified


def test_without_float64_the_shared_analysis_certifies(monkeypatch):
    """Float64 W refused (e.g. over the memory limit): balls at every state, and the
    shared ball analysis proves the rank; the same verdicts."""
    mech = _mechanism("four-bar")
    fast = elimination.solve(mech).diagnostics["certificate"]
    original = elimination.observation_matrix

    def no_float64(mechanism, backend, states):
        if isinstance(backend, Float64):
            raise MemoryError("refused")
        return original(mechanism, backend, states)

    monkeypatch.setattr(elimination, "observation_matrix", no_float64)
    slow = elimination.solve(_mechanism("four-bar")).diagnostics["certificate"]
    assert slow["samples"] == Trajectory.default(mech).count + slow["random_states"] > fast["samples"]
    for key in ("rank_lower_bound", "kept_columns_proven", "generators_tested", "generators_passed"):
        assert slow[key] == fast[key]


@pytest.mark.parametrize("case", ["four-bar", "tree"])
def test_rows_chosen_among_all_when_the_random_ones_alone_fail(monkeypatch, case):
    """The certificate's second stage: when the random states' rows alone prove nothing,
    rows are chosen among all states and balls computed at the trajectory states among
    them; the verdicts are those of the first stage."""
    first = elimination.solve(_mechanism(case)).diagnostics["certificate"]
    assert first["samples"] == first["random_states"]          # the random rows sufficed
    original = elimination.columns_independent
    calls = []

    def not_alone(blocks, wf, kept):
        calls.append(len(blocks))
        return False if len(blocks) == 1 else original(blocks, wf, kept)

    monkeypatch.setattr(elimination, "columns_independent", not_alone)
    second = elimination.solve(_mechanism(case)).diagnostics["certificate"]
    assert calls == [1, 2]               # the random rows alone, then with trajectory states
    assert first["samples"] < second["samples"] < Trajectory.default(_mechanism(case)).count
    for key in ("rank_lower_bound", "kept_columns_proven", "generators_tested", "generators_passed"):
        assert second[key] == first[key]
