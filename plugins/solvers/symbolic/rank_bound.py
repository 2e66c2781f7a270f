"""A cheap proof that chosen columns of an ``arb_mat`` W are independent (rank(W) >= their number).

The symbolic solver needs one fact about W: its kept columns K are independent. The
shared analysis (:func:`baseparams.numeric.certify.analyse`) proves that and much more (the
Gram matrix, pivots, beta, a tail bound), which costs O(rows n^2) Python-level ball
operations: half of a 48-body chain's symbolic run (docs/performance.md). Here the *choices* are made in float64 on a
copy of W (the same states in the Float64 backend) and only the *claim* is made in balls:

1. r = |K| rows R of W_K, by QR with column pivoting on the column-scaled W_K^T (the
   shared :func:`baseparams.numeric.linalg.pivoted_qr_columns`, numpy only: importing
   scipy.linalg would cost this one call more than its work, in the command's whole process);
2. an approximate inverse X of the r x r block M = W_RK, computed in float64 with rows and
   columns scaled by powers of two (exact), so X's entries are exact binary numbers;
3. in ball arithmetic at the caller's precision: E = I - M X, and the upper bound of
   ||E||_F^2 (one dot product in C). If ||E||_F < 1 then M X, hence M, is nonsingular for
   every matrix in W's balls, so the columns K of W are independent: rank(W) >= r.
   Should the float64 inverse be too poor (cond(M) near 1e16), python-flint's own
   preconditioned ``arb_mat.solve`` on M decides instead (it refuses a block it cannot
   prove nonsingular).

Nothing here is assumed from float64: a bad choice of rows or a poor X only makes the proof
fail (``False``), and the solver then falls back to the shared analysis.
"""

from collections.abc import Sequence

import numpy as np
from flint import arb_mat

from baseparams.numeric.linalg import pivoted_qr_columns

def _powers_of_two(norms: np.ndarray) -> np.ndarray:
    """2^-round(log2 x) per entry (1 where x is 0): exact scalings toward unit norm."""
    out = np.ones_like(norms)
    nz = norms > 0
    out[nz] = np.exp2(-np.round(np.log2(norms[nz])))
    return out


def choose_rows(wf_kept: np.ndarray) -> list[int] | None:
    """r rows of the float64 ``wf_kept`` (rows x r) whose square block is well conditioned
    (greedy: QR with column pivoting on the column-scaled transpose); None if fewer rows
    than columns, a zero column or a non-finite entry."""
    rows, r = wf_kept.shape
    if rows < r or not np.all(np.isfinite(wf_kept)):
        return None
    if r == 0:
        return []
    norms = np.linalg.norm(wf_kept, axis=0)
    if np.any(norms == 0):
        return None
    scaled = wf_kept * _powers_of_two(norms)
    return sorted(int(i) for i in pivoted_qr_columns(scaled.T, r))


def approximate_inverse(block: np.ndarray) -> np.ndarray | None:
    """X with block @ X ~ I, from the row- and column-equilibrated block (powers of two,
    so X = D inv(S block D) S is as accurate as the equilibrated inverse); None if singular
    in float64."""
    d = _powers_of_two(np.linalg.norm(block, axis=0))
    s = _powers_of_two(np.linalg.norm(block * d, axis=1))
    try:
        y = np.linalg.inv(s[:, None] * block * d)
    except np.linalg.LinAlgError:
        return None
    x = d[:, None] * y * s
    return x if np.all(np.isfinite(x)) else None


def columns_independent(blocks: Sequence[arb_mat], wf: np.ndarray, kept: list[int]) -> bool:
    """True when the columns ``kept`` of W are proven independent (for every matrix in its
    balls). W is given as ``blocks``, arb_mats with the same columns whose rows, stacked,
    are W's (no copy of W is made); ``wf`` is W's float64 counterpart (same rows and
    columns), used only to choose rows and a preconditioner. Call at the working precision
    (the backend's ``activate()``): the products are computed at the current flint
    precision."""
    r = len(kept)
    if r == 0:
        return True
    where = [(b, i) for b in blocks for i in range(b.nrows())]
    if not blocks or wf.shape != (len(where), blocks[0].ncols()):
        return False
    rows = choose_rows(wf[:, kept])
    if rows is None:
        return False
    block = arb_mat(r, r, [where[i][0][where[i][1], j] for i in rows for j in kept])
    x = approximate_inverse(wf[np.ix_(rows, kept)])
    if x is not None:
        residual = arb_mat(r, r, [1 if i == j else 0 for i in range(r) for j in range(r)]) - \
            block * arb_mat(r, r, x.ravel().tolist())
        flat = arb_mat(1, r * r, residual.entries())
        if (flat * flat.transpose())[0, 0] < 1:       # ||I - M X||_F^2 < 1, proven
            return True
    try:
        block.solve(arb_mat(r, 1, [1] * r))           # refuses (ZeroDivisionError) unless proven
    except ZeroDivisionError:
        return False
    return True
