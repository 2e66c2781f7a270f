"""The one numerical rank: how many singular values of a matrix exceed ``tol`` times the
largest, decided so that rounding cannot change the count.

Callers (every numerical rank in baseparams is this function):

- comparing base-parameter results (:func:`baseparams.solvers.compare.same_row_space`):
  rows of coefficients, each scaled to unit length first (``unit_rows=True``), so that a
  row's size does not decide whether it counts;
- the symbolic solver's body conditions: the sampled Lagrangian rows, as they are;
- dp's rank by the tolerance ``max(shape) eps s_max`` (``singular_values=``, its SVD's).

What is *not* a numerical rank, and lives elsewhere on purpose: the rank proven from balls
(:func:`baseparams.numeric.certify.analyse`, a lower bound with a certificate), the exact
rank of a rational matrix (python-flint ``fmpq_mat.rank``), and greedy choices of
independent rows or columns (``independent_rows``, pivoted QR), which pick indices.
"""

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import Union

import mpmath
import numpy as np
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat

# an entry given exactly: every float, mpmath number and rational is the rational it stands for
Entry = Union[int, float, Fraction, fmpq, mpmath.mpf]
Tolerance = Union[float, Fraction, mpmath.mpf]
EXACT_UP_TO = 60        # columns (of the smaller Gram side): the exact-rational decision is tried up to here


def numerical_rank(matrix: Sequence[Sequence[Entry]] | fmpq_mat | None = None, tol: Tolerance = 0.0, *,
                   singular_values: Sequence[float] | np.ndarray | None = None,
                   unit_rows: bool = False) -> int:
    """The number of singular values above ``tol`` times the largest.

    ``singular_values`` given (dp's SVD): they are counted as they are. A ``matrix`` (rows
    of exact entries, or an ``fmpq_mat``; rows of zeros count for nothing) is decided on
    its Gram matrix, whose eigenvalues are the squared singular values, by the first of:

    1. float64 (numpy's ``eigvalsh``), when every eigenvalue lies farther from the cut
       ``tol^2 * largest`` than the rounding of the Gram matrix and of the eigensolver
       can move it (``64 max(m, n) eps largest``): tolerances above about 1e-6;
    2. exact rational arithmetic (rows as they are, up to EXACT_UP_TO on the smaller side):
       pivoted LDL^T of the Gram matrix with a proof that the count is the SVD's with a
       margin of 10 in s (:func:`_pivot_count`);
    3. the Gram matrix formed in python-flint at ``2 log10(1/tol) + 30`` digits (at least
       60) and its eigenvalues by mpmath's symmetric solver (``eigsy``) at those digits.
       (python-flint's general ``acb_mat.eig(algorithm="approx")`` gave an eigenvalue 0.16
       for one of 25 zeros of a 60 x 60 Gram matrix: tests/test_result.py keeps the case.)

    ``unit_rows``: each row scaled to unit length first (step 2 is then skipped: the
    scaling is not rational).
    """
    exact_tol = _fraction(tol)
    if singular_values is not None:
        if matrix is not None:
            raise ValueError("numerical_rank: give a matrix or its singular values, not both")
        values = np.asarray(singular_values, dtype=float)
        return int(np.sum(values > float(tol) * values.max())) if values.size else 0
    if matrix is None:
        raise ValueError("numerical_rank: give a matrix or its singular values")
    a = matrix if isinstance(matrix, fmpq_mat) else _exact(matrix)
    nonzero = [i for i in range(a.nrows()) if any(a[i, j] != 0 for j in range(a.ncols()))]
    if not nonzero:
        return 0
    if len(nonzero) < a.nrows():
        a = fmpq_mat(len(nonzero), a.ncols(), [a[i, j] for i in nonzero for j in range(a.ncols())])
    count = _float64_count(a, float(exact_tol), unit_rows)
    if count is None and not unit_rows and min(a.nrows(), a.ncols()) <= EXACT_UP_TO:
        count = _pivot_count(a, exact_tol)
    return _precise_count(a, exact_tol, unit_rows) if count is None else count


def to_fmpq(x: Entry) -> fmpq:
    """An int, Fraction, float or mpmath number as the exact rational it is (a float or an
    mpf is m 2^e); anything else as the rational its text spells."""
    if isinstance(x, fmpq):
        return x
    if isinstance(x, int):
        return fmpq(x)
    if isinstance(x, Fraction):
        return fmpq(x.numerator, x.denominator)
    if isinstance(x, float):
        return to_fmpq(Fraction(x))
    if not isinstance(x, mpmath.mpf):           # e.g. a numpy integer or a sympy rational: its text
        return to_fmpq(Fraction(str(x)))
    sign, man, exp, _ = x._mpf_
    if not man:
        if exp:
            raise ValueError(f"{x} is not a finite number")
        return fmpq(0)
    man = -man if sign else man
    return fmpq(man << exp) if exp >= 0 else fmpq(man, 1 << -exp)


def _fraction(x: Tolerance) -> Fraction:
    q = to_fmpq(x)
    return Fraction(int(q.p), int(q.q))


