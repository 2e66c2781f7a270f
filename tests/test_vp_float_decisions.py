"""vp's float64 decisions beyond FAST_DECISIONS_ABOVE parameters (issue 47): the leftmost
basis and the square block chosen in float64 (numeric/decide.py), every property proven in
balls, against the working-precision decisions on the same W and the exact solver's rref;
where float64 cannot decide (a column 1e-10 from the span of the others), the working
precision decides, with the same result as before. And W's rows sized by the rank: the
same certified result as with the default samples."""

from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat

from baseparams import registry
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric import certify, decide
from baseparams.numeric.backends import Arb
from baseparams.plugins.solvers.exact.states import rref_pivots
from baseparams.plugins.solvers.vp import balls
from baseparams.plugins.solvers.vp import solver as vp_solver
from baseparams.solvers.run import run_solver

DIGITS = 30


@pytest.fixture(scope="module")
def chain():
    mech = parse_mechanism(generate.serial_chain(3, bodies=10), "chain10.toml")
    assert len(mech.parameters) > certify.FAST_DECISIONS_ABOVE
    return mech


@pytest.fixture(scope="module")
def exact(chain):
    res = registry.solvers()["exact"].item.solve(chain)
    rows = res.coefficient_matrix()
    R, rank = fmpq_mat(len(rows), len(rows[0]), [fmpq(v.numerator, v.denominator) for r in rows for v in r]).rref()
    return R, rank


def ball_decisions(W, digits, monkeypatch, earlier=None):
    """The analysis with every decision at the working precision (the path before issue 47)."""
    with monkeypatch.context() as m:
        m.setattr(certify, "_analyse_float", lambda *args, **kwargs: None)
        return certify.analyse(W, digits, earlier=earlier)


def test_float_decisions_are_the_working_precisions_and_the_exact_rref(chain, exact, monkeypatch):
    R, rank = exact
    trajectory = Trajectory.default(chain, samples=vp_solver.default_samples(chain))
    previous = None
    for digits in (DIGITS, 2 * DIGITS):
        W, _ = observation_matrix(chain, Arb(digits), trajectory)
        fast = certify.analyse(W, digits, earlier=previous)
        slow = ball_decisions(W, digits, monkeypatch)
        assert fast.decided == "float64" and slow.decided == "ball"
        assert fast.rank == slow.rank == rank and fast.kept == slow.kept == rref_pivots(R, rank)
        assert fast.eliminated == slow.eliminated and fast.pivoting == "natural"
        assert fast.ridge_log10 >= 3 and fast.ridge_log10 == pytest.approx(slow.ridge_log10, abs=0.5)
        assert fast.sigma_r_lower > 0 and fast.tail_bound < fast.sigma_r_lower
        for i in range(fast.beta.nrows()):
            for j in range(fast.beta.ncols()):
                x = fast.beta[i, j]
                assert x.overlaps(slow.beta[i, j])
                assert balls.contains_rational(x, Fraction(int(R[i, fast.eliminated[j]].p),
                                                           int(R[i, fast.eliminated[j]].q))), (digits, i, j)
        if previous is not None:          # the second precision reuses the first one's choice
            assert fast.rows == previous.rows and fast.kept == previous.kept
        previous = fast


def _grey_zone_matrix(digits: int) -> arb_mat:
    """W (120 x 90, integers) whose column 40 is column 3 plus 1e-10 times an independent
    column: rank 61 exactly, but a float64 Gram-Schmidt at 10^-7.5 calls column 40 dependent."""
    rng = np.random.default_rng(5)
    B = rng.integers(-4, 5, size=(120, 60))
    C = rng.integers(-4, 5, size=(60, 90))
    A = (B @ C).astype(object)
    extra = rng.integers(-4, 5, size=120)
    with ctx.workdps(digits):
        tiny = arb(10) ** -10
        entries = [arb(int(A[i, j])) + (tiny * int(extra[i]) if j == 40 else 0) for i in range(120) for j in range(90)]
        for i in range(120):
            entries[i * 90 + 40] = arb(int(A[i, 3])) + tiny * int(extra[i])
        return arb_mat(120, 90, entries)


