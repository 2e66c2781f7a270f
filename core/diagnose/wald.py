"""The tests selection makes: Wald tests of a candidate's directions beyond the current
model with a heteroscedasticity-and-autocorrelation-consistent (HAC) covariance, encompassing
tests between two candidates, Holm's correction, and the orthonormal bases they test.

Everything works on the weighted, stacked rows of the model (sample-major: the f
coordinates of sample 1, then of sample 2 ...); :mod:`.selection` makes the forward and
backward steps from these tests.

Why these choices:

- A candidate's columns are first projected on the orthogonal complement of the current
  model (Frisch-Waugh-Lovell): the test then sees only what the candidate adds, and a
  candidate the model absorbs (rotor inertia on a joint whose inertia is already a base
  parameter; an offset once a spring on the same independent coordinate is in) has no
  direction left and is not tested at all (``absorbed``).
- Wald, not score (LM), statistics: with a strong missing effect the LM statistic's HAC
  variance is computed from a residual that still contains the effect, which bounds the
  statistic near N / lags and makes every correlated candidate look alike. The Wald
  statistic uses the residual after the candidate is added, so the true effect stands out.
- The HAC covariance sums each sample's scores over its coordinates and applies the
  Newey-West (Bartlett) kernel over time (Driscoll-Kraay), with statsmodels'
  ``S_hac_simple``. The lag window is at least the Newey-West rule 4 (N/100)^(2/9) and at
  least the lag where the residual's autocorrelation falls inside its 95 % band: oversampled,
  low-pass-filtered residuals are correlated over many samples and a naive F test would
  reject far too often.
- p values from F(r, dof) (r the candidate's directions, dof the rows left), ranked by the
  Wilson-Hilferty normal equivalent of the statistic, which does not saturate at p = 0 and
  compares candidates with different numbers of columns.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import fdtrc

from baseparams.identify.longrun import hac_lags, hac_lags_each, local_power, long_run_each, stationary_variance
from baseparams.identify.linear import LinearFit as Fit, Reduced
from baseparams.numeric.linalg import column_norms, thin_svd
from baseparams.numeric.rank import numerical_rank

if TYPE_CHECKING:             # selection imports this module: its Candidate only for the types
    from baseparams.diagnose.selection import Candidate

# A candidate direction that keeps less than ABSORB_TOL of its (unit) norm after the
# current model is projected out is absorbed by the model.
ABSORB_TOL = 1e-7
# The tests are asymptotic in the number of samples a candidate acts on: a candidate whose
# directions spread over fewer samples than this fraction of the data (a Stribeck bump
# sampled at a few zero crossings) is not tested (its statistic would be one spike).
MIN_SUPPORT = 0.05
# The most bytes of candidate columns projected off the model, or of directions tested, at once.
BATCH_BYTES = 64 << 20


@dataclass(frozen=True)
class Test:
    """A Wald test: statistic, degrees of freedom (directions tested), p value, and the
    Wilson-Hilferty normal equivalent ``z`` used for ranking; ``lags`` of the HAC window."""
    stat: float
    df: int
    pvalue: float
    z: float
    lags: int = 0
    reason: str = ""              # why not tested: "absorbed" or "support"

    @property
    def tested(self) -> bool:
        return self.df > 0


NOT_TESTED = Test(0.0, 0, 1.0, -np.inf, reason="absorbed")
TOO_SPARSE = Test(0.0, 0, 1.0, -np.inf, reason="support")


# ----- linear algebra --------------------------------------------------------------------
def orthonormal_basis(matrix: np.ndarray, tol: float, reference: np.ndarray | None = None) -> np.ndarray:
    """An orthonormal basis of the range of ``matrix`` (rows, k): directions whose singular
    value exceeds ``tol`` times the norm of the corresponding ``reference`` columns (the
    columns before a projection; default: the largest singular value)."""
    if matrix.shape[1] == 0:
        return np.zeros((matrix.shape[0], 0))
    if matrix.shape[1] == 1:          # one column: its direction (an SVD call costs 10 times more)
        column = matrix[:, 0]
        norm = float(np.sqrt(column @ column))
        size = norm if reference is None else float(np.sqrt(reference[:, 0] @ reference[:, 0]))
        if norm == 0.0 or (reference is not None and norm <= tol * (size if size > 0 else 1.0)):
            return np.zeros((matrix.shape[0], 0))
        return (column / norm)[:, None]
    # how many leading directions to keep, from the singular values (largest first)
    count: Callable[[np.ndarray], int]
    if reference is not None:
        scale = column_norms(reference)
        count = lambda s: int(np.sum(s > tol))                               # noqa: E731
    else:
        scale = column_norms(matrix)
        count = lambda s: numerical_rank(tol=tol, singular_values=s)         # noqa: E731
    zero = reference is None and bool(np.any(scale == 0))   # a zero column: the Cholesky route must fail
    scale[scale == 0] = 1.0
    u, s, _ = thin_svd(matrix / scale, keep=count, zero_column=zero)
    return u[:, :count(s)]


def project_out(matrix: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """matrix minus its projection on the (orthonormal) ``basis``."""
    if basis.shape[1] == 0:
        return matrix
    return matrix - basis @ (basis.T @ matrix)


def support(basis: np.ndarray, shape: tuple[int, int]) -> float:
    """The fewest samples any direction of ``basis`` effectively acts on (participation
    ratio 1 / sum_t w_t^2 of its energy per sample w_t), over the subspace's canonical
    directions (:func:`canonical_each`)."""
    return float(support_each(basis[None], shape)[0])


def support_each(bases: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """:func:`support` of each of m bases (m, rows, r) of one width."""
    return _support_of_canonical(canonical_each(bases, shape), shape)


def _support_of_canonical(bases: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """:func:`support_each` of bases already rotated by :func:`canonical_each`."""
    n, f = shape
    b = bases.reshape(len(bases), n, f, -1)
    w = np.einsum("mtjr,mtjr->mtr", b, b)
    total, squares = w.sum(axis=1), np.einsum("mtr,mtr->mr", w, w)
    return np.where(squares > 0, total ** 2 / np.where(squares > 0, squares, 1.0), np.inf).min(axis=1)


def canonical_each(bases: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Each orthonormal basis (m, rows, r) rotated to the eigenvectors of sum_t G_t^2, where
    G_t = sum_j b_tj b_tj' is what sample t carries of the subspace (r, r). Why: a measure
    taken direction by direction (how few samples a direction acts on) must not depend on
    which orthonormal basis of the subspace the SVD returned; the SVD's choice among the
    bases of a subspace whose singular values are all 1 is decided by rounding, and on a
    PUMA step four such bases gave supports from 18 to 96 samples. These directions are the
    subspace's own: the most and the least concentrated in time."""
    m, rows, r = bases.shape
    if r <= 1:
        return bases
    n, f = shape
    rotated = np.empty_like(bases)
    for k in range(m):                        # one at a time: G is (n, r, r)
        b = bases[k].reshape(n, f, r)
        G = np.matmul(b.transpose(0, 2, 1), b).reshape(n * r, r)
        _, vectors = np.linalg.eigh(G.T @ G)   # sum_t G_t^2 = sum_t G_t' G_t (G_t symmetric)
        rotated[k] = bases[k] @ vectors
    return rotated


