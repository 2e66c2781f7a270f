"""Gautier's SVD method in double precision, with the diagnostics it needs to be honest.

Gautier (1991): with ``W = U S V^T`` and ``V = [V1 V2]`` split at the numerical rank
r, every vector of the null space of W is ``V2 a``; permuting the parameters so that
the block ``V22`` of V2 (rows of the parameters to eliminate) is square and invertible
gives the base parameters ``phi_b = phi_1 + beta phi_2`` with ``beta = -V21 V22^-1``
(the seed paper's section 2).

Choices made here, all reported in the result's diagnostics:

- **Column scaling.** Parameters have different units (kg, kg m, kg m^2), so the columns
  of W differ by orders of magnitude. Each column is divided by the power of two
  nearest its Euclidean norm (exact in binary floating point, so scaling adds no
  rounding). The base parameters do not depend on it (beta is scaled back exactly);
  the rank decision and the pivoting do.
- **Numerically zero columns.** A column whose norm is below ``max(shape) * eps *``
  (largest column norm) is rounding noise of an exactly zero column (the PUMA 560's
  ``mz2`` is 5.6e-15 where the other columns are ~1..40); scaling it up to norm 1
  would invent a rank. Such columns are set to zero and listed.
- **Rank.** The usual tolerance ``max(shape) * eps * s_max`` on the scaled W
  (numpy's ``matrix_rank`` default).
- **Directions lifted by scaling.** Rounding errors in W are of the size of W's entries,
  not of each column's: two small columns equal up to rounding (so100's ``mx1`` and ``mx2``,
  norm 8e-4 where W's largest is 200, differing by 1e-14) become, scaled to norm 1, a
  direction with a singular value above the scaled tolerance. So a trailing singular
  direction ``v`` of the scaled W is not counted when, in the parameters' own units
  (``x = v / scale``), ``|W x| / |x| = s / |v / scale|`` is at most the unscaled tolerance
  ``max(shape) * eps * s_max(W)``: below W's rounding level, as the unscaled rule would say.
  The directions dropped and the columns that carry them are reported.
- **Ridge.** Ratios ``s_i / s_{i+1}`` of consecutive singular values, for the values
  above the tolerance (the one below the cut is floored at ``eps * s_max``, the noise
  level of a double-precision SVD). The ridge is *clear* when the largest ratio is at
  least ``RIDGE_RATIO`` (1e3) and falls exactly at the tolerance cut; anything else is a
  warning, because the rank then depends on the tolerance, not on the mechanism.
- **Permutation.** By default (``pivoting="natural"``, since issue 45) the kept parameters
  are the leftmost independent columns of W, the choice vp, exact and symbolic make, so that
  every solver gives the same base parameters under the same names: the columns of ``V1^T``
  (W's row space) are taken left to right, each kept when its part outside the kept ones'
  span is above ``NATURAL_FLOOR``. Should that choice make ``cond(V22)`` larger than
  ``NATURAL_CONDITION`` (beta's error estimate grows with it, and the base regressor's
  conditioning for identification with it; QR pivoting's is 1-3 on the built-ins), or find
  too few columns (a nearly dependent column in the way), the pivoted choice is taken, and
  a note says so. ``pivoting="qr"``: QR with
  column pivoting (Businger-Golub) on ``V2^T`` picks the n-r parameters whose rows of V2 are
  the most independent: they are eliminated, which makes ``V22`` as well conditioned as a
  greedy choice can.
- **Economy SVD.** Only ``S`` and ``V`` are used, so a tall W (rows >= n) gets the thin
  SVD: memory ``rows x n``, not ``rows x rows`` (100,000 samples of a pendulum would
  otherwise ask for 74.5 GiB). A wide W (rows < n) needs the full ``V`` (n x n), and then
  ``U`` is only rows x rows.
- **Failure.** Non-finite entries in W (a degenerate axis or a geometry value beyond
  double precision makes the kinematics NaN) or an SVD that does not converge raise a
  :class:`baseparams.errors.KinematicsError` saying where, never numpy's LinAlgError.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from baseparams.errors import KinematicsError
from baseparams.numeric.linalg import pivoted_qr_columns, power_of_two_exponents
from baseparams.numeric.rank import numerical_rank

RIDGE_RATIO = 1e3
EPS = np.finfo(float).eps
NATURAL_FLOOR = 1e-6        # a column of V1^T outside the kept ones' span by less is dependent
NATURAL_CONDITION = 100     # the largest cond(V22) the natural choice may have (QR pivoting's is ~1-3)
NATURAL_BLOCK = 64          # columns projected together (one matrix product per block)


@dataclass
class DPResult:
    rank: int
    kept: list                   # column indices of phi_1 (base parameters' leading terms)
    eliminated: list             # column indices of phi_2
    beta: np.ndarray             # rank x len(eliminated), unscaled: phi_b = phi_1 + beta phi_2
    beta_s: np.ndarray           # the same in the scaled units of Ws (where its error is estimated)
    singular_values: np.ndarray  # of the scaled W, largest first
    tolerance: float
    scale: np.ndarray            # column scale factors (powers of two; 1 for zero columns)
    zero_columns: list           # exactly or numerically zero columns
    ratios: np.ndarray           # s_i / s_{i+1} for i < rank (last one across the cut)
    largest_gap: int             # i (1-based): the largest ratio is s_i / s_{i+1}
    clear_ridge: bool
    error_estimate: float        # first-order error of beta (scaled units): s_{r+1}/s_r * cond(V22)
    v22_condition: float
    warnings: list = field(default_factory=list)
    lifted: int = 0              # directions the scaling lifted above the tolerance, not counted
    lifted_columns: list = field(default_factory=list)   # the columns that carry them most
    kept_note: str = ""          # why the kept parameters are not the leftmost independent ones


def dp_gautier(W: np.ndarray, scale: bool = True, rank: int | None = None,
               columns: Sequence[str] | None = None, rows: int | None = None,
               pivoting: str = "natural") -> DPResult:
    """Gautier's method on a float64 observation matrix ``W`` (rows x parameters).

    ``rank``: force the rank (to study what DP gives at a rank known from elsewhere);
    by default the tolerance decides. ``columns``: the parameters' names, for messages.
    ``rows``: W is the triangular factor R (``R^T R = W^T W``,
    :func:`baseparams.numeric.linalg.triangular_factor`) of an observation matrix of this
    many rows: the same singular values, right singular vectors and column norms, so the
    same analysis; the row count enters the tolerances as W's would.
    ``pivoting``: ``"natural"`` (the leftmost independent columns kept) or ``"qr"`` (see the
    module doc). Raises :class:`KinematicsError` if W is not finite or the SVD fails.
    """
    W = np.asarray(W, dtype=float)
    n = W.shape[1]
    rows = W.shape[0] if rows is None else int(rows)
    check_finite(W, columns)
    norms = _column_norms(W)
    col_tol = max(rows, n) * EPS * (norms.max() if n else 0.0)
    zero_columns = [j for j in range(n) if norms[j] <= col_tol]
    W = W.copy()
    W[:, zero_columns] = 0.0
    norms[zero_columns] = 0.0
    with np.errstate(divide="ignore"):
        s_col = np.exp2(power_of_two_exponents(np.log2(norms))) if scale else np.ones(n)
    Ws = W / s_col

    s, vt = _singular_values_and_vt(Ws)
    s_full = np.zeros(n)
    s_full[:len(s)] = s
    s_max = s_full[0] if n else 0.0
    tol = max(rows, n) * EPS * s_max
    r_tol = numerical_rank(singular_values=s_full, tol=max(rows, n) * EPS)     # s_i > tol
    lifted = _lifted_by_scaling(W, s_full, vt, s_col, r_tol, rows) if scale and rank is None else 0
    warnings = []
    lifted_columns = []
    if lifted:
        weight = np.abs(vt[r_tol - lifted:r_tol]).max(axis=0)
        carriers = [j for j in np.argsort(-weight)[:6] if weight[j] >= 0.1 * weight.max()]
        lifted_columns = [str(columns[j]) if columns is not None else str(j) for j in carriers]
        warnings.append(
            f"{lifted} singular direction(s) of the scaled W above its tolerance are below W's rounding "
            f"level in the parameters' own units (carried by the small columns {', '.join(lifted_columns)}, "
            f"lifted by the column scaling): not counted, rank {r_tol - lifted} instead of {r_tol}")
        r_tol -= lifted
    r = r_tol if rank is None else int(rank)

    floor = EPS * s_max
    ratios = np.array([s_full[i] / max(s_full[i + 1], floor) for i in range(min(r_tol, n - 1))]) \
        if s_max > 0 else np.array([])
    if r_tol == n and n:
        ratios = ratios[:n - 1]
    largest = int(np.argmax(ratios)) + 1 if ratios.size else 0
    clear = bool(ratios.size) and ratios.max() >= RIDGE_RATIO and largest == r_tol
    if ratios.size and ratios.max() < RIDGE_RATIO:
        warnings.append(
            f"no clear ridge: the largest ratio between consecutive singular values above the "
            f"double-precision noise floor is {ratios.max():.3g} < {RIDGE_RATIO:.0e} "
            f"(s_{largest}/s_{largest + 1}); the rank {r_tol} is set by the tolerance "
            f"{tol:.3g}, not by the mechanism")
    elif ratios.size and largest != r_tol:
        warnings.append(
            f"no clear ridge at the tolerance cut: the tolerance {tol:.3g} gives rank {r_tol} "
            f"(s_{r_tol}/s_{r_tol + 1} = {ratios[r_tol - 1] if r_tol - 1 < ratios.size else float('nan'):.3g}), "
            f"but the largest gap is after s_{largest} (ratio {ratios.max():.3g}); "
            f"the rank depends on the tolerance")
    if rank is not None and rank != r_tol:
        warnings.append(f"rank forced to {rank}; the tolerance gives {r_tol}")

    v = vt.T
    notes: list[str] = []
    kept, eliminated, cond22 = _kept_columns(v, r, pivoting, notes)
    if eliminated:
        v2 = v[:, r:]
        v21, v22 = v2[kept, :], v2[eliminated, :]
        try:
            beta_s = -np.linalg.solve(v22.T, v21.T).T
        except np.linalg.LinAlgError:
            raise KinematicsError(
                f"the block V22 of the null space is singular in double precision: the "
                f"{n - r} parameters to eliminate cannot be chosen (rank {r} of {n}"
                + (", forced" if rank is not None else "") + ")") from None
    else:
        beta_s = np.zeros((r, 0))
    beta = beta_s * s_col[eliminated][None, :] / s_col[kept][:, None] if eliminated else beta_s
    noise = max(s_full[r] if r < n else 0.0, floor)      # the observed noise level
    err = noise / s_full[r - 1] * cond22 if r else 0.0
    if err > 1e-6:
        warnings.append(f"beta is uncertain: estimated relative error {err:.2g} "
                        f"(s_{r + 1} = {noise:.3g} / s_{r} = {s_full[r - 1]:.3g} x cond(V22) = {cond22:.3g})")
    return DPResult(r, kept, eliminated, beta, beta_s, s_full, tol, s_col, zero_columns, ratios, largest,
                    clear, err, cond22, warnings, lifted, lifted_columns, "".join(notes))


def _kept_columns(v: np.ndarray, r: int, pivoting: str, notes: list[str]) -> tuple[list[int], list[int], float]:
    """(kept, eliminated, cond(V22)) for rank ``r`` from the full V (columns: right singular
    vectors): the leftmost independent columns (``"natural"``, falling back to QR pivoting
    when that costs conditioning) or QR pivoting's (``"qr"``)."""
    n = v.shape[0]
    if r >= n:
        return list(range(n)), [], 1.0
    v2 = v[:, r:]

    def split(kept: list[int]) -> tuple[list[int], list[int], float]:
        chosen = set(kept)
        eliminated = [j for j in range(n) if j not in chosen]
        v22 = v2[eliminated, :]
        return kept, eliminated, float(np.linalg.cond(v22)) if eliminated else 1.0

    pivoted = None
    if pivoting == "natural":
        natural = _leftmost_independent(v[:, :r].T)
        if len(natural) == r:
            result = split(natural)
            if result[2] <= NATURAL_CONDITION:
                return result
            pivoted = split(sorted(set(range(n)) - set(pivoted_qr_columns(v2.T, n - r))))
            why = f"make cond(V22) {result[2]:.3g}, above {NATURAL_CONDITION:g} (QR pivoting's: {pivoted[2]:.3g})"
        else:
            why = f"are {len(natural)} of {r} columns above {NATURAL_FLOOR:g}"
        notes.append(f"kept parameters by QR pivoting: the leftmost independent ones (vp's, exact's) {why}, "
                     f"so these base parameters are other combinations than theirs")
    return pivoted or split(sorted(set(range(n)) - set(pivoted_qr_columns(v2.T, n - r))))


