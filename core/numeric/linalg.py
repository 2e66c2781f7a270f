"""Float64 linear-algebra helpers shared by the numeric solvers and the certified analysis:
the exact power-of-two column scaling rule, a greedy column choice, an SVD that does not
stop where LAPACK's divide and conquer fails to converge, and a tall matrix's SVD through
Cholesky QR (a rank-deficient one through Householder QR, or its Gram matrix inside
:func:`gram_route`)."""

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

import numpy as np


def power_of_two_exponents(log2_norms: Sequence[float | None] | np.ndarray) -> list[int]:
    """The column scaling rule of both dp and vp: column j is divided by 2^e_j with
    ``e_j = round(log2 ||W_j||)`` (0 for a zero column, given as -inf or None). Dividing
    by a power of two is exact in binary, so the scaling itself adds no rounding."""
    return [0 if x is None or not math.isfinite(x) else int(round(x)) for x in log2_norms]


# above this many entries LAPACK's blocked QR (scipy) is used: there its 10x speed repays
# importing scipy.linalg (paid by the whole process once: docs/performance.md); below, this loop
# takes milliseconds and a command that needs no other scipy never imports it
LAPACK_ENTRIES = 200_000


def pivoted_qr_columns(a: np.ndarray, count: int) -> list[int]:
    """Indices of ``count`` columns of ``a`` chosen by Householder QR with column pivoting
    (the same greedy choice either way: numpy's loop below, or LAPACK's for large ``a``)."""
    a = np.array(a, dtype=float, copy=True)
    m, n = a.shape
    if a.size > LAPACK_ENTRIES and np.all(np.isfinite(a)):
        import scipy.linalg
        _, _, perm = scipy.linalg.qr(a, mode="economic", pivoting=True, check_finite=False)
        return [int(i) for i in perm[:count]]
    perm = list(range(n))
    norms = np.sum(a * a, axis=0)
    for k in range(min(count, m)):
        j = k + int(np.argmax(norms[k:]))
        if j != k:
            a[:, [k, j]] = a[:, [j, k]]
            norms[[k, j]] = norms[[j, k]]
            perm[k], perm[j] = perm[j], perm[k]
        x = a[k:, k]
        alpha = -np.copysign(np.linalg.norm(x), x[0]) if x[0] != 0 else -np.linalg.norm(x)
        v = x.copy()
        v[0] -= alpha
        vn = np.linalg.norm(v)
        if vn > 0:
            v /= vn
            a[k:, k:] -= 2.0 * np.outer(v, v @ a[k:, k:])
        norms[k + 1:] = np.sum(a[k + 1:, k + 1:] ** 2, axis=0)
    return perm[:count]


def svd(a: np.ndarray, full_matrices: bool = True,
        compute_uv: bool = True) -> Any:
    """``np.linalg.svd`` (LAPACK's divide and conquer, gesdd) with the QR iteration (gesvd)
    where gesdd fails to converge: same arguments, same results, stacked matrices too.

    Why: gesdd's bidiagonal divide and conquer (dbdsdc) can fail on a finite matrix whose
    singular values reach rounding level, the case of every rank-deficient regressor
    (structural zeros, columns that are exactly zero). It happens for particular bits of
    the input, not for a family of them: the Kinova Gen3 cross-validation matrix (2541 x
    119, 7 zero columns, condition number 1e20) fails, and converges after a relative
    change of 1e-16 in its entries, so whether a run meets it depends on the last bits of
    what came before it (an unrelated SVD run first made the failure go away). gesvd is
    slower and converges on it. When gesdd converges the result is numpy's, bit for bit; a
    non-finite matrix, or one gesvd cannot factor either, raises numpy's LinAlgError."""
    try:
        if compute_uv:
            return np.linalg.svd(a, full_matrices=full_matrices)
        return np.linalg.svd(a, full_matrices=full_matrices, compute_uv=False)
    except np.linalg.LinAlgError as error:
        a = np.asarray(a, dtype=float)
        if not np.all(np.isfinite(a)):
            raise
        failure = error
    import scipy.linalg    # only here: a process that never meets the failure never imports it

    def one(m: np.ndarray) -> Any:
        return scipy.linalg.svd(m, full_matrices=full_matrices, compute_uv=compute_uv,
                                check_finite=False, lapack_driver="gesvd")

    try:
        if a.ndim == 2:
            return one(a)
        parts = [one(m) for m in a.reshape(-1, *a.shape[-2:])]
    except (np.linalg.LinAlgError, ValueError):
        raise failure from None
    if not compute_uv:
        return np.stack(parts).reshape(*a.shape[:-2], -1)
    u, s, vt = (np.stack(x) for x in zip(*parts))
    lead = a.shape[:-2]
    return u.reshape(*lead, *u.shape[1:]), s.reshape(*lead, -1), vt.reshape(*lead, *vt.shape[1:])