def test_where_float64_cannot_decide_the_working_precision_does(monkeypatch):
    W = _grey_zone_matrix(DIGITS)
    a = certify.analyse(W, DIGITS)
    b = ball_decisions(W, DIGITS, monkeypatch)
    assert a.decided == "ball"
    assert (a.rank, a.kept, a.pivoting) == (b.rank, b.kept, b.pivoting)
    assert a.ridge_log10 == b.ridge_log10


def test_the_leftmost_proof_refuses_a_column_that_depends_on_a_later_kept_one():
    kept, eliminated = [0, 2, 5], [1, 3, 4]
    small = arb_mat(3, 3, [1, 2, 0, 0, 1, 1, 0, 0, 0])          # column 1: kept 0 only; 3, 4: kept 0, 2
    assert certify._leftmost(small, kept, eliminated, -40.0, -20.0)
    later = arb_mat(3, 3, [1, 2, 0, 0, 1, 1, 0, 0, arb(10) ** -5])  # column 4 needs kept 5 (to 1e-5)
    assert not certify._leftmost(later, kept, eliminated, -40.0, -20.0)
    assert not certify._leftmost(small, kept, eliminated, -5.0, -20.0)   # the tail alone is too large


def test_natural_columns_and_rank_estimate_on_an_exact_low_rank_matrix():
    rng = np.random.default_rng(1)
    A = (rng.integers(-3, 4, size=(80, 12)) @ rng.integers(-3, 4, size=(12, 30))).astype(float)
    A[:, 7] = 2 * A[:, 2] - A[:, 0]                  # dependent on columns to its left
    A[:, 9] = 0.0
    exact = fmpq_mat(80, 30, [int(x) for x in A.ravel()]).rref()
    scaled = A / np.where(np.linalg.norm(A, axis=0) > 0, np.linalg.norm(A, axis=0), 1.0)
    kept, Q = decide.natural_columns(scaled, {9}, 1e-8)
    assert kept == rref_pivots(exact[0], exact[1])
    assert np.allclose(Q.T @ Q, np.eye(len(kept)), atol=1e-12)
    assert decide.rank_estimate(A) == exact[1]
    rows = decide.square_rows(Q)
    assert len(rows) == len(kept) and np.linalg.matrix_rank(A[np.ix_(rows, kept)]) == len(kept)


def test_rows_sized_by_the_rank_give_the_default_samples_result(chain, exact):
    _, rank = exact
    default = vp_solver.default_samples(chain)
    fewer = vp_solver.samples_from_rank(chain, default)
    assert fewer is not None and fewer[1] == rank and fewer[0] < default
    assert fewer[0] * len(chain.independent) >= vp_solver.ROWS_PER_RANK * rank
    small = run_solver("vp", chain, {"recover": False}).to_json()
    whole = run_solver("vp", chain, {"recover": False, "samples": default}).to_json()
    assert small["certified"] and whole["certified"] and small["rank"] == whole["rank"] == rank
    assert any("estimated in float64" in note for note in small["diagnostics"]["notes"])
    assert small["eliminated"] == whole["eliminated"]
    rows = [[float(row["expression"].get(p, 0)) for p in small["parameters"]] for row in small["base"]]
    other = [[float(row["expression"].get(p, 0)) for p in whole["parameters"]] for row in whole["base"]]
    assert np.sin(np.max(scipy.linalg.subspace_angles(np.array(rows).T, np.array(other).T))) < 1e-12


def test_no_rank_estimate_keeps_the_default_samples(chain, monkeypatch):
    monkeypatch.setattr(decide, "rank_estimate", lambda W, threshold=1e-8: 0)     # W not finite in float64
    assert vp_solver.samples_from_rank(chain, vp_solver.default_samples(chain)) is None
    small = parse_mechanism(generate.serial_chain(3, bodies=4), "chain4.toml")     # up to 80 parameters: never
    assert len(small.parameters) <= certify.FAST_DECISIONS_ABOVE
    assert vp_solver.samples_from_rank(small, 1000) is None