def wilson_hilferty(stat: float, df: int) -> float:
    """The normal deviate with the same upper tail as chi2(df) at ``stat`` (approximately)."""
    if df <= 0:
        return -np.inf
    c = 2.0 / (9.0 * df)
    return float(((max(stat, 0.0) / df) ** (1.0 / 3.0) - (1.0 - c)) / np.sqrt(c))


def wald(residual: np.ndarray, basis: np.ndarray, shape: tuple[int, int], dof: int,
         lags: int | None = None, sparse_if_white: bool = False, extra_df: int = 0,
         prewhiten: bool = True, sparse_if_coloured: bool = False) -> Test:
    """Wald test that the orthonormal directions ``basis`` (rows, r), orthogonal to the null
    model, have zero coefficients, given the null model's ``residual`` (rows,). HAC covariance:
    per-sample scores summed over the f coordinates, Bartlett kernel over time.

    Directions acting on fewer samples than MIN_SUPPORT are not tested (their HAC variance
    would rest on a few scores), unless ``sparse_if_white`` and the residual is white (HAC
    window 0): then the classical variance sigma^2 I (the directions are orthonormal and
    orthogonal to the null model, the weighted noise has one level per row) is exact for
    white noise however few samples the directions act on (see :func:`.selection.resolve`); and, with
    ``sparse_if_coloured`` too, on a coloured residual the variance from its autocovariance
    over all samples (:func:`~baseparams.identify.longrun.stationary_variance`); either
    scaled up by the noise's local power where the direction acts
    (:func:`~baseparams.identify.longrun.local_power`) when that is above its average."""
    return wald_each([residual], [basis], shape, [dof], lags, [extra_df], sparse_if_white, sparse_if_coloured,
                     prewhiten)[0]