def _exact(rows: Sequence[Sequence[Entry]]) -> fmpq_mat:
    if not rows:
        return fmpq_mat(0, 0)
    return fmpq_mat(len(rows), len(rows[0]), [to_fmpq(v) for row in rows for v in row])


def _float64_count(a: fmpq_mat, tol: float, unit_rows: bool) -> int | None:
    """Step 1 of :func:`numerical_rank`, or None when an eigenvalue lies within rounding
    reach of the cut (or the cut itself does)."""
    m, n = a.nrows(), a.ncols()
    reach_factor = 64 * max(m, n) * np.finfo(float).eps
    if tol * tol <= reach_factor:           # the cut lies within rounding reach of any eigenvalue
        return None
    entries = a.entries()
    if unit_rows:                           # each row divided by its largest entry (exact): no overflow
        peaks = [max(abs(x) for x in entries[i * n:(i + 1) * n]) for i in range(m)]
        rows = np.array([[float(entries[i * n + j] / peaks[i]) for j in range(n)] for i in range(m)])
        rows /= np.linalg.norm(rows, axis=1)[:, None]
    else:
        peak = max(abs(x) for x in entries)
        rows = np.array([float(x / peak) for x in entries]).reshape(m, n)
    gram = rows @ rows.T if m <= n else rows.T @ rows
    squares = np.linalg.eigvalsh(gram)
    largest = float(squares.max())
    cut = largest * tol * tol
    reach = reach_factor * largest
    if not np.isfinite(largest) or cut <= reach or np.any(np.abs(squares - cut) <= reach):
        return None
    return int(np.sum(squares > cut))


def _pivot_count(a: fmpq_mat, tol: Fraction) -> int | None:
    """Step 2 of :func:`numerical_rank`: the count of singular values above ``tol`` s_max,
    decided in exact rational arithmetic, or None when the margin is too thin to be sure.

    G (the smaller Gram matrix), LDL^T with complete pivoting (largest remaining diagonal
    first) until a pivot d < tol^2 d_max / (100 n), d_max the largest diagonal entry
    (d_max <= s_max^2):

    - every singular value from there on is below tol s_max / 10 (the remaining Schur
      complement S has s^2 <= trace S <= n d);
    - for the r pivots kept, the principal block G_KK bounds s_r^2 >= lambda_min(G_KK)
      (interlacing) >= 1 / ||G_KK^-1||_F (exact inverse): the count is returned only if
      that is >= 100 tol^2 trace G >= 100 tol^2 s_max^2, i.e. s_r >= 10 tol s_max.
    """
    g = a * a.transpose() if a.nrows() <= a.ncols() else a.transpose() * a
    n = g.nrows()
    G = [[g[i, j] for j in range(n)] for i in range(n)]
    trace = sum((G[i][i] for i in range(n)), fmpq(0))
    dmax = max((G[i][i] for i in range(n)), default=fmpq(0))
    if dmax == 0:
        return 0
    tol2 = fmpq(tol.numerator, tol.denominator) ** 2
    low = tol2 * dmax / (100 * n)
    open_, kept = list(range(n)), []
    while open_:
        j = max(open_, key=lambda k: G[k][k])
        d = G[j][j]
        if d < low:
            break
        open_.remove(j)
        kept.append(j)
        for i in open_:
            f = G[i][j] / d
            if f:
                row_i, row_j = G[i], G[j]
                for k in open_:
                    row_i[k] -= f * row_j[k]
    if not kept:
        return 0
    try:
        inverse = fmpq_mat(len(kept), len(kept), [g[i, j] for i in kept for j in kept]).inv()
    except ZeroDivisionError:
        return None
    flat = fmpq_mat(1, len(kept) ** 2, inverse.entries())
    frobenius2 = (flat * flat.transpose())[0, 0]
    bound = 100 * tol2 * trace
    return len(kept) if bound * bound * frobenius2 <= 1 else None


def _precise_count(a: fmpq_mat, tol: Fraction, unit_rows: bool) -> int:
    """Step 3 of :func:`numerical_rank`: the Gram matrix's eigenvalues at the digits the
    tolerance needs (its own precision contexts: flint's and mpmath's, both local)."""
    digits = max(60, 2 * math.ceil(-math.log10(tol)) + 30) if 0 < tol < 1 else 60
    m, n = a.nrows(), a.ncols()
    with ctx.workdps(digits):
        values = [arb(x) for x in a.entries()]
        if unit_rows:
            for i in range(m):
                row = values[i * n:(i + 1) * n]
                norm = sum((v * v for v in row), arb(0)).sqrt()
                values[i * n:(i + 1) * n] = [v / norm for v in row]
        A = arb_mat(m, n, values)
        G = A * A.transpose() if m <= n else A.transpose() * A
    with mpmath.workdps(digits):
        size = G.nrows()
        gram = mpmath.matrix([[mpmath.mpf(G[i, j].mid().str(digits + 5, radius=False)) for j in range(size)]
                              for i in range(size)])
        squares = [abs(x) for x in mpmath.eigsy(gram, eigvals_only=True)]
        largest = max(squares)
        ratio = mpmath.mpf(tol.numerator) / tol.denominator
        return sum(1 for x in squares if x > largest * ratio * ratio)