def _leftmost_independent(a: np.ndarray) -> list[int]:
    """Indices of the leftmost columns of ``a`` (r x n, orthonormal rows) that are
    independent: each kept when its part outside the kept columns' span has a norm above
    ``NATURAL_FLOOR`` (Gram-Schmidt, twice, by blocks of columns)."""
    r, n = a.shape
    basis = np.zeros((r, 0))
    kept: list[int] = []
    for start in range(0, n, NATURAL_BLOCK):
        if len(kept) == r:
            break
        block = a[:, start:start + NATURAL_BLOCK].copy()
        for _ in range(2):
            block -= basis @ (basis.T @ block)
        new: list[np.ndarray] = []
        for k in range(block.shape[1]):
            x = block[:, k]
            for _ in range(2):
                for q in new:
                    x = x - q * (q @ x)
            size = float(np.linalg.norm(x))
            if size > NATURAL_FLOOR and len(kept) < r:
                new.append(x / size)
                kept.append(start + k)
        if new:
            basis = np.hstack([basis, np.array(new).T])
    return kept


def _lifted_by_scaling(W: np.ndarray, s: np.ndarray, vt: np.ndarray, s_col: np.ndarray, r_tol: int,
                       rows: int) -> int:
    """How many of the trailing singular directions counted in the scaled W are below the
    unscaled tolerance in the parameters' own units (see the module doc); ``rows``: W's
    row count (W may be its triangular factor)."""
    n = W.shape[1]
    if not r_tol:
        return 0
    big = float(np.max(np.abs(W))) if W.size else 0.0
    if big == 0.0:
        return 0
    unit = W / big                                  # no overflow in the Gram matrix at 1e+-200
    s_max = big * float(np.sqrt(max(np.linalg.eigvalsh(unit.T @ unit)[-1], 0.0)))
    tol_units = max(rows, n) * EPS * s_max
    lifted = 0
    for k in range(r_tol - 1, -1, -1):
        x = vt[k] / s_col
        peak = float(np.max(np.abs(x)))
        size = peak * float(np.linalg.norm(x / peak)) if peak else 0.0       # no overflow near 1e+-200
        if size == 0.0 or s[k] / size > tol_units:
            break
        lifted += 1
    return lifted


