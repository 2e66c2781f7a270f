"""vp at scale: the fast paths of the certified analysis against independent results.

- The blocked eliminations (panels, compaction to the open columns, rows of L on a grid)
  against exact integer arithmetic: the rank of A (fmpz_mat) and the pivot columns of its
  exact rref (fmpq_mat), on matrices larger than a panel.
- The fast column-exponent rule against mpmath, on the columns that take its fallbacks.
- The Frobenius bound (one dot product in C) against the exact sum of squares.
- The fast decisions used beyond FAST_DECISIONS_ABOVE parameters (Gram matrix on a grid,
  rows chosen in float64, the refinement that may be skipped, row hints) against the
  working-precision decisions on the same W, and both against the exact solver.
- The rational recovery confirmed from the square block alone (W at the states its rows
  come from) against the exact solver's rref, on a generated chain of 90 parameters.
"""

import copy
import math
import random
from fractions import Fraction

import mpmath
import pytest
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat, fmpz_mat

from baseparams import registry
from baseparams.plugins.solvers.exact.states import rref_pivots
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric import certify
from baseparams.plugins.solvers.vp import balls
from baseparams.numeric.backends import Arb
from baseparams.plugins.solvers.vp import solver as vp_solver

DIGITS = 30


def exact_fraction(x):
    return Fraction(int(x.p), int(x.q))


@pytest.fixture(scope="module")
def chain():
    """A random serial chain of 9 bodies: 90 parameters, beyond FAST_DECISIONS_ABOVE."""
    mech = parse_mechanism(generate.serial_chain(2, bodies=9), "chain9.toml")
    assert len(mech.parameters) > certify.FAST_DECISIONS_ABOVE
    return mech


@pytest.fixture(scope="module")
def chain_W(chain):
    trajectory = Trajectory.default(chain, samples=vp_solver.default_samples(chain))
    W, _ = observation_matrix(chain, Arb(DIGITS), trajectory)
    return W


@pytest.fixture(scope="module")
def exact_result(chain):
    res = registry.solvers()["exact"].item.solve(chain)
    rows = res.coefficient_matrix()
    R, rank = fmpq_mat(len(rows), len(rows[0]), [fmpq(v.numerator, v.denominator) for r in rows for v in r]).rref()
    return res, R, rank


# ----- eliminations against exact integer arithmetic ----------------------------------------
def _low_rank_integer_matrix(seed, m, n, k, zero_columns=()):
    """A = B C (m x n, rank k), small random integers, with some columns set to zero and a
    few columns repeated (dependent columns on the left of independent ones)."""
    rng = random.Random(seed)
    B = [[rng.randint(-4, 4) for _ in range(k)] for _ in range(m)]
    C = [[rng.randint(-4, 4) for _ in range(n)] for _ in range(k)]
    A = [[sum(B[i][t] * C[t][j] for t in range(k)) for j in range(n)] for i in range(m)]
    for j in zero_columns:
        for row in A:
            row[j] = 0
    for j in range(5, min(n, 70), 11):          # dependent on the columns just before them
        for row in A:
            row[j] = row[j - 1] - 2 * row[j - 3]
    return A