def wald_each(residuals: Sequence[np.ndarray], bases: Sequence[np.ndarray], shape: tuple[int, int],
              dofs: Sequence[int], lags: int | None, extra_df: Sequence[int], sparse_if_white: bool = False,
              sparse_if_coloured: bool = False, prewhiten: bool = True) -> list[Test]:
    """:func:`wald` of each basis against its residual (one residual for all when
    ``residuals`` has one), with its null model's ``dofs`` and its ``extra_df``; the bases of
    one width that are not sparse (most: a friction or offset column) all at once, in matrix
    form (BATCH_BYTES at a time). Why: a step tests every form of every candidate (about 130
    on the TX40) and compares the winner with each rival, and one call per form was a fifth
    of diagnose's time, most of it in small numpy calls."""
    n, f = shape
    rows = n * f
    count = len(bases)
    residual_of = (lambda i: residuals[0]) if len(residuals) == 1 else (lambda i: residuals[i])
    dof_of = (lambda i: dofs[0]) if len(dofs) == 1 else (lambda i: dofs[i])
    tests: list[Test | None] = [None] * count
    for r in sorted({b.shape[1] for b in bases}):
        group = [i for i in range(count) if bases[i].shape[1] == r]
        if r == 0:
            for i in group:
                tests[i] = NOT_TESTED
            continue
        per_batch = max(1, BATCH_BYTES // (8 * rows * r))
        for first in range(0, len(group), per_batch):
            members = group[first:first + per_batch]
            B = np.stack([bases[i] for i in members])                            # (m, rows, r)
            canonical = canonical_each(B, shape)       # made once: the sparse tests work on them too
            dense = _support_of_canonical(canonical, shape) >= max(MIN_SUPPORT * n, 10)
            for k, (i, is_dense) in enumerate(zip(members, dense)):
                if not is_dense:
                    tests[i] = (_sparse_test(residual_of(i), canonical[k], shape, dof_of(i), lags, sparse_if_coloured)
                                if sparse_if_white else TOO_SPARSE)
            chosen = [i for i, is_dense in zip(members, dense) if is_dense]
            if chosen:
                R = np.stack([residual_of(i) for i in chosen])
                results = _dense_tests(R, B[dense], shape, np.array([dof_of(i) for i in chosen]), lags,
                                       np.array([extra_df[0] if len(extra_df) == 1 else extra_df[i] for i in chosen]),
                                       prewhiten)
                for i, test in zip(chosen, results):
                    tests[i] = test
    return tests                                                                     # type: ignore[return-value]


def _dense_tests(R: np.ndarray, B: np.ndarray, shape: tuple[int, int], dofs: np.ndarray, lags: int | None,
                 extra_df: np.ndarray, prewhiten: bool) -> list[Test]:
    """HAC Wald tests of m sets of r directions B (m, rows, r) that are not sparse, each
    against its residual R (m, rows) (:func:`wald`)."""
    n, f = shape
    m, rows, r = B.shape
    gamma = np.einsum("mxr,mx->mr", B, R)
    augmented = R - np.einsum("mxr,mr->mx", B, gamma)
    windows = (hac_lags_each(np.moveaxis(augmented.reshape(m, n, f), 0, 2)) if lags is None
               else np.full(m, lags, dtype=int))
    scores = np.einsum("mtjr,mtj->mtr", B.reshape(m, n, f, r), augmented.reshape(m, n, f))
    left = np.maximum(rows - dofs - r, 1)
    S = long_run_each(scores, windows, prewhiten) * (rows / left)[:, None, None]     # small-sample factor
    white = np.nonzero((windows == 0) & prewhiten)[0]
    if white.size:
        # no autocorrelation left: White's variance, but never below the classical one
        # (sigma^2 I on orthonormal directions), which White's underestimates where few
        # samples carry a direction (liberal in the tails: 1.7 times at 1 % on the PUMA)
        classical = np.einsum("mx,mx->m", augmented[white], augmented[white]) / left[white]
        values, vectors = np.linalg.eigh(S[white])
        S[white] = (vectors * np.maximum(values, classical[:, None])[:, None, :]) @ np.swapaxes(vectors, 1, 2)
    try:
        stat = np.einsum("mr,mr->m", gamma, np.linalg.solve(S, gamma[:, :, None])[:, :, 0])
    except np.linalg.LinAlgError:                   # a singular one among them: each alone
        stat = np.array([_quadratic(g, V) for g, V in zip(gamma, S)])
    k = r + extra_df              # a shape fitted over a grid: one more degree of freedom each
    denominator = np.maximum(n - np.ceil(dofs / f).astype(int) - r, 1)   # samples left: scores are per sample
    pvalues = fdtrc(k, denominator, stat / k)      # F upper tail (stats.f.sf, 40x faster)
    return [Test(float(s_), r, float(p), wilson_hilferty(float(s_), int(kk)), int(L))
            for s_, p, kk, L in zip(stat, pvalues, k, windows)]


def _sparse_test(residual: np.ndarray, basis: np.ndarray, shape: tuple[int, int], dof: int, lags: int | None,
                 sparse_if_coloured: bool) -> Test:
    """:func:`wald` of directions acting on few samples: the classical variance on a white
    residual, the stationary one on a coloured residual (with ``sparse_if_coloured``, else
    not tested), scaled by the noise's local power where they act. ``basis``: already
    rotated by :func:`canonical_each` (the local-power scaling below is direction by
    direction: made on the subspace's own directions, not on the basis an SVD returned)."""
    n, f = shape
    r = basis.shape[1]
    gamma = basis.T @ residual
    augmented = residual - basis @ gamma
    if lags is None:
        lags = hac_lags(augmented.reshape(n, f))
    rows = n * f
    left = max(rows - dof - r, 1)
    if lags > 0 and not sparse_if_coloured:
        return TOO_SPARSE
    noise, directions = augmented.reshape(n, f), basis.reshape(n, f, r)
    if lags > 0:
        V = stationary_variance(noise, directions, lags, left / f, truncated=True)
    else:
        V = float(augmented @ augmented) / left * np.eye(r)
    # each direction's variance scaled up by the noise's local power where it acts, when
    # that is above the residual's average: a direction where the residual is larger
    # (at velocity reversals, under load) is not named on that excess
    power = local_power(noise, lags)
    energy = directions ** 2
    factor = np.sqrt(np.maximum(np.einsum("tj,tjr->r", power, energy) / energy.sum(axis=(0, 1)), 1.0))
    stat = _quadratic(gamma / factor, V)
    pvalue = float(fdtrc(r, left, stat / r))
    return Test(stat, r, pvalue, wilson_hilferty(stat, r), lags)


def _quadratic(gamma: np.ndarray, V: np.ndarray) -> float:
    """gamma' V^-1 gamma (the pseudo-inverse when V is singular)."""
    try:
        return float(gamma @ np.linalg.solve(V, gamma))
    except np.linalg.LinAlgError:
        return float(gamma @ np.linalg.pinv(V) @ gamma)


def candidate_basis(candidate: "Candidate | np.ndarray", fit: "Fit | Reduced") -> np.ndarray:
    """The candidate's (or columns') directions beyond the current model (weighted, orthonormal)."""
    columns = candidate if isinstance(candidate, np.ndarray) else candidate.columns
    n, f, c = columns.shape
    Z = (columns * fit.weights[None, :, None]).reshape(n * f, c)
    return orthonormal_basis(fit.orthogonal(Z), ABSORB_TOL, reference=Z)


def column_bases(arrays: Sequence[np.ndarray], fit: "Fit | Reduced") -> list[np.ndarray]:
    """:func:`candidate_basis` of each array of columns (n, f, c), projected off the model
    together, BATCH_BYTES at a time."""
    if not arrays:
        return []
    n, f, _ = arrays[0].shape
    per_batch = max(1, BATCH_BYTES // (8 * n * f))       # columns projected at once (bounded memory)
    bases: list[np.ndarray] = []
    first = 0
    while first < len(arrays):
        last, width = first, 0
        while last < len(arrays) and (last == first or width + arrays[last].shape[-1] <= per_batch):
            width += arrays[last].shape[-1]
            last += 1
        bounds = np.cumsum([0] + [c.shape[-1] for c in arrays[first:last]])
        Z = np.empty((n * f, width))                     # the weighted columns, written in place
        stacked = Z.reshape(n, f, width)
        for columns, a, b in zip(arrays[first:last], bounds[:-1], bounds[1:]):
            np.multiply(columns, fit.weights[None, :, None], out=stacked[:, :, a:b])
        bases += _orthonormal_blocks(fit.orthogonal(Z), Z, bounds)
        first = last
    return bases


def _orthonormal_blocks(projected: np.ndarray, reference: np.ndarray, bounds: np.ndarray) -> list[np.ndarray]:
    """:func:`orthonormal_basis` (at ABSORB_TOL, against ``reference``) of each block of
    columns ``bounds[k]:bounds[k + 1]``, the one-column blocks (most: a friction, an
    offset) normalised all at once. Why: one call each was a fifth of a selection step."""
    norms, sizes = column_norms(projected), column_norms(reference)
    out: list[np.ndarray | None] = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a > 1:
            out.append(orthonormal_basis(projected[:, a:b], ABSORB_TOL, reference=reference[:, a:b]))
        elif norms[a] == 0.0 or norms[a] <= ABSORB_TOL * (sizes[a] if sizes[a] > 0 else 1.0):
            out.append(np.zeros((projected.shape[0], 0)))
        else:
            out.append(None)
    single = [k for k, basis in enumerate(out) if basis is None]
    if single:
        columns = bounds[single]
        unit = projected[:, columns] / norms[columns]
        for j, k in enumerate(single):
            out[k] = unit[:, j:j + 1]
    return out                                                                   # type: ignore[return-value]


def conditional(first: np.ndarray, given: np.ndarray) -> np.ndarray:
    """The directions of ``first`` beyond ``given`` (both orthonormal, beyond the model)."""
    return orthonormal_basis(project_out(first, given), ABSORB_TOL, reference=first)


def encompassing(a: np.ndarray, b: np.ndarray, residual: np.ndarray, shape: tuple[int, int],
                 dof: int, sparse_if_coloured: bool = False) -> tuple[Test, Test]:
    """Encompassing tests of two sets of directions (orthonormal, beyond the model whose
    ``residual`` and ``dof`` are given): (what a adds over b, what b adds over a), each a
    Wald test on the residual with the other's directions in."""
    return encompassing_each(a, [b], residual, shape, dof, sparse_if_coloured)[0]


def encompassing_each(a: np.ndarray, rivals: Sequence[np.ndarray], residual: np.ndarray, shape: tuple[int, int],
                      dof: int, sparse_if_coloured: bool = False) -> list[tuple[Test, Test]]:
    """:func:`encompassing` of ``a`` with each rival's directions, all tests made at once
    (:func:`wald_each`)."""
    residuals, bases, dofs = [], [], []
    for b in rivals:
        residuals += [residual - b @ (b.T @ residual), residual - a @ (a.T @ residual)]
        bases += [conditional(a, b), conditional(b, a)]
        dofs += [dof + b.shape[1], dof + a.shape[1]]
    tests = wald_each(residuals, bases, shape, dofs, None, [0], sparse_if_white=True,
                      sparse_if_coloured=sparse_if_coloured)
    return [(tests[2 * j], tests[2 * j + 1]) for j in range(len(rivals))]


def correlation(residual: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Correlation of what ``a`` and ``b`` each explain of the residual."""
    fa, fb = a @ (a.T @ residual), b @ (b.T @ residual)
    na, nb = np.linalg.norm(fa), np.linalg.norm(fb)
    return float(fa @ fb / (na * nb)) if na > 0 and nb > 0 else 0.0


def holm(pvalues: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjusted p values (statsmodels' ``multipletests(method="holm")`` gives
    the same, tests/test_diagnose.py checks it, but it runs ``gc.collect()`` on every call,
    which in a process holding sympy costs more than all of a step's tests)."""
    p = np.asarray(pvalues, dtype=float)
    order = np.argsort(p)
    m = len(p)
    stepped = np.maximum.accumulate(np.minimum(p[order] * (m - np.arange(m)), 1.0))
    out = np.empty(m)
    out[order] = stepped
    return out
