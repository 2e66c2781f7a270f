"""Decisions in float64 for the certified analysis of large W (issue 47): which columns are
the leftmost basis, which rows make a well-conditioned square block, and about how large
the rank is. Choices only: :func:`baseparams.numeric.certify.analyse` proves in ball
arithmetic every property it reports about them, and makes its decisions at the working
precision instead whenever a proof fails.

Why float64 is enough to *choose* for a robot's W with its columns scaled to unit norm: the
leftmost basis keeps a column when its distance to the kept columns on its left exceeds
about 1e-7.5 (the 30-digit threshold, ``10^(-D/4)``), and a float64 Gram-Schmidt computes
that distance to about 1e-15. Where W is too ill-conditioned for that (low-mobility
mechanisms, cond 1e20), the proofs fail and the working precision decides, as before.
"""

import numpy as np

from baseparams.numeric.linalg import pivoted_qr_columns


def natural_columns(a: np.ndarray, skip: set[int], threshold: float) -> tuple[list[int], np.ndarray]:
    """The leftmost columns of ``a`` (m x n, float64) whose distance to the span of the
    columns already kept exceeds ``threshold`` (Gram-Schmidt in parameter order, each
    column orthogonalised twice), the columns in ``skip`` passed over: (kept, Q), Q an
    orthonormal basis (m x len(kept)) of the kept columns."""
    m, n = a.shape
    Q = np.zeros((m, min(m, n)))
    kept: list[int] = []
    for j in range(n):
        if j in skip or len(kept) == Q.shape[1]:
            continue
        v = a[:, j].copy()
        k = len(kept)
        if k:
            basis = Q[:, :k]
            v -= basis @ (basis.T @ v)
            v -= basis @ (basis.T @ v)
        norm = float(np.linalg.norm(v))
        if norm > threshold:
            Q[:, k] = v / norm
            kept.append(j)
    return kept, Q[:, :len(kept)]


def square_rows(Q: np.ndarray) -> list[int]:
    """r rows of an orthonormal basis Q (m x r) making a well-conditioned square block:
    QR with column pivoting on Q^T (the rows of W_K's block inherit its conditioning)."""
    r = Q.shape[1]
    if not r or Q.shape[0] < r or not np.all(np.isfinite(Q)):
        return []
    return sorted(pivoted_qr_columns(Q.T, r))


def rank_estimate(W: np.ndarray, threshold: float = 1e-8) -> int:
    """About how many independent columns the float64 W has: columns scaled to unit norm
    (those below 1e-12 of the largest norm taken as zero, float rounding of an exact zero),
    then the leftmost basis at ``threshold``. An estimate for sizing W, never a result."""
    norms = np.linalg.norm(W, axis=0)
    biggest = float(norms.max()) if norms.size else 0.0
    if not biggest or not np.isfinite(biggest):
        return 0
    live = norms > 1e-12 * biggest
    scaled = np.where(live, W / np.where(live, norms, 1.0), 0.0)
    skip = set(np.flatnonzero(~live).tolist())
    return len(natural_columns(scaled, skip, threshold)[0])
