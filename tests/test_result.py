"""same_row_space: equal row spaces of independent rows, exactly and to a tolerance.

Cases built by hand, where the answer is plain from the vectors: a rank-deficient basis
must not pass for a larger space, nor a list of dependent rows for a base.
"""

from fractions import Fraction

import mpmath
import pytest

from baseparams.solvers.compare import numerical_rank, same_row_space


def exact(rows):
    return [[Fraction(v) for v in row] for row in rows]


def decimal(rows):
    return [[float(v) for v in row] for row in rows]


TOL = 1e-10

CASES = [
    # (a, b, same?)
    ([[1, 0, 0], [0, 1, 0]], [[0, 1, 0], [0, 2, 0]], False),    # b spans a line, a a plane
    ([[1, 0, 0]], [[1, 0, 0], [2, 0, 0]], False),               # b's two rows are dependent
    ([[1, 0, 0], [0, 1, 0]], [[1, 1, 0], [1, -1, 0]], True),    # two bases of one plane
    ([[1, 0, 0], [0, 1, 0]], [[1, 1, 0], [0, 0, 1]], False),    # two different planes
    ([[1, 2, 3]], [[-2, -4, -6]], True),
]


@pytest.mark.parametrize("a,b,same", CASES)
def test_numeric(a, b, same):
    assert same_row_space(decimal(a), decimal(b), TOL) is same
    assert same_row_space(decimal(b), decimal(a), TOL) is same


@pytest.mark.parametrize("a,b,same", CASES)
def test_exact(a, b, same):
    assert same_row_space(exact(a), exact(b)) is same
    assert same_row_space(exact(b), exact(a)) is same


def test_tolerance_decides_near_misses():
    a = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    tilted = [[1.0, 0.0, 1e-13], [0.0, 1.0, 0.0]]
    assert same_row_space(a, tilted, 1e-10)
    assert not same_row_space(a, tilted, 1e-15)
    assert not same_row_space(exact([[1, 0, 0], [0, 1, 0]]),
                              [[Fraction(1), Fraction(0), Fraction(1, 10 ** 13)], exact([[0, 1, 0]])[0]])


def test_numerical_rank_at_high_precision():
    """A direction 1e-30 long counts at tol 1e-40 (beyond float64) and not at 1e-20;
    an mpmath value keeps its 50 digits (1/3 rounded to 53 bits would count at 1e-40)."""
    rows = [[1, 0], [1, Fraction(1, 10 ** 30)]]
    assert numerical_rank(rows, Fraction(1, 10 ** 40)) == 2
    assert numerical_rank(rows, Fraction(1, 10 ** 20)) == 1
    with mpmath.workdps(50):
        third = mpmath.mpf(1) / 3
    assert numerical_rank([[third, 1], [Fraction(1, 3), 1]], Fraction(1, 10 ** 40)) == 1
    assert numerical_rank([[1 / 3, 1], [Fraction(1, 3), 1]], Fraction(1, 10 ** 40)) == 2
    assert numerical_rank([[0, 0], [0, 0]], TOL) == 0
