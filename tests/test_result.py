"""same_row_space: equal row spaces of independent rows, exactly and to a tolerance.

Cases built by hand, where the answer is plain from the vectors: a rank-deficient basis
must not pass for a larger space, nor a list of dependent rows for a base.
"""

from fractions import Fraction

import mpmath
import pytest

from baseparams.numeric.rank import numerical_rank
from baseparams.solvers.compare import same_row_space


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
    assert numerical_rank(rows, Fraction(1, 10 ** 40), unit_rows=True) == 2
    assert numerical_rank(rows, Fraction(1, 10 ** 20), unit_rows=True) == 1
    with mpmath.workdps(50):
        third = mpmath.mpf(1) / 3
    assert numerical_rank([[third, 1], [Fraction(1, 3), 1]], Fraction(1, 10 ** 40), unit_rows=True) == 1
    assert numerical_rank([[1 / 3, 1], [Fraction(1, 3), 1]], Fraction(1, 10 ** 40), unit_rows=True) == 2
    assert numerical_rank([[0, 0], [0, 0]], TOL, unit_rows=True) == 0


def _known_rank(rank, rows, cols, seed):
    """Rational rows of rank exactly ``rank`` (a product of random integer matrices): the
    Gram matrix has max(rows, cols) - rank zero eigenvalues, a cluster."""
    import random
    rng = random.Random(seed)
    left = [[Fraction(rng.randint(-9, 9)) for _ in range(rank)] for _ in range(rows)]
    right = [[Fraction(rng.randint(-9, 9)) for _ in range(cols)] for _ in range(rank)]
    return [[sum(row[k] * right[k][j] for k in range(rank)) for j in range(cols)] for row in left]


@pytest.mark.parametrize("rank,rows,cols,seed", [(35, 70, 60, 1), (12, 40, 30, 2), (3, 9, 10, 3), (20, 20, 20, 4)])
def test_numerical_rank_is_the_svd_count_with_clustered_zeros(rank, rows, cols, seed):
    """Against numpy's SVD (float64 suffices at tol 1e-6 with these clear gaps), on the
    float64 path and on the high-precision one."""
    import numpy as np
    a = _known_rank(rank, rows, cols, seed)
    sv = np.linalg.svd(np.array([[float(v) for v in row] for row in a])
                       / np.linalg.norm(np.array([[float(v) for v in row] for row in a]), axis=1)[:, None],
                       compute_uv=False)
    assert int(np.sum(sv > 1e-6 * sv[0])) == rank
    assert numerical_rank(a, 1e-6, unit_rows=True) == rank               # float64 decides
    assert numerical_rank(a, Fraction(1, 10 ** 20), unit_rows=True) == rank      # beyond float64: mpmath's eigsy


def test_clustered_zero_eigenvalues_are_not_miscounted():
    """The rows of dp's and the exact solver's base parameters of a generated 12-body chain
    span one space (dp's rows lie in the exact one to 5e-13): 35 singular values, then 25
    zeros. python-flint's general approximate eigensolver, used here before, gave one of
    the 25 zero eigenvalues of their Gram matrix as 0.16, so the spaces looked different."""
    from baseparams import registry
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    text = generate.serial_chain(1009, max_bodies=12, spherical=0.1, samples=30)
    results = {name: registry.solvers()[name].item.solve(parse_mechanism(text, "gen_chain_1009.toml"))
               for name in ("dp", "exact")}
    a, b = results["dp"].coefficient_matrix(), results["exact"].coefficient_matrix()
    assert len(a) == len(b) == 35
    assert numerical_rank(a + b, 1e-6, unit_rows=True) == 35
    assert same_row_space(a, b, tol=1e-6)
