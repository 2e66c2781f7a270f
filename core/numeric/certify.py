"""Gautier's method in ball arithmetic (python-flint ``arb``): a rank that is proven.

python-flint has no SVD. The work is split into *decisions*, made on midpoints, and
*claims*, each verified in ball arithmetic on the column-scaled observation matrix Ws
(every column divided by an exact power of two near its norm, so scaling adds no
rounding and ``beta = D_K^-1 beta_s D_E`` is exact):

1. Decisions. On the midpoints of the Gram matrix ``G = Ws^T Ws`` (70 x 70 for the
   SLA whatever the number of samples; one ``arb_mat`` product, in C), Cholesky with
   diagonal (complete) pivoting gives the rank r: the pivots above the noise threshold
   ``1e3 * n * 10^-D * max G_jj``. The kept columns K are then, by default, the
   leftmost basis (each pivot above ``10^(-D/2) max G_jj``, since rounding noise in this possibly
   ill-conditioned basis is amplified; parameter order: what an exact ``rref`` picks, so ``vp`` and
   ``exact`` results compare entry by entry), else the complete-pivoting columns. Then r rows R of
   Ws_K making a well-conditioned square block (QR with column pivoting on Ws_K^T, in float64).
2. Claims, each rigorous for every W inside the computed W ball:
   - ``rank(W) >= r``: ``arb_mat.solve`` proves the r x r block ``Ws_RK`` nonsingular
     (it refuses otherwise);
   - ``beta_s``: the enclosure of the solution of ``Ws_RK beta_s = Ws_RE``. For a W of
     rank exactly r, ``Ws_E = Ws_K beta_s`` holds on every row, so these r rows give
     its beta; solving a square block costs ``log10 cond`` digits, where the normal
     equations would cost twice that;
   - ``s_{r+1}(Ws) <= tail_bound = ||Ws_E - Ws_K B||_F`` for an exact matrix B (the
     midpoint of beta_s, refined once by least squares), by Weyl's inequality, since
     ``[Ws_K, Ws_K B]`` has rank r: every singular value after the ridge lies in a ball
     around zero, and that ball shrinks as D grows;
   - ``s_r(Ws) >= sigma_r_lower = ||Ws_RK^-1||_F^-1`` (dropping columns or rows never
     raises the smallest singular value). ``sigma_r_lower / tail_bound`` is the proven
     height of the ridge.

Why not eliminate in ball arithmetic directly: naive interval elimination widens the
balls at every step (on the SLA at 30 digits it proved only 39 of 41 pivots), while a
verified solve (python-flint's preconditioned one) and a residual bound stay tight.
Eigenvalues of G (``acb_mat.eig``) are rigorous only when isolated and fail on the
cluster of zero eigenvalues; they serve only for the approximate singular values that
are plotted.

Speed (docs/performance.md). python-flint reads or writes one entry in about half a
microsecond but multiplies matrices in C, so W's entries are read once and every
elimination, norm and solve is a matrix operation: the eliminations are blocked
(PANEL pivots, then one product updates the Schur complement of the still-open columns),
the Frobenius bounds are one dot product, ``beta_s`` and ``Ws_RK^-1`` come from one
solve. Beyond FAST_DECISIONS_ABOVE parameters (no built-in mechanism: theirs are
decided exactly as before, to the last digit) some *decisions* are made more cheaply:
G from W rounded 32 bits beyond the working precision, the rows R chosen in float64
when the Cholesky factor of G_KK is well conditioned (else as above), the rows of an
earlier precision tried first, and the least-squares refinement of B skipped when the
residual is dominated by the balls' radii (and kept only when it lowers the bound). No
claim changes: each is still verified in ball arithmetic as in 2.

Beyond FAST_DECISIONS_ABOVE parameters with natural pivoting (issue 47) the leftmost basis
K and the rows R are first chosen in float64 (:mod:`baseparams.numeric.decide`, no G at
all), and the next precision reuses that choice. Besides the claims of 2, the analysis then
proves that the decisions at D digits would have been the same, with 3 decades to spare
(:func:`_analyse_float`): every kept column's pivot >= sigma_r_lower^2, every eliminated
column within a proven distance of the kept columns on its left, and s_{r+1} <= tail_bound
below the noise threshold. When any of these fails, the decisions are made at D digits as
above (Talos: 4.0 -> 1.2 s at 30 digits, 6.2 -> 2.3 s at 60, the same rank, K and beta).
"""

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from flint import acb_mat, arb, arb_mat, arf, ctx

from baseparams.numeric import backends, decide
from baseparams.numeric.linalg import pivoted_qr_columns, power_of_two_exponents
from baseparams.numeric.ballgrid import GRID_EXTRA_BITS, centred, frobenius_upper  # noqa: F401 (re-exported)
from baseparams.numeric.ballgrid import frobenius_pair as _frobenius_pair, on_grid as _on_grid