# thin_svd factors through Cholesky QR when the matrix's condition number (columns as given)
# is below this, and with LAPACK's SVD otherwise: Cholesky QR twice is as accurate as
# Householder QR up to a condition number near eps^-1/2 (7e7; Yamamoto, Nakatsukasa,
# Yanagisawa and Fukaya, ETNA 44, 2015), here kept well inside that bound.
CHOLESKY_QR_CONDITION = 1e5


def thin_svd(a: np.ndarray, keep: Callable[[np.ndarray], int] | None = None, zero_column: bool = False
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``svd(a, full_matrices=False)`` of a tall matrix (m >= 4 n): through Cholesky QR twice
    (Q R = a from the n x n Gram matrices) and the SVD of the small R, U = Q U_R; LAPACK's
    SVD (:func:`svd`) when a is wide, not finite, or worse conditioned than
    CHOLESKY_QR_CONDITION. Why: the diagnosis factors thousands of tall, thin matrices
    (30,000 weighted rows of a model or of a candidate's few columns) and LAPACK's SVD of
    such a matrix costs 5 to 12 times the four matrix products used here (issue 42). The
    singular values and subspaces agree with LAPACK's to rounding (relative 1e-16 times the
    condition number); singular vectors may differ in sign, and within singular values that
    are equal to rounding by any rotation, as they may between LAPACK builds.

    ``keep``: how many leading left singular vectors the caller uses, as a function of the
    singular values (a numerical rank); u then has at least those. An ill-conditioned
    matrix is then factored by :func:`_householder_svd` instead of LAPACK's SVD, 1.5 to 2.5
    times faster: rank-deficient models (exactly collinear columns) were the diagnosis'
    largest single cost (issue 42).

    ``zero_column``: the caller knows that a column of ``a`` is exactly zero. Its Gram
    matrix then has a zero pivot, Cholesky QR always fails, and the route it falls back to is
    taken at once: the same result without the Gram product (a tenth of the time on 30,000 x
    91)."""
    m, n = a.shape
    if n == 0 or m < 4 * n:
        return svd(a, full_matrices=False)

    def fallback(gram: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if keep is None or not np.all(np.isfinite(a)):
            return svd(a, full_matrices=False)
        found = _gram_svd(a, keep, gram) if _GRAM_ROUTE.get() else None
        return found if found is not None else _householder_svd(a, keep)

    if zero_column:
        return fallback()

    gram = a.T @ a
    try:
        first = np.linalg.cholesky(gram).T                          # a = Q1 first, Q1 = a first^-1
    except np.linalg.LinAlgError:
        return fallback(gram)
    if not np.all(np.isfinite(first)):
        return fallback()
    singular = np.linalg.svd(first, compute_uv=False)
    if not singular[-1] > singular[0] / CHOLESKY_QR_CONDITION:
        return fallback(gram)
    q1 = a @ np.linalg.inv(first)
    try:
        second = np.linalg.cholesky(q1.T @ q1).T                    # Q1 = Q second: orthogonal to rounding
    except np.linalg.LinAlgError:
        return fallback()
    u_r, s, vt = np.linalg.svd(second @ first)
    return q1 @ (np.linalg.inv(second) @ u_r), s, vt


# _gram_svd keeps the Gram matrix's eigen-directions whose eigenvalue exceeds GRAM_KEPT times the
# largest (singular values above 1e-5 of the largest: their basis then loses at most 1e-6 of its
# orthogonality, which one Cholesky QR restores), and takes that route only when the directions
# it drops leave at most GRAM_DROPPED times the largest singular value (||a v||, measured): the
# exactly collinear columns of the diagnosis' models leave 1e-15 to 1e-12 there.
GRAM_KEPT = 1e-10
GRAM_DROPPED = 1e-10


_GRAM_ROUTE: ContextVar[bool] = ContextVar("thin_svd_gram_route", default=False)


@contextmanager
def gram_route() -> Iterator[None]:
    """Within it, :func:`thin_svd` (given ``keep``) factors a rank-deficient tall matrix through
    its Gram matrix (:func:`_gram_svd`) where its singular values allow, Householder QR
    otherwise. Why a context, not the default: the two agree to rounding (singular values to
    5e-15 of the largest, projections to 4e-14 on a UR5's held diagnosis), but a held
    diagnosis (``diagnose --params``) turns on rounding there: the original code named
    ``body`` instead of ``payload`` on wrist_3_link in 2 of 5 runs whose torques moved by
    1e-15 (tests/test_diagnose_payload_kind.py's seed 3). ``diagnose --baseline`` takes it
    (change.diagnose_change), its decisions checked at scale (docs/diagnosis.md)."""
    token = _GRAM_ROUTE.set(True)
    try:
        yield
    finally:
        _GRAM_ROUTE.reset(token)


def _gram_svd(a: np.ndarray, keep: Callable[[np.ndarray], int], gram: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`_householder_svd`'s result for a tall, finite ``a`` (m, n) whose singular values
    fall into a kept group (above 1e-5 of the largest) and a dropped one (at most 1e-10 of it),
    without a QR of its m rows; None when they do not, or ``keep`` counts other than the kept
    group. The Gram matrix ``gram`` (a^T a, made if not given) has eigenvectors [V_k V_d]; a V_d
    is measured and at most GRAM_DROPPED s_1, so a's range is that of a V_k to it; Q T = a V_k
    D^-1 by Cholesky QR (D^2 the kept eigenvalues: a V_k D^-1 is orthonormal to 1e-6 before,
    Q to rounding after), and the SVD of the small Q^T a (k, n) = U_B S W^T gives the kept
    singular values and right vectors as Householder's R does, u = Q U_B, the dropped
    directions W's others, their singular values ||a w|| (rounding). Why: the rank-deficient
    models of the diagnosis between recordings (30,000 x 84, 23 exactly collinear columns) were
    a sixth of its time in Householder QR; here 0.06 CPU s against 0.09 for 30,000 x 91."""
    g = a.T @ a if gram is None else gram
    values, vectors = np.linalg.eigh(g)
    values, vectors = values[::-1], vectors[:, ::-1]                 # largest first
    if not (np.all(np.isfinite(values)) and values[0] > 0):
        return None
    k = int(np.sum(values > GRAM_KEPT * values[0]))
    d = np.sqrt(values[:k])
    rest = a @ np.ascontiguousarray(vectors[:, k:])                   # a V_d
    if rest.shape[1] and not np.max(column_norms(rest)) <= GRAM_DROPPED * d[0]:
        return None
    q1 = a @ np.ascontiguousarray(vectors[:, :k] / d)
    gram_q1 = q1.T @ q1
    try:
        t = np.linalg.cholesky(gram_q1).T                             # q1 = Q t
    except np.linalg.LinAlgError:
        return None
    inverse = np.linalg.inv(t)
    # Q^T a = t^-T q1^T (a V) V^T, a V = [q1 D, a V_d]: no product of a's m rows again
    cross = q1.T @ rest
    moved = np.concatenate([gram_q1 * d[None, :], cross], axis=1) @ vectors.T
    u_b, s, wt = np.linalg.svd(inverse.T @ moved)                    # Q^T a = U_B S W^T, W (n, n)
    # ||a w|| per dropped direction from (a V)^T (a V), whose blocks are made: y = V^T w, and every
    # term of y^T (a V)^T (a V) y is of the size of the sum (y's kept part is the tiny angle)
    block = np.block([[d[:, None] * gram_q1 * d[None, :], d[:, None] * cross], [cross.T * d[None, :], rest.T @ rest]])
    y = vectors.T @ wt[k:].T
    left = np.sqrt(np.maximum(np.einsum("ij,ij->j", y, block @ y), 0.0))
    order = np.argsort(-left, kind="stable")
    s = np.concatenate([s[:k], left[order]])
    if int(keep(s)) != k:
        return None
    return q1 @ (inverse @ u_b), s, np.concatenate([wt[:k], wt[k:][order]])


def column_norms(matrix: np.ndarray) -> np.ndarray:
    """The Euclidean norm of each column of ``matrix`` (rows, k). Why not ``np.linalg.norm(...,
    axis=0)``: on the diagnosis' tall matrices (30,000 rows, a few columns) numpy's strided
    reduction cost as much as the SVD after it."""
    return np.sqrt(np.einsum("ij,ij->j", matrix, matrix))


def _householder_svd(a: np.ndarray, keep: Callable[[np.ndarray], int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The thin SVD of a tall, finite, ill-conditioned ``a`` (m, n) with only the ``keep(s)``
    leading left singular vectors: R from Householder QR (LAPACK's geqrf, backward stable
    whatever the conditioning), R = U_R S V^T, and U_k = a V_k S_k^-1 orthonormalised once
    more by Cholesky QR (its columns are orthonormal to about 1e-16 times s_1 / s_k before).
    Singular values and right vectors are R's, as accurate as LAPACK's; u spans the same
    k directions to rounding relative to s_k. Why not LAPACK's SVD: it also forms the
    m x n orthogonal factor and multiplies it out, 2 to 3 times the work of this."""
    import scipy.linalg    # only here: a process that never meets an ill-conditioned matrix never imports it
    m, n = a.shape
    # mode 'raw': the same geqrf, but R taken from its first n rows (mode 'r' copies out the whole
    # m x n upper triangle, mostly zeros, first)
    r = scipy.linalg.qr(a, mode="raw", check_finite=False)[1]
    _, s, vt = svd(np.triu(r))
    k = min(int(keep(s)), n)
    if k == 0:
        return np.zeros((m, 0)), s, vt
    u = a @ (vt[:k].T / s[:k])
    try:
        t = np.linalg.cholesky(u.T @ u).T
    except np.linalg.LinAlgError:
        return svd(a, full_matrices=False)
    return u @ np.linalg.inv(t), s, vt


def triangular_factor(blocks: Iterable[np.ndarray], columns: int) -> tuple[np.ndarray, int]:
    """(R, rows): the triangular factor of the matrix the row ``blocks`` stack into, and its
    row count, without ever holding that matrix: each block is stacked under the R so far
    and factored again (Householder QR, backward stable column by column). ``R^T R = W^T W``
    and ``R = Q^T W``: R has W's singular values and right singular vectors, its column
    norms are W's, so Gautier's method on R is Gautier's method on W in
    ``(columns + block rows) x columns`` memory instead of ``rows x columns``.
    R is ``min(rows, columns) x columns``."""
    R: np.ndarray = np.zeros((0, columns))
    rows = 0
    for block in blocks:
        block = np.asarray(block, dtype=float)
        rows += block.shape[0]
        R = np.asarray(np.linalg.qr(np.vstack([R, block]), mode="r"))
    return R, rows
