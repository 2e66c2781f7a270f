"""The one numerical rank (baseparams.numeric.rank): each of its three decisions against an
independent count (numpy's or mpmath's SVD of matrices built with known singular values),
rows as they are and scaled to unit length, and the singular-value form dp uses."""

import random
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from flint import fmpq_mat

from baseparams.numeric import rank
from baseparams.numeric.rank import numerical_rank
from baseparams.plugins.solvers.symbolic.body_conditions import NULL_TOL, Rows


def _with_singular_values(rows, cols, singular, seed, dps=60):
    """rows x cols at ``dps`` digits with the given singular values (the rest 0): mpmath rows."""
    rng = random.Random(seed)
    with mpmath.workdps(dps):
        u, _ = mpmath.qr(mpmath.matrix([[rng.uniform(-1, 1) for _ in range(rows)] for _ in range(rows)]))
        v, _ = mpmath.qr(mpmath.matrix([[rng.uniform(-1, 1) for _ in range(cols)] for _ in range(cols)]))
        s = mpmath.zeros(rows, cols)
        for k, x in enumerate(singular):
            s[k, k] = x
        a = u * s * v.T
        return [[+a[i, j] for j in range(cols)] for i in range(rows)]


def _svd_count(rows, tol, dps=80):
    with mpmath.workdps(dps):
        s = [abs(x) for x in mpmath.svd_r(mpmath.matrix(rows), compute_uv=False)]
        cut = mpmath.mpf(tol.numerator) / tol.denominator if isinstance(tol, Fraction) else mpmath.mpf(tol)
        return sum(1 for x in s if x > cut * max(s))


CASES = [  # (rows, cols, singular values, tolerance)
    (12, 8, [1, 0.5, 0.2, 1e-3], 1e-5),                       # float64 decides
    (23, 10, [1, 1e-3, 1e-9, 1e-12], Fraction(1, 10 ** 14)),   # beyond float64: exact pivots
    (9, 14, [3, 1, 2e-20, 1e-31], Fraction(1, 10 ** 25)),      # wide; 2e-20 counts, 1e-31 does not
    (30, 20, [1] * 12 + [1e-40] * 3, Fraction(1, 10 ** 30)),   # a cluster far below the cut
]


@pytest.mark.parametrize("m, n, singular, tol", CASES)
def test_each_decision_is_the_svd_count(m, n, singular, tol, monkeypatch):
    rows = _with_singular_values(m, n, singular, seed=m + n)
    want = _svd_count(rows, tol)
    assert want == sum(1 for s in singular if s > float(tol) * max(singular))
    assert numerical_rank(rows, tol) == want
    # the last resort alone (the first two declined) gives the same count
    monkeypatch.setattr(rank, "_float64_count", lambda *args: None)
    monkeypatch.setattr(rank, "_pivot_count", lambda *args: None)
    assert numerical_rank(rows, tol) == want


def test_the_steps_decline_rather_than_guess():
    """A singular value 1.2 times the cut: float64 cannot see it, the exact pivot count's
    margin (10 in s) is not met; the high-precision eigenvalues decide, as the SVD."""
    tol = Fraction(1, 10 ** 8)
    for factor, want in ((1.2, 3), (1 / 1.2, 2)):
        rows = _with_singular_values(15, 7, [1, 0.4, factor * 1e-8], seed=3)
        a = rank._exact(rows)
        assert rank._float64_count(a, float(tol), False) is None
        assert rank._pivot_count(a, tol) is None
        assert numerical_rank(rows, tol) == _svd_count(rows, tol) == want


def test_unit_rows_scale_each_row_first():
    """Rows of sizes 1 and 1e-12, independent: as they are, the small row is below a 1e-9
    cut; scaled to unit length, both count."""
    rows = [[1, 0, 0], [0, Fraction(1, 10 ** 12), 0]]
    assert numerical_rank(rows, 1e-9) == 1
    assert numerical_rank(rows, 1e-9, unit_rows=True) == 2
    assert numerical_rank(fmpq_mat(2, 3, [1, 0, 0, 0, 0, 0]), 1e-9) == 1       # a zero row counts for nothing
    assert numerical_rank([[0, 0]], 1e-9) == 0


def test_singular_values_are_counted_as_given():
    """dp's rule: s_i > tol * s_max (numpy's matrix_rank with that tolerance)."""
    rng = np.random.default_rng(4)
    a = rng.standard_normal((20, 6)) @ rng.standard_normal((6, 9))
    s = np.linalg.svd(a, compute_uv=False)
    tol = max(a.shape) * np.finfo(float).eps
    assert numerical_rank(singular_values=s, tol=tol) == np.linalg.matrix_rank(a) == 6
    assert numerical_rank(singular_values=[], tol=tol) == 0
    with pytest.raises(ValueError):
        numerical_rank([[1]], 1e-3, singular_values=[1.0])


# ----- the symbolic solver's use: its sampled rows as they are, at NULL_TOL ---------------
@pytest.mark.parametrize("singular,expected", [
    ([1, 0.5, 0.1], 3),
    ([1, 1e-3, 1e-8, 1e-12], 4),                       # 1e-12 > 1e-14: counted
    ([1, 1e-2] + [mpmath.mpf(10) ** -24] * 3, 2),      # 1e-24: noise
    ([1] * 10, 10),
    ([], 0),
])
def test_the_exact_pivot_count_is_the_svd_count(singular, expected):
    """The symbolic solver's rank (the one numerical rank, on the rows as they are): its
    exact-rational step decides alone, and agrees with mpmath's SVD."""
    tol = NULL_TOL
    with mpmath.workdps(28):
        rows = Rows(_with_singular_values(23, 10, singular, seed=len(singular), dps=60))
        assert _svd_count(rows, tol, dps=28) == expected
        assert rank._pivot_count(rows.exact(), rank._fraction(tol)) == expected
        assert rank.numerical_rank(rows.exact(), tol) == expected


def test_the_pivot_count_declines_near_the_threshold_and_the_precise_count_decides():
    tol = NULL_TOL
    with mpmath.workdps(28):
        rows = Rows(_with_singular_values(23, 10, [1, 0.3, mpmath.mpf(10) ** -14 * 1.5], seed=5))     # near the tolerance
        assert rank._pivot_count(rows.exact(), rank._fraction(tol)) is None
        assert rank.numerical_rank(rows.exact(), tol) == _svd_count(rows, tol, dps=28) == 3
        rows = Rows(_with_singular_values(23, 10, [1, 0.3, mpmath.mpf(10) ** -14 / 1.5], seed=5))
        assert rank._pivot_count(rows.exact(), rank._fraction(tol)) is None
        assert rank.numerical_rank(rows.exact(), tol) == _svd_count(rows, tol, dps=28) == 2
