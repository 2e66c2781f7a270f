"""Comparing base-parameter results: do two solvers describe the same base parameters?

Two results describe the same base parameters exactly when their coefficient matrices
(rank x parameters, :meth:`BaseParameterResult.coefficient_matrix`) have the same row
space; :func:`same_row_space` checks that exactly for rational coefficients and by
numerical ranks, to a tolerance, for decimals. Cross-validation of solvers builds on it.
"""

import math
from fractions import Fraction

import mpmath
import numpy as np
from flint import arb, arb_mat, fmpq, fmpq_mat

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

    The squared singular values are the eigenvalues of the Gram matrix, a symmetric
    eigenproblem. In float64 first (numpy's ``eigvalsh``): it decides when every eigenvalue
    lies farther from the cut ``tol^2 * largest`` than the rounding of the Gram matrix and
    of the eigensolver can move it (64 max(m, n) eps largest). Otherwise the Gram matrix is
    formed from the exact entries in python-flint at ``2 * log10(1/tol) + 30`` digits (at
    least 60) and its eigenvalues computed at that precision by mpmath's symmetric solver
    (``eigsy``). (python-flint's general ``acb_mat.eig(algorithm="approx")``, used here
    before, returned an eigenvalue 0.16 for one of 25 zeros of a 60 x 60 Gram matrix
    whose other eigenvalues were right: tests/test_result.py keeps that case.)
    """
    exact = [[_to_fraction(v) for v in row] for row in rows]
    exact = [row for row in exact if any(v != 0 for v in row)]
    if not exact:
        return 0
    tol = Fraction(tol)
    m, n = len(exact), len(exact[0])
    count = _float64_rank(exact, float(tol))
    if count is not None:
        return count
    digits = max(60, 2 * math.ceil(-math.log10(tol)) + 30) if tol < 1 else 60
    with Arb(digits).activate():
        entries = []
        for row in exact:
            values = [arb(fmpq(v.numerator, v.denominator)) for v in row]
            norm = sum((v * v for v in values), arb(0)).sqrt()
            entries += [v / norm for v in values]
        A = arb_mat(m, n, entries)
        G = A * A.transpose() if m <= n else A.transpose() * A
    with mpmath.workdps(digits):
        size = G.nrows()
        gram = mpmath.matrix([[mpmath.mpf(G[i, j].mid().str(digits + 5, radius=False)) for j in range(size)]
                              for i in range(size)])
        squares = [abs(x) for x in mpmath.eigsy(gram, eigvals_only=True)]
        largest = max(squares)
        cut = largest * mpmath.mpf(tol.numerator) / tol.denominator * mpmath.mpf(tol.numerator) / tol.denominator
        return sum(1 for x in squares if x > cut)


def _float64_rank(exact, tol: float) -> int | None:
    """:func:`numerical_rank` decided in float64, or None when an eigenvalue lies within
    rounding reach of the cut (or the rows do not fit in float64)."""
    rows = []
    for row in exact:
        peak = max(abs(v) for v in row)
        rows.append([float(v / peak) for v in row])       # exact division: no overflow
    a = np.array(rows)
    a /= np.linalg.norm(a, axis=1)[:, None]
    gram = a @ a.T if a.shape[0] <= a.shape[1] else a.T @ a
    squares = np.linalg.eigvalsh(gram)
    largest = float(squares.max())
    cut = largest * tol * tol
    reach = 64 * max(a.shape) * np.finfo(float).eps * largest
    if not np.isfinite(largest) or cut <= reach or np.any(np.abs(squares - cut) <= reach):
        return None
    return int(np.sum(squares > cut))


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
