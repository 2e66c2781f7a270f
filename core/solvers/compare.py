"""Comparing base-parameter results: do two solvers describe the same base parameters?

Two results describe the same base parameters exactly when their coefficient matrices
(rank x parameters, :meth:`BaseParameterResult.coefficient_matrix`) have the same row
space; :func:`same_row_space` checks that exactly for rational coefficients and by
numerical ranks, to a tolerance, for decimals. Cross-validation of solvers builds on it.
"""

from collections.abc import Sequence
from fractions import Fraction

from flint import fmpq_mat

from baseparams.numeric.rank import Entry, Tolerance, numerical_rank, to_fmpq

Rows = Sequence[Sequence[Entry]]


def same_row_space(a: list[list[Entry]], b: list[list[Entry]], tol: Tolerance | None = None) -> bool:
    """Do the base parameter coefficient matrices ``a`` and ``b`` (lists of rows) describe
    the same base parameters: independent rows spanning the same row space?

    span(a) and span(b) both lie in span(a + b) (the rows of both), so they are equal
    exactly when the three have the same dimension. The rows of each must also be
    independent: a result whose rows are dependent (``[[1, 0, 0], [2, 0, 0]]``) lists more
    base parameters than it describes, and is not the same as one listing them once.
    Exact (rational ranks) when every entry is a Fraction and ``tol`` is None; otherwise
    numerical ranks (:func:`baseparams.numeric.rank.numerical_rank`, rows scaled to unit
    length) with the relative tolerance ``tol`` (default 1e-10).
    """
    if tol is None and all(isinstance(v, Fraction) for row in a + b for v in row):
        def dimension(rows: Rows) -> int:
            return fmpq_mat(len(rows), len(rows[0]), [to_fmpq(v) for row in rows for v in row]).rank() if rows else 0
    else:
        cut = Fraction(1, 10 ** 10) if tol is None else tol

        def dimension(rows: Rows) -> int:
            return numerical_rank(rows, cut, unit_rows=True)
    ra, rb = dimension(a), dimension(b)
    return ra == len(a) and rb == len(b) and ra == rb == dimension(a + b)