NOISE_FACTOR = 1000       # pivots below NOISE_FACTOR * n * 10^-D * max G_jj are noise
SPECTRUM_IN_ARB_UP_TO = 80  # parameters: approximate spectra by an eig at D digits up to here
FAST_DECISIONS_ABOVE = 80  # parameters: beyond, the cheaper decisions (module docstring)
FLOAT_BITS = 53           # precision of the helpers whose result is a float or an integer
FLOAT_BASIS_RELATIVE = 10 ** -7.5  # float64 leftmost basis: a column's distance over sqrt(max G_jj) (30 digits' 10^(-D/4))
MARGIN_DECADES = 3        # float64 decisions: proven to agree with the working precision's by this much
REFINE_PASSES = 4         # the next precision's beta_s from the previous one's: passes allowed (one suffices 30 -> 60)
REFINE_CONTRACTION_BITS = 20  # ... only while ||I - Y Ws_RK||_F < 2^-20 (Y the previous precision's inverse)
REFINE_SLACK_BITS = 32    # ... done when the enclosure's width is within 2^32 (9.6 digits) of the working precision's
LOG10_2 = math.log10(2)


@dataclass
class BallAnalysis:
    digits: int
    rank: int
    kept: list[int]
    eliminated: list[int]
    pivoting: str                 # "natural", "complete" or "imposed"
    pivots: list[arb]             # complete-pivoting pivots of the scaled G (midpoints), in order
    pivot_order: list[int]        # their columns
    beta_s: arb_mat               # r x (n - r), scaled
    beta: arb_mat                 # r x (n - r), unscaled: phi_b = phi_1 + beta phi_2
    exponents: list[int]          # column j scaled by 2^-exponents[j]
    zero_columns: list[int]       # columns no entry of which is proven nonzero
    tail_bound: arb               # rigorous upper bound of s_{r+1}(Ws) (0 if r = n)
    sigma_r_lower: arb            # rigorous lower bound of s_r(Ws)
    singular_values: list[str]    # approximate singular values of Ws, largest first
    refined: arb_mat | None = None  # exact (midpoint) B used for tail_bound
    notes: list[str] = field(default_factory=list)
    decided: str = "ball"         # "float64": K and R chosen by numeric.decide, proven below
    rows: list[int] = field(default_factory=list)  # the rows R of the square block Ws_RK
    _residual: tuple[Any, arb_mat] | None = field(default=None, repr=False, compare=False)  # (W, mid(Ws_E - Ws_K B))
    block_inverse: arb_mat | None = field(default=None, repr=False, compare=False)  # exact, ~ Ws_RK^-1 (float64 decisions)

    @property
    def ridge_log10(self) -> float:
        """log10(sigma_r_lower / tail_bound): the proven height of the ridge, in decades."""
        if self.rank == 0 or not self.sigma_r_lower > 0:
            return -math.inf
        if self.tail_bound == 0:
            return math.inf
        return log10(self.sigma_r_lower) - log10(self.tail_bound)


def log10(x: arb | arf) -> float:
    """log10 |midpoint| as a float (-inf for zero); fine for 10^-100000. From the
    midpoint's exact mantissa and binary exponent (no precision involved: called tens of
    thousands of times per analysis); a non-finite midpoint at FLOAT_BITS."""
    m = arb(x).mid()
    if m.is_finite():
        man, exp = m.man_exp()
        mantissa = int(man)
        return math.log10(abs(mantissa)) + int(exp) * LOG10_2 if mantissa else -math.inf
    with ctx.workprec(FLOAT_BITS):
        x = abs(arb(x).mid())
        if x == 0:
            return -math.inf
        return float(x.log() / arb(10).log())


# ----- reading W ----------------------------------------------------------------
# python-flint reads or writes a matrix entry in about half a microsecond and multiplies
# matrices in C: W's entries are read once (``entries()``), every submatrix is built from
# that list, and every loop over entries that can be a matrix product is one.

def _float_mids(entries: Sequence[arb], rows: int, cols: int) -> np.ndarray:
    """The midpoints as a float64 array (rows x cols): 0 or inf where out of float range."""
    return np.fromiter(map(float, entries), dtype=float, count=len(entries)).reshape(rows, cols)


def _column_exponents(W: backends.BallMatrix, entries: list[arb] | None = None,
                      mids: np.ndarray | None = None) -> tuple[list[int], list[int]]:
    """Per column: round(log2(norm)) from the midpoints, and the zero columns.

    A column is zero when every entry's ball contains 0: nothing proves it nonzero, and
    scaling its rounding noise up to norm 1 would invent a rank (the PUMA 560's ``mz2``
    is such a column: exactly zero, but its balls have midpoints ~1e-31 at 30 digits).
    Zero columns are eliminated with zero coefficients; if one is in fact tiny and
    nonzero, a higher precision shows it (and the ``vp`` solver's ranks then differ).

    Fast path, same result: the midpoints as floats give each column's largest entry,
    whose ball excluding 0 proves the column nonzero, and the norm, whose rounded log2
    is the exponent unless the floats under- or overflow or log2 lies within 1e-6 of a
    half-integer; those columns (and every column whose largest entry contains 0) are
    decided entry by entry in arb, as they always were.
    """
    rows, cols = W.nrows(), W.ncols()
    if entries is None:
        entries = W.entries()
    if not rows:
        return power_of_two_exponents([None] * cols), list(range(cols))
    if mids is None:
        mids = _float_mids(entries, rows, cols)
    with np.errstate(all="ignore"):
        largest = np.abs(mids).max(axis=0)
        where = np.abs(mids).argmax(axis=0)
        safe = np.isfinite(largest) & (largest > 1e-290) & (largest < 1e290)
        norms = largest * np.sqrt(np.sum((mids / np.where(safe, largest, 1.0)) ** 2, axis=0))
        logs = np.log2(np.where(safe, norms, 1.0))
    log2_norms: list[float | None] = []
    zero: list[int] = []
    for j in range(cols):
        if safe[j] and not entries[int(where[j]) * cols + j].contains(0):
            log2 = float(logs[j])
            if abs(log2 - math.floor(log2) - 0.5) > 1e-6:
                log2_norms.append(log2)
                continue
        column = entries[j::cols]
        if all(x.contains(0) for x in column):
            zero.append(j)
            log2_norms.append(None)
            continue
        total: Any = arb(0)
        for x in column:
            m = x.mid()
            total += m * m
        log2_norms.append(log10(total) / 2 / math.log10(2))
    return power_of_two_exponents(log2_norms), zero


