"""Comparing base-parameter results: do two solvers describe the same base parameters?

Two results describe the same base parameters exactly when their coefficient matrices
(rank x parameters, :meth:`BaseParameterResult.coefficient_matrix`) have the same row
space; :func:`same_row_space` checks that exactly for rational coefficients and by
numerical ranks, to a tolerance, for decimals. Cross-validation of solvers builds on it.
"""

import math
from fractions import Fraction

import mpmath
from flint import acb_mat, arb, arb_mat, fmpq, fmpq_mat

from baseparams.numeric.backends import Arb


def same_row_space(a, b, tol=None):
    """Do the base parameter coefficient matrices ``a`` and ``b`` (lists of rows) describe
    the same base parameters: independent rows spanning the same row space?

    span(a) and span(b) both lie in span(a + b) (the rows of both), so they are equal
    exactly when the three have the same dimension. The rows of each must also be
    independent: a result whose rows are dependent (``[[1, 0, 0], [2, 0, 0]]``) lists more
    base parameters than it describes, and is not the same as one listing them once.
    Exact (rational ranks) when every entry is a Fraction and ``tol`` is None; otherwise
    numerical ranks (:func:`numerical_rank`) with the relative tolerance ``tol`` (default 1e-10).
    """
    if tol is None and all(isinstance(v, Fraction) for row in a + b for v in row):
        rank = _rank_exact
    else:
        tol = Fraction(1, 10 ** 10) if tol is None else tol

        def rank(rows):
            return numerical_rank(rows, tol)
    ra, rb = rank(a), rank(b)
    return ra == len(a) and rb == len(b) and ra == rb == rank(a + b)


def _rank_exact(rows):
    if not rows:
        return 0
    m = fmpq_mat(len(rows), len(rows[0]), [fmpq(v.numerator, v.denominator) for row in rows for v in row])
    return m.rank()


def numerical_rank(rows, tol):
    """Singular values above ``tol`` times the largest, of the rows scaled to unit length
    (so that a row's size does not decide whether it counts).

    The squared singular values are the eigenvalues of the Gram matrix, computed from the
    exact entries in python-flint at ``2 * log10(1/tol) + 30`` digits (at least 60), far
    below ``tol^2``: approximate eigenvalues (``acb_mat.eig``) serve, as only which side of
    ``tol^2`` each falls on matters.
    """
    exact = [[_to_fraction(v) for v in row] for row in rows]
    exact = [row for row in exact if any(v != 0 for v in row)]
    if not exact:
        return 0
    tol = Fraction(tol)
    digits = max(60, 2 * math.ceil(-math.log10(tol)) + 30) if tol < 1 else 60
    m, n = len(exact), len(exact[0])
    with Arb(digits).activate():
        entries = []
        for row in exact:
            values = [arb(fmpq(v.numerator, v.denominator)) for v in row]
            norm = sum((v * v for v in values), arb(0)).sqrt()
            entries += [v / norm for v in values]
        A = arb_mat(m, n, entries)
        G = A * A.transpose() if m <= n else A.transpose() * A
        squares = [abs(e.real.mid()) for e in acb_mat(G).eig(algorithm="approx")]
        largest = max(squares)
        cut = largest * arb(fmpq(tol.numerator, tol.denominator)) ** 2
        return sum(1 for x in squares if x > cut)


def _to_fraction(v):
    """An exact Fraction of a coefficient value (Fraction, int, float, mpmath mpf)."""
    if isinstance(v, (Fraction, int)):
        return Fraction(v)
    if isinstance(v, float):
        return Fraction(v)
    if isinstance(v, mpmath.mpf):
        man, exp = v.man_exp            # man is unsigned (mpmath 1.3): the sign comes apart
        return (-1 if v < 0 else 1) * Fraction(man) * Fraction(2) ** exp
    return Fraction(str(v))