@pytest.mark.parametrize("seed, m, n, k", [(1, 150, 100, 70), (2, 220, 150, 140), (3, 90, 80, 20)])
def test_eliminations_give_the_exact_rank_and_leftmost_basis(seed, m, n, k):
    A = _low_rank_integer_matrix(seed, m, n, k, zero_columns=(3, 40))
    exact = fmpz_mat(A)
    rank = exact.rank()
    R, r2 = fmpq_mat(A).rref()
    leftmost = rref_pivots(R, r2)
    with ctx.workdps(DIGITS):
        W = arb_mat(A)
        G = W.transpose() * W
        gmax = max(float(G[i, i].mid()) for i in range(n))
        noise = arb(certify.NOISE_FACTOR * n * gmax) * arb(10) ** (-DIGITS)
        strict = arb(gmax) * arb(10) ** (-(DIGITS // 2))
        zero = [j for j in range(n) if all(A[i][j] == 0 for i in range(m))]
        order, pivots = certify._approximate_pivots(G, noise, skip=zero)
        natural, factor = certify._natural_basis(G, strict, len(order), skip=zero)
        assert len(order) == rank
        assert natural == leftmost
        assert natural != list(range(len(natural)))     # the leftmost basis skips columns
        # R^T R = G_KK to the working precision (the factor feeds the row choice)
        Gkk = arb_mat(len(natural), len(natural), [G[i, j] for i in natural for j in natural])
        difference = (factor.transpose() * factor - Gkk).mid()
        assert max(abs(float(x)) for x in difference.entries()) <= 1e-20 * gmax
        # the Cholesky of any kept set, from its own elimination, is the same factor
        again = certify._cholesky_mid(G, natural)
        assert all(abs(float((x - y).mid())) <= 1e-20 * gmax for x, y in zip(again.entries(), factor.entries()))


def test_cholesky_of_a_dependent_set_is_refused():
    A = _low_rank_integer_matrix(4, 80, 70, 30)
    with ctx.workdps(DIGITS):
        W = arb_mat(A)
        G = W.transpose() * W
        assert certify._cholesky_mid(G, list(range(40))) is None       # 40 columns of rank 30


# ----- column exponents against mpmath -----------------------------------------------------
def test_column_exponents_fast_rule_equals_the_entrywise_rule():
    with ctx.workdps(DIGITS):
        half = arb(2) ** arb(fmpq(10 ** 9 + 2, 2 * 10 ** 9))    # 2^(1/2 + 1e-9): log2 just above k + 1/2
        columns = [
            [arb(3), arb(-4), arb(0)],                                  # norm 5
            [arb("1e-31 +/- 1e-30"), arb("-2e-31 +/- 1e-30"), arb(0)],  # zero: every ball holds 0
            [arb("0.5 +/- 1"), arb("0.3 +/- 0.01"), arb(0)],            # largest holds 0, another not
            [half * 8, arb(0), arb(0)],                                  # log2 = 3.5 + 1e-9: fallback
            [arb(10) ** -320, arb(3) * arb(10) ** -321, arb(0)],        # below float range
            [arb(10) ** 330, arb(7) * arb(10) ** 329, arb(1)],          # above float range
            [arb(0), arb(0), arb(0)],
        ]
        W = arb_mat([[col[i] for col in columns] for i in range(3)])
        exponents, zero = certify._column_exponents(W)
    assert zero == [1, 6]
    with mpmath.workdps(50):           # local: the global precision is neither read nor left changed
        for j, col in enumerate(columns):
            if j in zero:
                assert exponents[j] == 0
                continue
            norm = mpmath.sqrt(sum(mpmath.mpf(x.mid().str(60, radius=False)) ** 2 for x in col))
            assert exponents[j] == int(mpmath.nint(mpmath.log(norm, 2))), j


# ----- the Frobenius bound against exact arithmetic ------------------------------------------
def test_frobenius_bound_contains_and_hugs_the_exact_norm():
    rng = random.Random(5)
    with ctx.workdps(DIGITS):
        values = []
        for _ in range(60 * 40):
            mid = arb(rng.uniform(-1, 1)) * arb(10) ** rng.randint(-30, 0)
            values.append(arb(mid, arb(10) ** -32 * rng.random()))
        M = arb_mat(60, 40, values)
        bound = certify.frobenius_upper(M)
    # the largest sum of squares over the balls: (|mid| + rad)^2 per entry, exactly
    exact = sum((abs(balls._dyadic(x.mid())) + balls._dyadic(arb(x.rad()))) ** 2 for x in values)
    b = balls._dyadic(bound)
    assert b * b >= exact
    assert b * b <= exact * Fraction(1001, 1000)


# ----- fast decisions against working-precision decisions and the exact solver ---------------
def test_fast_decisions_agree_with_working_precision_ones_and_the_exact_solver(chain, chain_W, exact_result,
                                                                                  monkeypatch):
    fast = certify.analyse(chain_W, DIGITS)
    monkeypatch.setattr(certify, "FAST_DECISIONS_ABOVE", 10 ** 9)
    slow = certify.analyse(chain_W, DIGITS)
    monkeypatch.undo()
    res, R, rank = exact_result
    assert fast.rank == slow.rank == rank == res.rank
    assert fast.kept == slow.kept == rref_pivots(R, rank)
    assert fast.ridge_log10 >= 3 and fast.ridge_log10 == pytest.approx(slow.ridge_log10, abs=0.5)
    for i in range(fast.beta.nrows()):
        for j in range(fast.beta.ncols()):
            x = fast.beta[i, j]
            assert x.overlaps(slow.beta[i, j])
            assert balls.contains_rational(x, exact_fraction(R[i, fast.eliminated[j]])), (i, j)


def test_rows_of_an_earlier_analysis_are_used_and_keep_the_claims(chain, chain_W, exact_result, monkeypatch):
    first = certify.analyse(chain_W, DIGITS)
    W60, _ = observation_matrix(chain, Arb(2 * DIGITS),
                                Trajectory.default(chain, samples=vp_solver.default_samples(chain)))

    def no_choice(*args, **kwargs):
        raise AssertionError("the earlier rows should have been used")

    monkeypatch.setattr(certify, "_select_rows_float64", no_choice)
    monkeypatch.setattr(certify, "_select_rows", no_choice)
    hinted = certify.analyse(W60, 2 * DIGITS, earlier=first)
    monkeypatch.undo()
    _, R, _ = exact_result
    assert hinted.rows == first.rows and hinted.kept == first.kept
    for i in range(hinted.beta.nrows()):
        for j in range(hinted.beta.ncols()):
            assert balls.contains_rational(hinted.beta[i, j], exact_fraction(R[i, hinted.eliminated[j]]))
    # a useless hint (a block of one repeated row) falls back to a proper choice
    useless = copy.copy(first)
    useless.rows = [0] * len(first.rows)
    again = certify.analyse(chain_W, DIGITS, earlier=useless)
    assert again.kept == first.kept and again.rows != useless.rows


def test_tail_values_are_the_residual_of_the_analysed_W(chain, chain_W):
    a = certify.analyse(chain_W, DIGITS)
    cached = balls.tail_singular_values(chain_W, a)
    copy = arb_mat(chain_W.nrows(), chain_W.ncols(), chain_W.entries())     # another object: recomputed
    recomputed = balls.tail_singular_values(copy, a)
    assert cached == recomputed
    assert len(cached) == len(a.eliminated)
    assert all(float(v) <= 10 * float(a.tail_bound.mid()) for v in cached)     # Weyl: below the tail bound


# ----- the solver: recovery from the square block, against exact rationals -------------------
def test_vp_recovers_the_exact_rref_from_the_square_block(chain, exact_result):
    res, R, rank = exact_result
    vp = registry.solvers()["vp"].item.solve(chain)
    recovery = vp.diagnostics.details["rational_recovery"]
    assert vp.certified and vp.rank == rank
    assert recovery["succeeded"] and recovery["confirmed_at_digits"] == 120
    params = vp.parameters
    pivots = rref_pivots(R, rank)
    assert vp.kept == [params[j] for j in pivots]
    for i, row in enumerate(recovery["base"]):
        for j, p in enumerate(params):
            expected = exact_fraction(R[i, j])
            got = Fraction(row["expression"][p]) if p in row["expression"] else Fraction(0)
            assert got == expected, (row["name"], p)


def test_beta_from_rows_encloses_the_exact_beta_at_higher_precision(chain, exact_result):
    _, R, _ = exact_result
    trajectory = Trajectory.default(chain, samples=vp_solver.default_samples(chain))
    W, _ = observation_matrix(chain, Arb(DIGITS), trajectory)
    a = certify.analyse(W, DIGITS)
    states = {row // len(chain.independent) for row in a.rows}
    assert len(states) < trajectory.count          # only some states are evaluated again
    beta = vp_solver._beta_from_rows(chain, 2 * DIGITS, trajectory, (), a)
    for i in range(beta.nrows()):
        for j in range(beta.ncols()):
            x = beta[i, j]
            assert balls.contains_rational(x, exact_fraction(R[i, a.eliminated[j]]))
            assert x.rad() < a.beta[i, j].rad() or a.beta[i, j].rad() == 0


def test_log10_matches_mpmath_far_outside_float_range():
    rng = random.Random(9)
    for _ in range(200):
        e = rng.randint(-100000, 100000)
        x = arb(rng.uniform(1, 10)) * arb(10) ** e
        with mpmath.workdps(40):
            expected = float(mpmath.log10(mpmath.mpf(x.mid().str(40, radius=False))))
        assert certify.log10(x) == pytest.approx(expected, rel=1e-13, abs=1e-9)
    assert certify.log10(arb(0)) == -math.inf