def scaled_entries(entries: Sequence[arb], cols: int, exponents: Sequence[int]) -> list[arb]:
    """W's entries (row-major) with column j divided by 2^exponents[j]: exact."""
    two = arb(2)
    powers = [two ** (-e) for e in exponents]
    if not cols:
        return []
    repeated = powers * (len(entries) // cols)
    return list(map(arb.__mul__, entries, repeated))          # x * p, iterated in C


def block(entries: Sequence[arb], cols: int, rows: Sequence[int], picked: Sequence[int]) -> arb_mat:
    """The submatrix (``rows`` x ``picked`` columns) of the row-major ``entries`` of a
    matrix with ``cols`` columns, as an arb_mat (copied, not rounded)."""
    if not rows or not picked:
        return arb_mat(len(rows), len(picked))
    return arb_mat(len(rows), len(picked), [entries[i * cols + j] for i in rows for j in picked])


def _gram(Ws: arb_mat) -> arb_mat:
    """Midpoints of ``Ws^T Ws`` (decisions only): one product, in C. Beyond
    FAST_DECISIONS_ABOVE columns from Ws on a grid (:func:`_on_grid`: 1.5-2x faster);
    up to there (every built-in mechanism) from Ws itself, so that the approximate
    spectrum, which is read from G, stays what it was to the last printed digit."""
    Y = _on_grid(Ws).mid() if Ws.ncols() > FAST_DECISIONS_ABOVE else Ws
    return (Y.transpose() * Y).mid()


# ----- decisions (midpoints) ---------------------------------------------------
PANEL = 64                 # pivots per block update of the Schur complement


def _eliminations(G: arb_mat, threshold: arb, complete: bool = True, skip: Iterable[int] = (),
                  target: int | None = None) -> Iterator[tuple[int, Any, list[Any]]]:
    """Symmetric Gaussian elimination (Cholesky, ``G = L^T L``) on the midpoints of G, one
    pivot at a time: yields (column, pivot, row of L) for each pivot above ``threshold``;
    the row of L is the pivot's Schur column divided by the square root of the pivot.

    ``complete``: the largest remaining diagonal next (complete pivoting), until none
    exceeds the threshold; else the columns in order, those at or below the threshold
    skipped (the leftmost basis), until ``target`` pivots. Blocked, with the arithmetic in
    C: a pivot's column is its column of the panel-start matrix minus one vector-matrix
    product with the panel's earlier rows of L, and the matrix is updated once per PANEL
    pivots by one matrix product; Python touches O(n) numbers per pivot (the column, and
    the diagonal that complete pivoting chooses from). The rows of L are bounded by
    sqrt(max G_jj) (G is positive semidefinite) and put on a grid 32 bits finer than the
    working precision (:func:`_on_grid`), so the products run on one exponent range.
    Every result is rounded to its midpoint (decisions only).
    """
    n = G.nrows()
    skipped = set(skip)
    open_ = [j for j in range(n) if j not in skipped]
    A = _submatrix(G.mid(), open_) if skipped else G.mid()
    cols = list(open_)              # the columns A holds (the open ones at the panel's start)
    place = {j: i for i, j in enumerate(cols)}
    diag: list[Any] = [A[i, i] for i in range(len(cols))] if complete else []
    cap = len(open_) if target is None else min(len(open_), target)
    L = arb_mat(PANEL, len(cols))   # the panel's rows of L, over ``cols``
    rows: list[list[Any]] = []      # the same, as lists
    zeros = [0] * PANEL
    four = arb_mat(1, len(cols), [4] * len(cols)) if cols else None
    count = 0
    while open_ and count < cap:
        if complete:
            j = max(open_, key=lambda k: (diag[place[k]], -k))
        else:
            j = open_[0]
        open_.remove(j)
        a = place[j]
        p: Any = diag[a] if complete else None
        if complete and not p > threshold:
            return
        width = len(cols)
        row = arb_mat(1, width, [A[a, k] for k in range(width)])
        if rows:
            row = row - arb_mat(1, PANEL, [r[a] for r in rows] + zeros[len(rows):]) * L
        row = row.mid()
        if not complete:
            p = row[0, a]
            if not p > threshold:
                continue
        ell = _on_grid((row * (1 / p.sqrt())).mid(), four=four).mid().entries()
        if complete:
            for k in open_:
                b = place[k]
                diag[b] = (diag[b] - ell[b] * ell[b]).mid()
        c = len(rows)
        for k in range(width):
            L[c, k] = ell[k]
        rows.append(ell)
        count += 1
        full: list[Any] = [0] * n
        for k, x in zip(cols, ell):
            full[k] = x
        yield j, p, full
        if len(rows) == PANEL and open_ and count < cap:
            # the Schur complement on the columns still open only
            keep = [place[k] for k in sorted(open_)]
            Lk = arb_mat(PANEL, len(keep), [r[b] for r in rows for b in keep])
            A = (_submatrix(A, keep) - Lk.transpose() * Lk).mid()
            if complete:
                diag = [diag[b] for b in keep]
            cols = sorted(open_)
            place = {k: i for i, k in enumerate(cols)}
            L = arb_mat(PANEL, len(cols))
            four = arb_mat(1, len(cols), [4] * len(cols))
            rows = []


def _submatrix(A: arb_mat, index: Sequence[int]) -> arb_mat:
    """The symmetric submatrix A[index, index] (copied, not rounded)."""
    n = A.ncols()
    e = A.entries()
    return arb_mat(len(index), len(index), [e[i * n + j] for i in index for j in index])


def _approximate_pivots(G: arb_mat, threshold: arb, skip: Iterable[int] = ()) -> tuple[list[int], list[arb]]:
    """Cholesky (LDL^T) with diagonal pivoting on midpoints while the pivot exceeds ``threshold``.

    Returns (order, pivots): the columns in pivot order and their pivots (midpoints).
    """
    order, pivots = [], []
    for j, p, _ in _eliminations(G, threshold, complete=True, skip=skip):
        order.append(j)
        pivots.append(p)
    return order, pivots


def _natural_basis(G: arb_mat, threshold: arb, target: int,
                   skip: Iterable[int] = ()) -> tuple[list[int], arb_mat]:
    """Leftmost columns (parameter order) whose midpoint Schur pivot exceeds ``threshold``,
    and the Cholesky factor of G restricted to them, from the same elimination (the
    columns passed over take no part in it): (columns, R)."""
    found = list(_eliminations(G, threshold, complete=False, skip=skip, target=target))
    return [j for j, _, _ in found], _factor(found)


def _cholesky_mid(G: arb_mat, kept: Sequence[int]) -> arb_mat | None:
    """Upper-triangular R with R^T R = G_KK (midpoints), or None if a pivot is not positive."""
    others = set(range(G.nrows())) - set(kept)
    found = list(_eliminations(G, arb(0), complete=False, skip=others))
    if [j for j, _, _ in found] != sorted(kept):
        return None
    return _factor(found)


def _factor(found: Sequence[tuple[int, Any, list[Any]]]) -> arb_mat:
    """R (upper triangular, R^T R = G_KK) from the elimination's (column, pivot, row of L)
    of the kept columns K, in order."""
    kept = [j for j, _, _ in found]
    r = len(kept)
    values = []
    for i, (_, _, ell) in enumerate(found):
        values += [0] * i + [ell[j] for j in kept[i:]]
    return arb_mat(r, r, values) if r else arb_mat(0, 0)


def _select_rows_float64(Wk: arb_mat, R: arb_mat | None, W64: np.ndarray | None = None) -> list[int] | None:
    """The rows of :func:`_select_rows` chosen in float64 when R is well conditioned
    (cond(R) <= 1e8, so ``Q = W_K R^-1`` has float accuracy to 1e-8), by LAPACK's QR with
    column pivoting; None when it is not. A choice only, as the other's."""
    r = Wk.ncols()
    if R is None or not r or Wk.nrows() < r:
        return None
    R64 = np.array([float(x) for x in R.entries()]).reshape(r, r)
    if not np.all(np.isfinite(R64)) or np.linalg.cond(R64) > 1e8:
        return None
    if W64 is None:
        W64 = _float_mids(Wk.entries(), Wk.nrows(), r)
    import scipy.linalg      # here, not at the top: a large part of every command's start, for one call
    Qt = scipy.linalg.solve_triangular(R64, W64.T, trans="T")
    _, perm = scipy.linalg.qr(Qt, mode="r", pivoting=True)
    return sorted(int(i) for i in perm[:r])


def _select_rows(Wk: arb_mat, R: arb_mat | None) -> list[int]:
    """r rows of W_K making a well-conditioned square block (a choice only: what is claimed
    is verified in arb).

    W_K itself may be far too ill-conditioned for float64 (cond 1e20 when the kept
    columns are the parameter-order basis of a low-mobility mechanism), so it is first
    orthonormalised at the working precision, ``Q = W_K R^-1`` with ``R^T R = G_KK``
    (Cholesky on midpoints); QR with column pivoting on ``Q^T`` in float64 then picks
    rows whose block of Q, hence of W_K, is as well conditioned as a greedy choice can.
    """
    r = Wk.ncols()
    Q = Wk
    if R is not None:
        try:
            Q = Wk.mid() * R.inv().mid()
        except ZeroDivisionError:
            Q = Wk
    a = np.array([float(x) for x in Q.entries()]).reshape(Q.nrows(), r).T
    return sorted(pivoted_qr_columns(a, r))


def _verify(scaled: Sequence[arb], shape: tuple[int, int], G: arb_mat, kept: Sequence[int],
            R: arb_mat | None = None, hint: tuple[list[int], list[int]] | None = None,
            scaled64: np.ndarray | None = None) -> tuple[list[int], arb_mat, arb_mat, arb_mat] | None:
    """(rows, beta_s, Ws_K, Ws_RK^-1) with Ws_RK beta_s = Ws_RE and the inverse solved in
    ball arithmetic (one solve, right-hand side [Ws_RE, I]), or None when Ws_RK is not
    proven nonsingular. ``scaled``: the row-major entries of the column-scaled W of
    ``shape``; ``R``: the Cholesky factor of G_KK if known; ``hint``: (kept, rows) of an
    earlier analysis, whose rows are tried first if it kept these columns.

    The rows are a choice: beyond FAST_DECISIONS_ABOVE columns the hint, then rows chosen
    in float64 (:func:`_select_rows_float64`) are tried first; whichever block fails to
    be proven nonsingular, the working-precision choice is made and tried as always."""
    m, n = shape
    eliminated = [j for j in range(n) if j not in set(kept)]
    if not kept:
        return [], arb_mat(0, len(eliminated)), arb_mat(m, 0), arb_mat(0, 0)
    Wk = block(scaled, n, range(m), kept)
    fast = n > FAST_DECISIONS_ABOVE
    tried = []
    if fast and hint is not None and hint[0] == list(kept) and all(0 <= i < m for i in hint[1]):
        tried.append(list(hint[1]))
        found = solve_block(scaled, n, tried[-1], kept, eliminated)
        if found is not None:
            return (tried[-1], found[0], Wk, found[1])
    if R is None:
        R = _cholesky_mid(G, kept)
    if fast:
        rows = _select_rows_float64(Wk, R, None if scaled64 is None else scaled64[:, kept])
        if rows is not None and rows not in tried:
            tried.append(rows)
            found = solve_block(scaled, n, rows, kept, eliminated)
            if found is not None:
                return (rows, found[0], Wk, found[1])
    rows = _select_rows(Wk, R)
    if len(rows) < len(kept) or rows in tried:
        return None
    found = solve_block(scaled, n, rows, kept, eliminated)
    return None if found is None else (rows, found[0], Wk, found[1])


def solve_block(scaled: Sequence[arb], n: int, rows: Sequence[int], kept: Sequence[int],
                eliminated: Sequence[int], inverse: bool = True) -> tuple[arb_mat, arb_mat] | None:
    """(beta_s, Ws_RK^-1) by one verified solve, or None when Ws_RK is not proven nonsingular.
    ``inverse=False``: beta_s alone (the inverse returned empty), a smaller right-hand side."""
    r, e = len(kept), len(eliminated)
    inverse = inverse or not e          # nothing else to solve for: the inverse proves Ws_RK nonsingular
    Wrk = block(scaled, n, rows, kept)
    extra = r if inverse else 0
    identity = [0] * extra
    right: list[Any] = []
    for a, i in enumerate(rows):
        right += [scaled[i * n + j] for j in eliminated]
        if inverse:
            identity[a] = 1
            right += identity
            identity[a] = 0
    try:
        X = Wrk.solve(arb_mat(r, e + extra, right))
    except ZeroDivisionError:
        return None
    x = X.entries()
    width = e + extra
    beta_s = arb_mat(r, e, [x[a * width + b] for a in range(r) for b in range(e)]) if e else arb_mat(r, 0)
    inv = (arb_mat(r, r, [x[a * width + e + b] for a in range(r) for b in range(r)]) if inverse
           else arb_mat(0, 0))
    return beta_s, inv


# ----- the analysis --------------------------------------------------------------
def analyse(W: backends.BallMatrix, digits: int, kept: Sequence[int] | None = None, pivoting: str = "natural",
            approximate_spectrum: bool = True, earlier: BallAnalysis | None = None) -> BallAnalysis:
    """Rank, permutation and beta of an ``arb_mat`` W, computed at ``digits`` (whatever
    precision the caller has set; it is restored on return).

    ``kept``: impose the kept columns (to compare two precisions, or another solver's
    permutation); ValueError if they are not proven independent. ``earlier``: an
    analysis of W at the same states (another precision): when it kept the same columns,
    its rows are tried first for the square block (a choice only; beyond
    FAST_DECISIONS_ABOVE columns).
    """
    hint = None if earlier is None else (list(earlier.kept), list(earlier.rows))
    reuse = hint if earlier is not None and earlier.decided == "float64" else None
    with ctx.workdps(digits):
        return _analyse(W, digits, kept, pivoting, approximate_spectrum, hint, reuse,
                        earlier if reuse is not None else None)


def _analyse(W: backends.BallMatrix, digits: int, kept: Sequence[int] | None, pivoting: str, approximate_spectrum: bool,
             hint: tuple[list[int], list[int]] | None = None,
             reuse: tuple[list[int], list[int]] | None = None, start: BallAnalysis | None = None) -> BallAnalysis:
    m, n = W.nrows(), W.ncols()
    entries = W.entries()
    mids = _float_mids(entries, m, n) if m else None
    exponents, zero = _column_exponents(W, entries, mids)
    scaled = scaled_entries(entries, n, exponents)
    # the scaled midpoints in float64 (for choices and the approximate spectrum only)
    scaled64 = np.ldexp(mids, -np.array(exponents, dtype=int)) if mids is not None else np.zeros((0, n))
    del entries, mids
    if kept is None and pivoting == "natural" and n > FAST_DECISIONS_ABOVE and m:
        fast = _analyse_float(W, digits, scaled, scaled64, exponents, zero, reuse, approximate_spectrum, start)
        if fast is not None:
            return fast
    everything = arb_mat(m, n, scaled) if m and n else arb_mat(m, n)
    G = _gram(everything)
    del everything
    gm = G.entries()
    gmax = max((float(abs(gm[i * n + i])) for i in range(n)), default=0.0)
    threshold = arb(NOISE_FACTOR * n * max(gmax, 1e-300)) * arb(10) ** (-digits)
    order, pivots = _approximate_pivots(G, threshold, skip=zero)
    notes: list[str] = []
    candidates: list[tuple[list[int], str, arb_mat | None]] = []
    if kept is not None:
        candidates.append((sorted(kept), "imposed", None))
    else:
        if pivoting == "natural":
            # a dependent column's pivot is noise amplified by cond(W_K), which can be huge
            # for this basis: demand 10^(-D/2), which noise cannot reach while cond < 10^(D/2)
            strict = max(threshold, arb(max(gmax, 1e-300)) * arb(10) ** (-(digits // 2)))
            natural, R = _natural_basis(G, strict, len(order), skip=zero)
            if len(natural) == len(order):
                candidates.append((natural, "natural", R))
            else:
                notes.append(f"the parameter-order basis found {len(natural)} of {len(order)} columns "
                             f"at {digits} digits; the complete-pivoting columns are kept instead")
        candidates.append((sorted(order), "complete", None))
    verified = None
    while verified is None:
        for cand, how, factor in candidates:
            verified = _verify(scaled, (m, n), G, cand, factor, hint, scaled64)
            if verified is not None:
                kept, used = cand, how
                break
            if how == "imposed":
                raise ValueError("the imposed kept columns are not proven independent at this precision")
            notes.append(f"the {how} choice of {len(cand)} columns is not proven independent "
                         f"at {digits} digits")
        if verified is None:            # a smaller rank that can be proven
            order, pivots = order[:-1], pivots[:-1]
            candidates = [(sorted(order), "complete", None)]
            notes.append(f"rank lowered to {len(order)}: the last pivot is not provable at {digits} digits")
    rows, beta_s, Wk, inverse = verified
    assert kept is not None             # the verified candidate's columns
    eliminated = [j for j in range(n) if j not in set(kept)]

    # s_{r+1} <= ||Ws_E - Ws_K B||_F for any exact B (Weyl: [Ws_K, Ws_K B] has rank r)
    residual = None
    if eliminated and kept and n > FAST_DECISIONS_ABOVE:
        B, residual, tail = _refined_fast(scaled, (m, n), scaled64, kept, eliminated, Wk, beta_s)
    elif eliminated and kept:
        We = block(scaled, n, range(m), eliminated)
        B = beta_s.mid()
        try:                            # one least-squares refinement of B on all rows
            E = (We - Wk * B).mid()
            Gkk = arb_mat(len(kept), len(kept), [gm[i * n + j] for i in kept for j in kept])
            B = (B + Gkk.solve((Wk.transpose() * E).mid())).mid()
        except ZeroDivisionError:
            pass
        residual = We - Wk * B
        tail = frobenius_upper(residual)
    elif eliminated:
        B = arb_mat(0, len(eliminated))
        residual = block(scaled, n, range(m), eliminated)
        tail = frobenius_upper(residual)
    else:
        B = arb_mat(len(kept), 0)
        tail = arb(0)

    # s_r >= s_min(Ws_K) >= s_min(Ws_RK) >= 1 / ||Ws_RK^-1||_F
    sigma_lower = arb(0)
    if kept:
        f = frobenius_upper(inverse)
        sigma_lower = arb((1 / f).lower()) if f > 0 else arb(0)

    beta = unscaled(beta_s, kept, eliminated, exponents)

    svals = _approximate_singular_values(G, scaled64) if approximate_spectrum else []
    analysis = BallAnalysis(digits, len(kept), list(kept), eliminated, used, pivots, order, beta_s, beta,
                            exponents, zero, tail, sigma_lower, svals, B, notes)
    analysis.rows = list(rows)
    if residual is not None:
        analysis._residual = (W, residual.mid())
    return analysis


def _refined_fast(scaled: Sequence[arb], shape: tuple[int, int], scaled64: np.ndarray, kept: Sequence[int],
                  eliminated: Sequence[int], Wk: arb_mat, beta_s: arb_mat) -> tuple[arb_mat, arb_mat, arb]:
    """(B, Ws_E - Ws_K B, its Frobenius bound) beyond FAST_DECISIONS_ABOVE columns.

    B starts as the midpoint of beta_s. The least-squares refinement (as for small W) is
    tried only where it can pay: when the residual's midpoints make up more than a quarter
    of its bound (when the balls' radii dominate, no B does better), and kept only if its
    bound is smaller. Both bounds are rigorous for their own exact B, so the smaller one is
    a valid claim; the correction itself is a choice, computed in float64 (the normal
    equations of the scaled midpoints, the residual scaled by a power of two into float
    range: Talos 0.4 s at 30 digits, 0.8 s at 60, in balls before issue 47)."""
    m, n = shape
    We = block(scaled, n, range(m), eliminated)
    B = beta_s.mid()
    residual = We - Wk * B
    tail, size = _frobenius_pair(residual)            # size: ||E||_F bounded, E below
    E = residual.mid()
    if 4 * size > tail and size > 0:
        shift = -math.floor(log10(size) / LOG10_2)          # E * 2^shift: entries at most about 1
        E64 = np.array([float(x * arb(2) ** shift) for x in E.entries()]).reshape(m, len(eliminated))
        K64 = scaled64[:, kept]
        try:
            C64 = np.linalg.solve(K64.T @ K64, K64.T @ E64)
        except np.linalg.LinAlgError:
            return B, residual, tail
        if not np.all(np.isfinite(C64)):
            return B, residual, tail
        C = arb_mat(len(kept), len(eliminated), [float(x) for x in C64.ravel()]) * arb(2) ** (-shift)
        B1 = (B + C).mid()
        other = We - Wk * B1
        bound = frobenius_upper(other)
        if bound < tail:
            return B1, other, bound
    return B, residual, tail


def _analyse_float(W: backends.BallMatrix, digits: int, scaled: Sequence[arb], scaled64: np.ndarray, exponents: list[int],
                   zero: list[int], reuse: tuple[list[int], list[int]] | None,
                   approximate_spectrum: bool, start: BallAnalysis | None = None) -> BallAnalysis | None:
    """The natural-order analysis beyond FAST_DECISIONS_ABOVE columns with K (the leftmost
    basis) and R chosen in float64 (:mod:`baseparams.numeric.decide`), or ``reuse``d from
    the previous precision's float64 choice; None when a proof below fails (the working
    precision then decides, as always). The claims are those of :func:`_analyse`; what its
    decisions at ``digits`` would conclude is proven too, with MARGIN_DECADES to spare:

    - each kept column's Schur pivot in the scaled G is >= sigma_r_lower^2 (interlacing),
      above the leftmost basis' threshold;
    - each eliminated column e lies within ``tail + 2 sqrt(k) ||B[K > e, e]||`` of the
      kept columns left of it (k of them right of it; scaled columns have norms below 2),
      whose square is below that threshold;
    - s_(r+1) <= tail with tail^2 below the noise threshold: no pivot after the r-th.

    With ``start`` (the previous precision's analysis of the same states, which chose K and
    R) beta_s and the bound of ||Ws_RK^-1||_F come from its inverse (:func:`_refined_solve`)
    when that converges, else from one verified solve, as always.
    """
    m, n = scaled64.shape
    live = [j for j in range(n) if j not in set(zero)]
    gmax = max(float(np.max(np.sum(scaled64[:, live] ** 2, axis=0))) if live else 0.0, 1e-300)
    log_noise = math.log10(NOISE_FACTOR * n * gmax) - digits
    log_strict = max(log_noise, math.log10(gmax) - digits // 2)
    if reuse is not None:
        kept, rows = list(reuse[0]), list(reuse[1])
    else:
        kept, Q = decide.natural_columns(scaled64, set(zero), FLOAT_BASIS_RELATIVE * math.sqrt(gmax))
        rows = decide.square_rows(Q)
    r = len(kept)
    if not r or len(rows) != r or max(rows) >= m:
        return None
    eliminated = [j for j in range(n) if j not in set(kept)]
    refined = None if start is None else _refined_solve(scaled, n, rows, kept, eliminated, exponents, start)
    if refined is not None:
        beta_s, f, Y = refined
    else:
        found = solve_block(scaled, n, rows, kept, eliminated)
        if found is None:
            return None
        beta_s, inverse = found
        f, Y = frobenius_upper(inverse), inverse.mid()
    beta_s = centred(beta_s)            # B, its midpoint, on one grid: cheaper products (numeric.ballgrid)
    sigma_lower = arb((1 / f).lower()) if f > 0 else arb(0)
    if not sigma_lower > 0 or 2 * log10(sigma_lower) < log_strict + MARGIN_DECADES:
        return None
    B, residual, tail = arb_mat(r, 0), None, arb(0)
    if eliminated:
        Wk = block(scaled, n, range(m), kept)
        B, residual, tail = _refined_fast(scaled, (m, n), scaled64, kept, eliminated, Wk, beta_s)
    log_tail = log10(tail) if tail != 0 else -math.inf
    if 2 * log_tail > log_noise - MARGIN_DECADES or not _leftmost(B, kept, eliminated, log_tail,
                                                                    log_strict - MARGIN_DECADES):
        return None
    beta = unscaled(beta_s, kept, eliminated, exponents)
    svals = _approximate_singular_values(None, scaled64) if approximate_spectrum else []
    analysis = BallAnalysis(digits, r, list(kept), eliminated, "natural", [], list(kept), beta_s, beta,
                            exponents, zero, tail, sigma_lower, svals, B, [], decided="float64", block_inverse=Y)
    analysis.rows = list(rows)
    if residual is not None:
        analysis._residual = (W, residual.mid())
    return analysis


def _refined_solve(scaled: Sequence[arb], n: int, rows: Sequence[int], kept: Sequence[int],
                   eliminated: Sequence[int], exponents: Sequence[int],
                   start: BallAnalysis) -> tuple[arb_mat, arb, arb_mat] | None:
    """(beta_s, an upper bound of ||Ws_RK^-1||_F, Y) at the working precision from ``start``, the previous
    precision's analysis with the same columns, scaling and rows R: None when it does not apply or does not
    converge (one verified solve then). Why: that solve's factorisation is most of an analysis at 60 digits
    (TIAGo, r = 310: 1.46 of 2.2 s); a few products cost far less (issue 47).

    With Y = the previous inverse (exact) and A = Ws_RK, C = I - Y A encloses every member's; c = ||C||_F upper
    < 1 proves every A nonsingular (YA = I - C). For an exact X, the error D = A^-1 Ws_RE - X solves D = Z + C D
    with Z = Y (Ws_RE - A X): ||D_k|| <= ||Z|| / (1 - c) for each column, so each entry of C D is at most
    c z / (1 - c) (z >= ||Z||_F) and beta_s lies in X + Z widened by that. X starts at the previous beta_s and
    moves to mid(X + Z) while c z > 2^REFINE_SLACK_BITS units of ||X||_F at the working precision (30 -> 60
    digits: one pass; a second only lengthens digits capped by the agreement with 30, for two of five products).
    And ||A^-1||_F = ||(I - C)^-1 Y||_F <= ||Y||_F / (1 - c)."""
    Y = start.block_inverse
    if (Y is None or list(start.kept) != list(kept) or list(start.rows) != list(rows)
            or list(start.exponents) != list(exponents) or list(start.eliminated) != list(eliminated)):
        return None
    r, A = len(kept), block(scaled, n, rows, kept)
    identity = arb_mat(r, r)            # zeros, then the diagonal's ones (a list of r^2 ints: 0.02 s)
    for i in range(r):
        identity[i, i] = 1
    c = frobenius_upper(identity - Y * A)
    if not c < arb(2) ** -REFINE_CONTRACTION_BITS:
        return None
    f = arb((frobenius_upper(Y) / (1 - c)).upper())
    if not eliminated:
        return arb_mat(r, 0), f, Y
    B, X = block(scaled, n, rows, eliminated), start.beta_s.mid()
    small = frobenius_upper(X) * arb(2) ** -(ctx.prec - REFINE_SLACK_BITS)
    for _ in range(REFINE_PASSES):
        Z = Y * (B - A * X)
        z = frobenius_upper(Z)
        if c * z <= small:
            spread = arb(0, (c * z / (1 - c)).upper())
            return X + Z + arb_mat(r, len(eliminated), [spread] * (r * len(eliminated))), f, Y
        X = (X + Z).mid()
    return None


def _leftmost(B: arb_mat, kept: Sequence[int], eliminated: Sequence[int], log_tail: float, log_limit: float) -> bool:
    """Is every eliminated column e within 10^(log_limit / 2) of the kept columns left of it?
    Bounded by ``tail + 2 sqrt(k) ||B[K > e, e]||`` (B exact; each |entry| bounded in float64
    with one part in 10^15 and 1e-300 to spare, so underflow cannot hide one)."""
    r, e = len(kept), len(eliminated)
    if not e:
        return True
    b = np.abs(np.fromiter(map(float, B.entries()), dtype=float, count=r * e)).reshape(r, e) * (1 + 1e-15) + 1e-300
    below = np.vstack([np.cumsum((b ** 2)[::-1], axis=0)[::-1], np.zeros((1, e))])   # below[s]: rows s..r-1
    starts = np.searchsorted(np.asarray(kept), np.asarray(eliminated), side="right")
    right = r - starts
    with np.errstate(divide="ignore"):
        log_b = np.log10(2 * np.sqrt(right) * np.sqrt(below[starts, np.arange(e)]) * (1 + 1e-15))
    worst = np.maximum(log_b, log_tail) + LOG10_2
    return bool(np.all(2 * worst <= log_limit))

def unscaled(beta_s: arb_mat, kept: Sequence[int], eliminated: Sequence[int], exponents: Sequence[int]) -> arb_mat:
    """beta = D_K^-1 beta_s D_E entry by entry (powers of two: exact)."""
    values = beta_s.entries()
    ne = len(eliminated)
    if not kept or not ne:
        return arb_mat(len(kept), ne)
    shifts = (np.take(exponents, eliminated)[None, :] - np.take(exponents, kept)[:, None]).ravel().tolist()
    table = {s: arb(2) ** s for s in set(shifts)}            # each entry times one, iterated in C
    return arb_mat(len(kept), ne, list(map(arb.__mul__, values, map(table.__getitem__, shifts))))


def _approximate_singular_values(G: arb_mat | None, scaled64: np.ndarray) -> list[str]:
    """sqrt(|eigenvalues|) of the scaled Gram matrix, largest first, as decimal strings.

    ``acb_mat.eig(algorithm="approx")``: no error bounds (the cluster of zero eigenvalues
    defeats rigorous isolation); the values after the ridge are the working precision's
    noise, and ``BallAnalysis.tail_bound`` bounds them rigorously. Beyond
    ``SPECTRUM_IN_ARB_UP_TO`` parameters (an eig at D digits costs tens of seconds there)
    they are the float64 singular values of Ws's midpoints (``scaled64``): the same values
    to float accuracy (absolute 1e-16 of the largest), nothing proven either way.
    """
    m, n = scaled64.shape
    if n == 0:
        return []
    if n > SPECTRUM_IN_ARB_UP_TO:
        values = np.linalg.svd(scaled64, compute_uv=False) if m else np.zeros(0)
        return [arb(float(v)).str(12, radius=False) for v in values] + ["0"] * (n - len(values))
    assert G is not None                # beyond SPECTRUM_IN_ARB_UP_TO columns only scaled64 is read
    M = acb_mat(G)
    spectrum = [abs(e.real.mid()).sqrt() for e in M.eig(algorithm="approx")]
    spectrum.sort(key=lambda v: -log10(v))
    return [v.str(12, radius=False) for v in spectrum]


def decimal_string(x: arb, digits: int) -> str:
    """The midpoint with ``digits`` significant digits, without the radius."""
    digits = max(1, min(int(digits), 100_000))
    return x.mid().str(digits, radius=False).replace("e+", "e")