def check_finite(W: np.ndarray, columns: Sequence[str] | None) -> None:
    """Refuse a W with NaN or infinite entries, naming the columns (parameters) and rows hit."""
    finite = np.isfinite(W)
    if finite.all():
        return
    bad_rows, bad_cols = np.nonzero(~np.all(finite, axis=1))[0], np.nonzero(~np.all(finite, axis=0))[0]
    names = [str(columns[j]) if columns is not None else str(j) for j in bad_cols[:6]]
    more = f" and {len(bad_cols) - 6} more" if len(bad_cols) > 6 else ""
    raise KinematicsError(
        f"the observation matrix W has {int((~finite).sum())} non-finite entries (NaN or inf) in "
        f"{len(bad_rows)} of {W.shape[0]} rows, in the columns of {', '.join(names)}{more}: the "
        f"kinematics cannot be evaluated in double precision (a degenerate axis or ref, or a "
        f"geometry value too small or too large for float64)")


def _column_norms(W: np.ndarray) -> np.ndarray:
    """Euclidean column norms without overflow or underflow (entries near 1e+-300 stay exact)."""
    largest = np.max(np.abs(W), axis=0) if W.shape[0] else np.zeros(W.shape[1])
    safe = np.where(largest > 0, largest, 1.0)
    with np.errstate(over="ignore"):
        return largest * np.linalg.norm(W / safe, axis=0)


def _singular_values_and_vt(Ws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values and the full n x n V^T; economy SVD when W is tall (see the module doc)."""
    rows, n = Ws.shape
    try:
        _, s, vt = np.linalg.svd(Ws, full_matrices=rows < n)
        return s, vt
    except np.linalg.LinAlgError:
        pass
    try:
        # LAPACK's divide and conquer (gesdd) may fail to converge where the QR iteration
        # (gesvd) does not (so100's stacked W): the slower driver before giving up
        import scipy.linalg
        _, s, vt = scipy.linalg.svd(Ws, full_matrices=rows < n, lapack_driver="gesvd")
    except (np.linalg.LinAlgError, ValueError):
        raise KinematicsError(
            f"the SVD of the observation matrix W ({rows} x {n}, largest entry "
            f"{float(np.max(np.abs(Ws))):.3g}) did not converge in double precision: the "
            f"kinematics are degenerate or badly scaled (try the vp solver)") from None
    return s, vt
