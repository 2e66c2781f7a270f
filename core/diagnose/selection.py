"""Statistical selection of missing effects: forward steps of Wald tests with a
heteroscedasticity-and-autocorrelation-consistent (HAC) covariance, Holm's correction over
the candidates, and encompassing tests that decide whether the winner is named or reported
as ambiguous with its rivals.

Everything works on the weighted, stacked rows of the model (sample-major: the f
coordinates of sample 1, then of sample 2 ...). Each coordinate's rows are divided by its
noise level estimated from the current model's residual (Gautier's weighting), so a
coordinate with a large torque does not drown the others.

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
- After the forward steps, two backward passes given the complete model (its residual is
  then white): an ambiguous group formed because a comparison inside it could not be made
  (:func:`regroup`) is compared again, and a named effect that no longer clears the bar it
  entered by is taken out (:func:`eliminate`); the forward steps then resume.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import fdtrc
from scipy.optimize import minimize_scalar

from baseparams.identify.longrun import hac_lags, hac_lags_each, local_power, long_run_each, stationary_variance
from baseparams.identify.linear import LinearFit as Fit, Reduced, WeightedLinearModel
from baseparams.identify.weighting import TOLERANCE
from baseparams.numeric.linalg import svd
from baseparams.numeric.rank import numerical_rank

# A candidate direction that keeps less than ABSORB_TOL of its (unit) norm after the
# current model is projected out is absorbed by the model.
ABSORB_TOL = 1e-7
MAX_STEPS = 12
# Rivals are confusable with the winner only when what they explain is this correlated: two
# weak candidates that explain different things, neither adding over the other (on a residual
# with structure left, whitened) are not one ambiguous effect (the TX40 made a group of nine
# with correlations below 0.01).
CONFUSABLE_CORRELATION = 0.5
# Between steps the noise weights move little: refitted until no SD changes by 2 %, not 0.1 %
# (a test statistic moves by as little; half the weighted fits of a diagnosis).
STEP_TOLERANCE = 0.02
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


@dataclass(frozen=True)
class Candidate:
    """An effect on one coordinate: ``columns`` (N, f, c) on the independent coordinates.

    A shaped effect (Coulomb friction's transition speed) carries ``variants``: its columns
    at each value of a grid of shape parameters (``shapes``, one dict each). Selection tests
    the best variant against the current model (variable projection over the grid) and
    counts the fitted shape as one more degree of freedom; once the effect enters the model
    its variant is fixed (:meth:`at`)."""
    kind: str
    coordinate: str
    names: tuple[str, ...]
    columns: np.ndarray
    variants: tuple = ()                       # columns (N, f, c) at each shape of ``shapes``
    shapes: tuple = ()                         # shape parameters of each variant
    shape: dict = field(default_factory=dict)  # the shape of ``columns``
    generalises: tuple = ()                    # kinds this one generalises (Effect.generalises)
    make: Callable | None = field(default=None, compare=False, repr=False)
    # shape -> columns (N, f, c) at any shape value (None: the grid only)

    @property
    def label(self) -> str:
        return f"{self.kind}:{self.coordinate}"

    @property
    def extra_df(self) -> int:
        """Shape parameters fitted by the test (one per shape name, when there is a grid)."""
        return len(self.shapes[0]) if len(self.variants) > 1 else 0

    def at(self, k: int) -> "Candidate":
        """The candidate fixed at its ``k``-th shape."""
        return Candidate(self.kind, self.coordinate, self.names, self.variants[k], (), (), dict(self.shapes[k]),
                         self.generalises, self.make)

    def rows(self, index: slice | np.ndarray) -> "Candidate":
        """The candidate restricted to samples ``index`` (a slice or an index array)."""
        maker = self.make
        make = None if maker is None else (lambda shape: maker(shape)[index])
        return Candidate(self.kind, self.coordinate, self.names, self.columns[index],
                         tuple(v[index] for v in self.variants), self.shapes, self.shape, self.generalises, make)


@dataclass
class Rival:
    """Evidence on a candidate that competes with the winner: both directions of the
    encompassing test and the correlation of what the two explain."""
    index: int
    winner_over_rival: Test
    rival_over_winner: Test
    correlation: float


@dataclass
class Step:
    """One forward step: every candidate's test, the Holm-adjusted p values, the chosen
    candidate (None when nothing is significant) and the rivals it cannot be told from."""
    tests: list[Test]
    adjusted: np.ndarray
    fit: "Fit"                    # the weighted fit of the model this step tests against
    whiten: Callable[[np.ndarray], np.ndarray]   # the filter its fit and tests saw (Whitening or identity)
    chosen: int | None = None
    confusable: list[Rival] = field(default_factory=list)
    beaten: list[Rival] = field(default_factory=list)
    # the most significant candidate, which cleared Holm and opened the step, when a comparison
    # named another in its place (a rival that explains its signal, or a group resolved again),
    # and the test of what the chosen one adds over it (None: nested in it, nothing to test)
    strongest: int | None = None
    over: Test | None = None


@dataclass
class Selection:
    steps: list[Step]
    added: list[int]              # candidate indices, in the order they entered the model
    ambiguous: dict               # added index -> the confusable rivals of that step
    companions: list[int] = field(default_factory=list)   # those rivals: in the model, never named
    removed: list[tuple[int, Test, float]] = field(default_factory=list)
    # named effects taken out again by backward elimination: (index, its test given the
    # others, the bar it failed)
    regrouped: list[tuple[int, int]] = field(default_factory=list)
    # ambiguous groups resolved again once the model was complete: (old head, new winner)
    candidates: list = field(default_factory=list)
    # the candidates as selection left them: shaped ones in the model fixed at their shape
    shaped: dict = field(default_factory=dict)     # shaped ones in the model: index -> every variant
    bars: dict = field(default_factory=dict)       # named index -> the Bonferroni bar it entered by
    resolved: set = field(default_factory=set)     # ambiguous groups already resolved again

    @property
    def in_model(self) -> list[int]:
        """Every candidate in the final model, in the order of its columns after the model's."""
        return self.added + self.companions


# ----- linear algebra --------------------------------------------------------------------
def orthonormal_basis(matrix: np.ndarray, tol: float, reference: np.ndarray | None = None) -> np.ndarray:
    """An orthonormal basis of the range of ``matrix`` (rows, k): directions whose singular
    value exceeds ``tol`` times the norm of the corresponding ``reference`` columns (the
    columns before a projection; default: the largest singular value)."""
    if matrix.shape[1] == 0:
        return np.zeros((matrix.shape[0], 0))
    if matrix.shape[1] == 1:          # one column: its direction (an SVD call costs 10 times more)
        column = matrix[:, 0]
        norm = float(np.linalg.norm(column))
        size = norm if reference is None else float(np.linalg.norm(reference))
        if norm == 0.0 or (reference is not None and norm <= tol * (size if size > 0 else 1.0)):
            return np.zeros((matrix.shape[0], 0))
        return (column / norm)[:, None]
    if reference is not None:
        scale = np.linalg.norm(reference, axis=0)
        scale[scale == 0] = 1.0
        scaled = matrix / scale
        u, s, _ = svd(scaled, full_matrices=False)
        keep = s > tol
    else:
        scale = np.linalg.norm(matrix, axis=0)
        scale[scale == 0] = 1.0
        u, s, _ = svd(matrix / scale, full_matrices=False)
        keep = np.arange(s.size) < numerical_rank(tol=tol, singular_values=s)
    return u[:, keep]


def project_out(matrix: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """matrix minus its projection on the (orthonormal) ``basis``."""
    if basis.shape[1] == 0:
        return matrix
    return matrix - basis @ (basis.T @ matrix)


def support(basis: np.ndarray, shape: tuple[int, int]) -> float:
    """The fewest samples any direction of ``basis`` effectively acts on (participation
    ratio 1 / sum_t w_t^2 of its energy per sample w_t)."""
    return float(support_each(basis[None], shape)[0])


def support_each(bases: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """:func:`support` of each of m bases (m, rows, r) of one width."""
    n, f = shape
    b = bases.reshape(len(bases), n, f, -1)
    w = np.einsum("mtjr,mtjr->mtr", b, b)
    total, squares = w.sum(axis=1), np.einsum("mtr,mtr->mr", w, w)
    return np.where(squares > 0, total ** 2 / np.where(squares > 0, squares, 1.0), np.inf).min(axis=1)


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
    white noise however few samples the directions act on (see :func:`resolve`); and, with
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
            dense = support_each(B, shape) >= max(MIN_SUPPORT * n, 10)
            for i, is_dense in zip(members, dense):
                if not is_dense:
                    tests[i] = (_sparse_test(residual_of(i), bases[i], shape, dof_of(i), lags, sparse_if_coloured)
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
    not tested), scaled by the noise's local power where they act."""
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
    columns = candidate.columns if isinstance(candidate, Candidate) else candidate
    n, f, c = columns.shape
    Z = (columns * fit.weights[None, :, None]).reshape(n * f, c)
    return orthonormal_basis(fit.orthogonal(Z), ABSORB_TOL, reference=Z)


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


# ----- coloured residuals: Prais-Winsten whitening --------------------------------------------
# The largest AR(1) coefficient whitening uses (beyond it the filter is a plain difference).
MAX_RHO = 0.98


@dataclass(frozen=True)
class Whitening:
    """Per-coordinate AR(1) filter x_t - rho x_(t-1) (Prais-Winsten: the first row times
    sqrt(1 - rho^2)), applied alike to the data, the model and the candidates: feasible GLS
    (Cochrane-Orcutt). Why: on residuals correlated over tens of samples (AR(1) noise at 0.9,
    filtered recordings) the tests of candidates orthogonal to a smooth model are liberal
    however their variance is estimated: the fitted model removes the residual's
    low-frequency content, where a low-frequency candidate's own variance lives; HAC tests
    rejected at 16 % (prewhitened HAC 9 %, batch means 14 %) instead of 5 % on the PUMA with
    AR(1) noise at 0.9. The tests after whitening see a nearly white residual."""
    rho: np.ndarray                     # (f,)

    @staticmethod
    def of(residual: np.ndarray) -> "Whitening | None":
        """The filter for a residual (n, f), or None when it is white (HAC window 0)."""
        if len(residual) < 20 or hac_lags(residual) == 0:
            return None
        lag0 = np.sum(residual[:-1] ** 2, axis=0)
        rho = np.sum(residual[1:] * residual[:-1], axis=0) / np.where(lag0 > 0, lag0, 1.0)
        return Whitening(np.clip(rho, 0.0, MAX_RHO))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """x (n, f) or (n, f, c), filtered along the samples."""
        rho = self.rho if x.ndim == 2 else self.rho[:, None]
        out = np.empty_like(x)
        out[1:] = x[1:] - rho * x[:-1]
        out[0] = x[0] * np.sqrt(1.0 - rho ** 2)
        return out

    def candidate(self, cand: Candidate) -> Candidate:
        maker = cand.make
        make = None if maker is None else (lambda shape: self(maker(shape)))
        return Candidate(cand.kind, cand.coordinate, cand.names, self(cand.columns),
                         tuple(self(v) for v in cand.variants), cand.shapes, cand.shape, cand.generalises, make)


def _same(x: np.ndarray) -> np.ndarray:
    return x


# ----- the forward loop ----------------------------------------------------------------------
def select(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], alpha: float = 0.05,
           max_steps: int = MAX_STEPS, whiten: "Whitening | None" = None,
           resume: Selection | None = None) -> Selection:
    """Forward selection: test every candidate against the current model, Holm-correct, add
    the most significant (or, for a confusable group, its strongest member, reported as
    ambiguous), refit and repeat until no candidate is significant. Then backward
    elimination (:func:`eliminate`): a named effect that no longer clears the bar it entered
    by, once the effects named after it are in, is taken out and may not come back, and the
    forward steps resume; until nothing is taken out. The last step always tests the final
    model (its ``fit`` is the final fit, ``chosen`` None unless ``max_steps`` ran out).

    A confusable group enters the working model whole (its strongest member among ``added``,
    the others as ``companions``): with only one member in, what the hidden member adds over
    it, a small but sharp remainder, was chased by further candidates (the SLA, viscous
    friction on the upper arm hidden, named four wrong effects after its group).

    ``whiten``: a filter for coloured noise (:class:`Whitening`, estimated from a complete
    model's residual: :func:`select_whitened`) applied to the data, the model and every
    candidate before each fit and test.

    ``resume``: a selection made with another filter (the first round of
    :func:`select_whitened`), continued from where it stopped: its model is tested again
    under ``whiten``, effects that no longer clear their bar are taken out and missing ones
    added, with the same rules; its steps stay in the history. ``max_steps`` counts the new
    steps only."""
    n, f, _ = model.shape
    filtered: Callable[[np.ndarray], np.ndarray] = whiten or _same
    candidates = list(candidates)             # shaped ones are fixed at their variant on entry
    shaped: dict[int, Candidate] = {}         # ... and their every variant kept here
    added: list[int] = []
    steps: list[Step] = []
    ambiguous: dict = {}
    companions: list[int] = []
    removed: list[tuple[int, Test, float]] = []
    bars: dict[int, float] = {}               # named index -> the Bonferroni bar it entered by
    regrouped: set[int] = set()               # ambiguous groups already resolved again
    regroups: list[tuple[int, int]] = []
    previous = None
    touched: set = set()                      # places where the model changed since the last step
    whitened: dict[int, tuple[Candidate, Candidate]] = {}
    # Coloured noise (whitened data): a direction acting on few samples is tested with the
    # stationary variance, for entry and in comparisons. Why: refused, the truth never
    # entered and a stand-in took its place (a four-bar's gear loss, whitened, acts on 4 % of
    # the samples: Coulomb friction on the other joint was named in 3 of 20 under AR(1) 0.9),
    # and a refused comparison counted as nesting, so Coulomb friction and viscous friction on
    # the other joint ended ambiguous in 9 of 20 although Coulomb added p 1e-173 over it. On
    # white noise a refused comparison waits for the complete model (:func:`regroup`).
    coloured = whiten is not None
    if resume is not None:
        candidates, shaped = list(resume.candidates), dict(resume.shaped)
        added, steps, companions = list(resume.added), list(resume.steps), list(resume.companions)
        ambiguous = {k: list(v) for k, v in resume.ambiguous.items()}
        removed, regroups = list(resume.removed), list(resume.regrouped)
        bars, regrouped = dict(resume.bars), set(resume.resolved)
        touched = {"all"}                     # every shape is chosen again under the new filter
        max_steps = len(steps) + max_steps
    known: KnownFit | None = None             # the last step's fit, which the next complete fit extends
    while len(steps) < max_steps:
        complete = refine_shapes(model, y, candidates, added + companions, shaped, previous, filtered, touched,
                                 known)
        touched = set()
        blocks = [candidates[i].columns for i in added + companions]
        if complete is None and known is not None and previous is not None:
            complete = _extended(known, blocks, model.shape[-1], filtered, previous)
        # the step's fit, at the weights its noise levels move to, refitted from the complete one
        fit = WeightedLinearModel(filtered(np.concatenate([model] + blocks, axis=-1)), filtered(y)).fit(
            start=previous, tolerance=STEP_TOLERANCE if previous is not None else TOLERANCE, near=complete)
        previous, known = fit.weights, (fit, blocks)
        dof = fit.rank
        excluded = set(added) | set(companions) | {i for i, _, _ in removed}
        bases, tests, variant = {}, [], {}
        lags = hac_lags(fit.residual.reshape(n, f))     # one window per step: candidates barely change it
        seen: dict[int, Candidate] = {}
        for i, cand in enumerate(candidates):
            if i in excluded:
                continue
            if whiten is None:
                seen[i] = cand
            else:                                 # whitened once a pass (until its shape changes)
                if i not in whitened or whitened[i][0] is not cand:
                    whitened[i] = (cand, whiten.candidate(cand))
                seen[i] = whitened[i][1]
        forms = dict(zip(seen, candidate_bases(list(seen.values()), fit)))
        # every form of every candidate tested at once; whitened, a step (Coulomb friction)
        # is a few spikes: tested with the classical variance when the whitened residual is
        # white, else with the stationary one
        flat = [basis for i in seen for basis in forms[i]]
        extra = [seen[i].extra_df if seen[i].variants else 0 for i in seen for _ in forms[i]]
        each = wald_each([fit.residual], flat, (n, f), [dof], lags, extra, sparse_if_white=coloured,
                         sparse_if_coloured=coloured)
        form_tests, at = {}, 0
        for i in seen:
            form_tests[i], at = each[at:at + len(forms[i])], at + len(forms[i])
        for i in range(len(candidates)):
            if i not in seen:
                tests.append(NOT_TESTED)
                continue
            bases[i], test, variant[i] = best_variant(seen[i], fit, (n, f), dof, bases=forms[i], tests=form_tests[i])
            tests.append(test)
        tested = [i for i, t in enumerate(tests) if t.tested]
        adjusted = np.ones(len(candidates))
        if tested:
            adjusted[tested] = holm([tests[i].pvalue for i in tested])
        step = Step(tests, adjusted, fit, filtered)
        steps.append(step)
        significant = [i for i in tested if adjusted[i] <= alpha]
        if not significant:
            if len(steps) >= max_steps:    # no step left to test a changed model: this fit is the last
                break
            change = regroup(model, y, candidates, added, companions, ambiguous, bars, fit.weights,
                             alpha, regrouped, filtered)
            if change is not None:
                old, winner, confusable, beaten = change
                regroups.append((old, winner))
                for r in ambiguous.pop(old):
                    companions.remove(r.index)
                added[added.index(old)] = winner
                touched |= {candidates[old].coordinate, candidates[winner].coordinate}
                bars[winner] = bars[old]
                regrouped.add(winner)
                entered = next(s for s in steps if s.chosen == old)
                opened = old if entered.strongest is None else entered.strongest
                entered.chosen, entered.confusable, entered.beaten = winner, confusable, beaten
                entered.strongest, entered.over = (None, None) if winner == opened else (
                    opened, next((r.winner_over_rival for r in beaten if r.index == opened), None))
                if confusable:
                    ambiguous[winner] = confusable
                    companions.extend(r.index for r in confusable)
                continue
            out = eliminate(model, y, candidates, added, companions, ambiguous, bars, fit.weights, filtered,
                            complete=fit)    # this step's fit: the final model at these weights
            if out is None:
                break
            removed.append(out)
            added.remove(out[0])
            touched.add(candidates[out[0]].coordinate)
            continue
        strongest = max(significant, key=lambda i: tests[i].z)
        rivals = [i for i in tested if tests[i].pvalue <= alpha and i != strongest]
        winner, confusable, beaten = resolve(strongest, rivals, bases, fit, (n, f), dof, alpha,
                                             nested_level=alpha / len(tested),
                                             generalises=_generalises(candidates), sparse_if_coloured=coloured)
        step.chosen, step.confusable, step.beaten = winner, confusable, beaten
        if winner != strongest:                   # a rival named for the signal the strongest cleared Holm on
            step.strongest = strongest
            step.over = encompassing(bases[winner], bases[strongest], fit.residual, (n, f), dof, coloured)[0]
        for i in [winner] + [r.index for r in confusable]:
            if candidates[i].variants:            # its shape is chosen again at each step (refine_shapes)
                shaped[i] = candidates[i]
                candidates[i] = candidates[i].at(variant[i])
        added.append(winner)
        touched |= {candidates[i].coordinate for i in [winner] + [r.index for r in confusable]}
        bars[winner] = alpha / len(tested)
        if confusable:
            ambiguous[winner] = confusable
            companions.extend(r.index for r in confusable)
    return Selection(steps, added, ambiguous, companions, removed, regroups, candidates, shaped, bars, regrouped)


# kinds that act on a body, not a coordinate: a kind generalising them may act anywhere
BODY_KINDS = ("mass", "body")


def _generalises(candidates: Sequence[Candidate]) -> Callable[[int, int], bool]:
    """Whether candidate a's kind generalises candidate b's on the same coordinate (or on the
    body b acts on: cogging on a joint imitates the gravity of a mass carried beyond it)."""
    def relation(a: int, b: int) -> bool:
        ca, cb = candidates[a], candidates[b]
        return cb.kind in ca.generalises and (ca.coordinate == cb.coordinate or cb.kind in BODY_KINDS)
    return relation


def simpler_in_place(model: np.ndarray, y: np.ndarray, selection: Selection, held: int,
                     kept: Sequence[int], alpha: float) -> tuple[Step, int] | None:
    """The simpler kinds a held-back effect generalises on its coordinate (cogging: an offset
    or a spring), tested in its place against the model with the ``kept`` effects, under the
    selection's last filter and weights, at the bar ``held`` entered by (Holm over the simpler
    forms): a step choosing the strongest that clears it, or None. Why: with AR(1) noise at
    0.9 a general form's extra directions take a part of the noise's slow swings, win over
    the simpler form that is the truth (cogging over an offset), and then fail the
    out-of-sample checks; without this the truth was lost in 2 of 40 such datasets. The
    step is not in ``selection`` (the caller enters it once its choice holds up)."""
    candidates = selection.candidates
    relation = _generalises(candidates)
    place = candidates[held].coordinate
    simpler = [j for j, cand in enumerate(candidates) if cand.coordinate == place and relation(held, j)
               and j not in selection.in_model and not any(j == i for i, _, _ in selection.removed)]
    if not simpler:
        return None
    last = selection.steps[-1]
    filtered = last.whiten
    n, f, _ = model.shape
    fit, _ = _complete(model, y, candidates, kept, filtered, last.fit.weights)
    tests, variant, bases = [NOT_TESTED] * len(candidates), {}, {}
    for j in simpler:
        seen = filtered.candidate(candidates[j]) if isinstance(filtered, Whitening) else candidates[j]
        bases[j], tests[j], variant[j] = best_variant(seen, fit, (n, f), fit.rank,
                                                      sparse_if_white=isinstance(filtered, Whitening),
                                                      sparse_if_coloured=isinstance(filtered, Whitening))
    tested = [j for j in simpler if tests[j].tested]
    adjusted = np.ones(len(candidates))
    if tested:
        adjusted[tested] = holm([tests[j].pvalue for j in tested])
    bar = selection.bars.get(held, alpha)
    passing = [j for j in tested if adjusted[j] <= bar]
    if not passing:
        return None
    strongest = max(passing, key=lambda j: tests[j].z)
    # among themselves as in a forward step: an offset nested in a spring replaces it unless
    # the spring's slope clears the bar too; forms the data cannot tell apart: none named
    best, confusable, beaten = resolve(strongest, [j for j in passing if j != strongest], bases, fit, (n, f),
                                       fit.rank, alpha, nested_level=bar, generalises=relation)
    if confusable:
        return None
    over = None if best == strongest else next((r.winner_over_rival for r in beaten if r.index == strongest), None)
    return Step(tests, adjusted, fit, filtered, chosen=best, beaten=beaten,
                strongest=None if best == strongest else strongest, over=over), variant[best]


# A fit of the model and some effects' columns (the arrays, in their order), for _complete to extend.
KnownFit = tuple[Fit, list[np.ndarray]]


def _complete(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
              whiten: Callable[[np.ndarray], np.ndarray], weights: np.ndarray,
              known: KnownFit | None = None) -> tuple[Fit, np.ndarray]:
    """The complete model's fit (the model and every effect in ``in_model``, filtered by
    ``whiten``, at ``weights``) and the column offsets of each effect (len(in_model) + 1);
    extended from ``known`` (the same model and data with fewer effects, at these weights)
    when it can be."""
    p = model.shape[-1]
    blocks = [candidates[i].columns for i in in_model]
    offsets = np.cumsum([p] + [b.shape[-1] for b in blocks])
    complete = _extended(known, blocks, p, whiten, weights) if known is not None else None
    if complete is None:
        complete = WeightedLinearModel(whiten(np.concatenate([model] + blocks, axis=-1)), whiten(y)).fit(weights)
    return complete, offsets


def _extended(known: KnownFit, blocks: list[np.ndarray], p: int, whiten: Callable[[np.ndarray], np.ndarray],
              weights: np.ndarray) -> Fit | None:
    """``known``'s fit with the blocks it has that ``blocks`` lacks taken out (a shape changed
    or an effect taken out since: :meth:`LinearFit.subset`), those it lacks added
    (:meth:`LinearFit.extended`), and its columns put in ``blocks``' order; None when it is
    at other weights or rank-deficient."""
    fit, old = known
    if not np.array_equal(fit.weights, weights):
        return None
    position: list[int] = []                  # where each of known's blocks still in use is in ``blocks``
    dropped: list[int] = []                   # known's columns no longer in use
    at = p
    for block in old:
        j = next((j for j, b in enumerate(blocks) if b is block and j not in position), None)
        if j is None:
            dropped += range(at, at + block.shape[-1])
        else:
            position.append(j)
        at += block.shape[-1]
    if dropped:
        kept = fit.subset([c for c in range(at) if c not in set(dropped)])
        if kept is None:
            return None
        fit = kept
    new = [j for j in range(len(blocks)) if j not in position]
    if new:
        n, f, _ = blocks[new[0]].shape
        columns = whiten(np.concatenate([blocks[j] for j in new], axis=-1)) * weights[None, :, None]
        grown = fit.extended(columns.reshape(n * f, -1))
        if grown is None:
            return None
    else:
        grown = fit                               # the same columns (a step that added nothing)
    start, at = {}, p                          # each block's first column in the grown fit
    for j in position + new:
        start[j], at = at, at + blocks[j].shape[-1]
    return grown.reordered(list(range(p)) + [start[j] + c for j in range(len(blocks))
                                             for c in range(blocks[j].shape[-1])])


def _left_out(complete: Fit, offsets: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int], i: int,
              whiten: Callable[[np.ndarray], np.ndarray]) -> tuple[Fit | Reduced, np.ndarray] | None:
    """The complete fit with effect ``i`` left out (Frisch-Waugh-Lovell) and i's directions
    beyond it; None when that needs a refit or i has no direction of its own."""
    k = list(in_model).index(i)
    fit = complete.without(range(offsets[k], offsets[k + 1]))
    if fit is None:
        return None
    own = candidate_basis(whiten(candidates[i].columns), fit)
    return (fit, own) if own.shape[1] else None


def outdone(model: np.ndarray, y: np.ndarray, selection: Selection, in_model: Sequence[int],
            rivals: dict[int, Candidate], level: float) -> dict[int, tuple[Test, Test]]:
    """Named effects (keys of ``rivals``, in ``in_model``) that their rival outdoes: given every
    other effect in ``in_model``, the rival adds significantly (at ``level``) over the effect
    and the effect adds nothing over the rival; each with (the rival's test over it, its test
    over the rival). Under the selection's last filter and weights, from one fit of the
    complete model (each effect left out by Frisch-Waugh-Lovell). Why: rivals that are not
    candidates (one drive's own delay) still show what a named effect may stand in for."""
    last = selection.steps[-1]
    filtered = last.whiten                  # the identity when the noise was white
    n, f, p = model.shape
    candidates = selection.candidates
    complete, offsets = _complete(model, y, candidates, in_model, filtered, last.fit.weights)
    out = {}
    for i, rival in rivals.items():
        found = _left_out(complete, offsets, candidates, in_model, i, filtered)
        if found is None:
            continue
        fit, own = found
        other = candidate_basis(filtered(rival.columns), fit)
        if other.shape[1] == 0:
            continue
        over_other, over_own = encompassing(own, other, fit.residual, (n, f), fit.rank)
        rival_adds = over_own.tested and over_own.pvalue <= level
        own_adds = over_other.tested and over_other.pvalue <= level
        if rival_adds and not own_adds:
            out[i] = (over_own, over_other)
    return out


def weakest_over(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
                 i: int, rivals: Sequence[np.ndarray], whiten: Callable[[np.ndarray], np.ndarray],
                 weights: np.ndarray, scale: tuple[float, float]) -> tuple[Test, int] | None:
    """What candidate ``i`` (in ``in_model``) adds over each rival (n, f) whose fitted
    coefficient lies in ``scale`` (given every other effect in ``in_model``, ``i`` left out):
    the weakest of those tests (largest p) and its rival's index; None when no rival is in
    scale or ``i`` has no direction of its own. Why: a named effect that some member of a
    physical family (a resonant lag over its grid) explains as well cannot be told from that
    family on these data; the scale keeps the member physical (a third of a resonance, which
    is no elastic joint, imitated a first-order filter's lag)."""
    if not rivals:
        return None
    n, f, p = model.shape
    found = _left_out(*_complete(model, y, candidates, in_model, whiten, weights), candidates, in_model, i, whiten)
    if found is None:
        return None
    fit, own = found
    Z = np.stack([(whiten(rival) * fit.weights[None, :]).reshape(n * f) for rival in rivals], axis=1)
    beyond = fit.orthogonal(Z)                       # every rival projected off the model at once
    size = np.einsum("xr,xr->r", beyond, beyond)
    fitted = (beyond.T @ fit.residual) / np.where(size > 0, size, 1.0)
    in_scale = [r for r in range(len(rivals)) if size[r] > 0 and scale[0] <= fitted[r] <= scale[1]]
    others = {r: orthonormal_basis(beyond[:, r:r + 1], ABSORB_TOL, reference=Z[:, r:r + 1]) for r in in_scale}
    others = {r: b for r, b in others.items() if b.shape[1]}
    weakest: tuple[Test, int] | None = None
    pairs = encompassing_each(own, list(others.values()), fit.residual, (n, f), fit.rank)
    for r, (over, _) in zip(others, pairs):
        if not over.tested:              # no test to make: the rival is the candidate on these data
            continue
        if weakest is None or over.z < weakest[0].z:
            weakest = (over, r)
    return weakest


def added_test(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
               i: int, whiten: Callable[[np.ndarray], np.ndarray], weights: np.ndarray,
               sparse: bool = False) -> Test | None:
    """The Wald test of candidate ``i`` added to the model and the effects ``in_model`` (i not
    among them), filtered by ``whiten`` at ``weights``; None when i has no direction of its
    own there or the fit needs a refit. Why: an effect found significant at its step, then
    held back, may explain nothing the final model leaves (it stood in for one named later).
    ``sparse``: directions acting on few samples are tested too (:func:`_sparse_test`)."""
    n, f, _ = model.shape
    found = _left_out(*_complete(model, y, candidates, [*in_model, i], whiten, weights), candidates,
                      [*in_model, i], i, whiten)
    if found is None:
        return None
    fit, own = found
    return wald(fit.residual, own, (n, f), fit.rank, sparse_if_white=sparse, sparse_if_coloured=sparse)


# A selection is repeated when the complete model's residual asks for a filter differing from
# the one it ran with by more than this (in any coordinate's AR(1) coefficient).
RHO_AGREEMENT = 0.01


def select_whitened(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], alpha: float = 0.05,
                    max_steps: int = MAX_STEPS) -> Selection:
    """:func:`select` on data, model and candidates whitened (feasible GLS, :class:`Whitening`)
    when the noise is coloured. The first AR(1) filter comes from the residual of the model
    plus every candidate at once: the model alone would leave the missing effects in its
    residual (an AR(1) coefficient near 1, a plain difference that hides a step-like effect
    among a few spikes). That residual is overfitted, its coefficient a little low (0.86 for
    0.90 on the PUMA, which made the tests liberal), so the filter is estimated again from the
    selected model's residual and the selection repeated with it when the two differ
    (Cochrane-Orcutt, one more round)."""
    n, f = y.shape
    complete = WeightedLinearModel(np.concatenate([model] + [c.columns for c in candidates], axis=-1), y).fit()
    whiten = Whitening.of(complete.unweighted_residual())
    chosen = select(model, y, candidates, alpha, max_steps, whiten)
    final = np.concatenate([model] + [chosen.candidates[i].columns for i in chosen.in_model], axis=-1)
    fit = WeightedLinearModel(final, y).fit(chosen.steps[-1].fit.weights)
    again = Whitening.of(fit.unweighted_residual())
    before = whiten.rho if whiten is not None else np.zeros(f)
    after = again.rho if again is not None else np.zeros(f)
    if np.max(np.abs(after - before)) <= RHO_AGREEMENT:
        return chosen
    return select(model, y, candidates, alpha, max_steps, again, resume=chosen)


def refine_shapes(model: np.ndarray, y: np.ndarray, candidates: list[Candidate], in_model: list[int],
                  shaped: dict, weights: np.ndarray | None, whiten: Callable = _same,
                  touched: set | None = None, known: KnownFit | None = None) -> Fit | None:
    """Variable projection for the shaped effects in the model: each one's shape is chosen
    again given everything else in the model (the variant that leaves the smallest weighted
    residual), in place. Why: a shape chosen while other effects were still missing fits
    those too (Coulomb friction took a smooth shape, then a Stribeck bump made up the
    difference). ``touched``: the places where the model changed since the last call (a shape
    is chosen again only where something changed beside it; None: everywhere). ``known``: a
    fit at ``weights`` with fewer effects (the last step's) that the complete fit extends.
    Returns the complete fit with the shapes as left, when one was made, else None."""
    complete: Fit | None = None
    whole: Fit | None = None                  # without weights: the whole model at its own, once
    whole_columns: list[np.ndarray] = []
    for i in in_model:
        if i not in shaped or (touched is not None and candidates[i].coordinate not in touched
                               and "all" not in touched):
            continue
        # the model without i: at given weights from the model with everything (Frisch-Waugh-
        # Lovell: one factorisation for all), else a refit
        fit: Fit | Reduced | None = None
        if weights is not None:
            if complete is None:
                complete, _ = _complete(model, y, candidates, in_model, whiten, weights, known)
                known = (complete, [candidates[j].columns for j in in_model])
            start = model.shape[-1] + sum(candidates[j].columns.shape[-1] for j in in_model[:in_model.index(i)])
            fit = complete.without(range(start, start + candidates[i].columns.shape[-1]))
        if fit is None:
            others = [j for j in in_model if j != i]
            near = None
            if weights is None:           # at its own weights: refitted from the whole model's factors
                if whole is None:
                    whole = WeightedLinearModel(whiten(np.concatenate(
                        [model] + [candidates[j].columns for j in in_model], axis=-1)), whiten(y)).fit()
                    whole_columns = [candidates[j].columns for j in in_model]
                widths = [c.shape[-1] for c in whole_columns]
                if all(candidates[j].columns is c for j, c in zip(in_model, whole_columns)):
                    first = model.shape[-1] + sum(widths[:in_model.index(i)])
                    drop = set(range(first, first + widths[in_model.index(i)]))
                    near = whole.subset([c for c in range(len(whole.coefficients)) if c not in drop])
            fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others],
                                                            axis=-1)), whiten(y)).fit(weights, near=near)

        def explained(columns: np.ndarray) -> float:
            basis = candidate_basis(whiten(columns), fit)
            return float(np.sum((basis.T @ fit.residual) ** 2))

        gains = [float(np.sum((basis.T @ fit.residual) ** 2))
                 for basis in column_bases([whiten(columns) for columns in shaped[i].variants], fit)]
        best = int(np.argmax(gains))
        before = candidates[i]
        candidates[i] = _between(shaped[i], best, explained) or shaped[i].at(best)
        if candidates[i].columns is not before.columns:
            complete = None                   # i's columns changed: the next one needs a new complete fit
    return complete


# Shape values between grid points are searched on logarithms rounded to this step (2.5 %): the
# columns of a value met again (the next step's search) are made once (candidates._maker).
SHAPE_STEP = 0.025


def _between(cand: Candidate, k: int, explained: Callable[[np.ndarray], float]) -> Candidate | None:
    """The candidate at the shape value between grid points k - 1 and k + 1 that explains the
    most (bounded search on its logarithm), when it has one shape, a column maker and a
    positive value there; else None. Why: between grid points the misfit of the shape was
    larger than the noise, and a Stribeck bump was named to make up the difference."""
    if cand.make is None or len(cand.shapes[k]) != 1:
        return None
    (name, value), = cand.shapes[k].items()
    values = [next(iter(s.values())) for s in cand.shapes]
    if value <= 0:
        return None
    low = values[k - 1] if k > 0 and values[k - 1] > 0 else value / 2
    high = values[k + 1] if k + 1 < len(values) else value * 2
    made: dict[float, np.ndarray] = {}          # each shape's columns, made once (a filtering each)
    maker = cand.make

    def snapped(x: float) -> float:
        return round(x / SHAPE_STEP) * SHAPE_STEP

    def columns(x: float) -> np.ndarray:
        x = snapped(x)
        if x not in made:
            made[x] = maker({name: float(np.exp(x))})
        return made[x]

    # to 5 % of the value: grid points are 3 times apart, and the fit is flat near its best
    found = minimize_scalar(lambda x: -explained(columns(x)), bounds=(np.log(low), np.log(high)),
                            method="bounded", options={"xatol": 0.05})
    shape = {name: float(np.exp(snapped(found.x)))}
    return Candidate(cand.kind, cand.coordinate, cand.names, columns(found.x), (), (), shape, cand.generalises)


def candidate_bases(candidates: Sequence[Candidate], fit: "Fit | Reduced") -> list[list[np.ndarray]]:
    """:func:`candidate_basis` of every form of each candidate (its one form, or each
    variant), the projection off the model done for all at once (two matrix products
    instead of one pair per form: most of a step's cost on a robot's many candidates)."""
    forms = [list(c.variants) if c.variants else [c.columns] for c in candidates]
    bases = column_bases([columns for each in forms for columns in each], fit)
    out, at = [], 0
    for each in forms:
        out.append(bases[at:at + len(each)])
        at += len(each)
    return out


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
        Z = np.concatenate([(c * fit.weights[None, :, None]).reshape(n * f, -1) for c in arrays[first:last]], axis=1)
        projected = fit.orthogonal(Z)
        bounds = np.cumsum([0] + [c.shape[-1] for c in arrays[first:last]])
        bases += [orthonormal_basis(projected[:, a:b], ABSORB_TOL, reference=Z[:, a:b])
                  for a, b in zip(bounds[:-1], bounds[1:])]
        first = last
    return bases


def best_variant(cand: Candidate, fit: "Fit", shape: tuple[int, int], dof: int, sparse_if_white: bool = False,
                 lags: int | None = None, sparse_if_coloured: bool = False,
                 bases: list[np.ndarray] | None = None,
                 tests: list[Test] | None = None) -> tuple[np.ndarray, Test, int]:
    """(basis, test, variant index) of the candidate's best shape against ``fit`` (the
    largest normal-equivalent statistic; the one form of an unshaped candidate); ``bases``:
    each form's :func:`candidate_basis`, when already made (:func:`candidate_bases`);
    ``tests``: each form's Wald test, when already made (:func:`wald_each`)."""
    forms = list(cand.variants) if cand.variants else [cand.columns]
    if bases is None:
        bases = [candidate_basis(columns, fit) for columns in forms]
    if tests is None:
        extra = cand.extra_df if cand.variants else 0
        tests = [wald(fit.residual, basis, shape, dof, lags=lags, extra_df=extra, sparse_if_white=sparse_if_white,
                      sparse_if_coloured=sparse_if_coloured) for basis in bases]
    if not cand.variants:
        return bases[0], tests[0], -1
    best = 0
    for k in range(1, len(tests)):
        if tests[k].z > tests[best].z:
            best = k
    return bases[best], tests[best], best


def regroup(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], added: list[int],
            companions: list[int], ambiguous: dict, bars: dict, weights: np.ndarray, alpha: float,
            done: set[int], whiten: Callable = _same) -> tuple[int, int, list[Rival], list[Rival]] | None:
    """An ambiguous group formed while a comparison inside it could not be made, resolved
    again given the rest of the final model: (the group's old strongest member, the new
    winner, its confusable rivals, the beaten ones) when the group changes, else None.

    When the difference of two rivals acts on few samples (viscous friction on the SLA's
    upper arm against the same on the lower arm: they differ only near the arms' toggle
    position), only the classical variance can test it, and only on a white residual; at the
    step the group formed, other hidden effects were still in the residual, the comparison
    was refused ('support') and the two were reported ambiguous although one is 2,500 times
    as likely. Once the model is complete the residual is white and the comparison can be
    made. (On whitened data the comparison is made at once with the stationary variance:
    there the residual's colour is the noise's, and waiting for a white one would wait for
    ever.) Groups formed with every comparison made are left as they are: the data did not
    separate them, and a second look with the same data would only add chances of a wrong
    name."""
    n, f, _ = model.shape
    for head, rivals in list(ambiguous.items()):
        if head in done:
            continue
        done.add(head)
        if not any("support" in (r.winner_over_rival.reason, r.rival_over_winner.reason) for r in rivals):
            continue
        members = [head] + [r.index for r in rivals]
        others = [j for j in added + companions if j not in members]
        fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others], axis=-1)),
                                  whiten(y)).fit(weights)
        bases = {i: candidate_basis(whiten(candidates[i].columns), fit) for i in members}
        if any(b.shape[1] == 0 for b in bases.values()):
            continue
        winner, confusable, beaten = resolve(head, members[1:], bases, fit, (n, f), fit.rank, alpha,
                                             nested_level=bars[head], generalises=_generalises(candidates))
        if winner == head and {r.index for r in confusable} == set(members[1:]):
            continue
        return head, winner, confusable, beaten
    return None


def eliminate(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], added: list[int],
              companions: list[int], ambiguous: dict, bars: dict, weights: np.ndarray,
              whiten: Callable = _same, complete: Fit | None = None) -> tuple[int, Test, float] | None:
    """Backward elimination, one effect at a time: each named effect (not an ambiguous
    group: those are not named) is tested beyond everything else in the final model, at the
    Bonferroni bar alpha / m it cleared to enter (the most significant of m candidates under
    Holm). The one furthest above its bar (largest p / bar) is returned when it fails, else
    None; one with nothing left beyond the others ('absorbed') fails, one whose remainder is
    too sparse to test (a Stribeck bump beside Coulomb friction on a coloured residual) is
    kept: untestable is not evidence of absence. Why: forward selection names a candidate
    that imitates two hidden effects at once
    (on the SLA, Coulomb friction on the hub imitating viscous friction on the hub plus
    Coulomb friction on a damper joint); once those are in, it adds nothing, and naming it
    is a wrong name. The noise weights are the final model's (one weighted fit per test);
    ``complete``: the final model's fit at them, when made (the last step's)."""
    named = [i for i in added if i not in ambiguous]
    if not named:
        return None
    n, f, p = model.shape
    in_model = added + companions
    if complete is None:
        complete = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in in_model],
                                                             axis=-1)), whiten(y)).fit(weights)
    offsets = np.cumsum([p] + [candidates[j].columns.shape[-1] for j in in_model])
    worst = None
    for i in named:
        k = in_model.index(i)
        fit: Fit | Reduced | None = complete.without(range(offsets[k], offsets[k + 1]))
        if fit is None:                      # the complete model is rank deficient: refit without i
            others = [j for j in in_model if j != i]
            fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others],
                                                            axis=-1)), whiten(y)).fit(weights)
        basis = candidate_basis(whiten(candidates[i].columns), fit)
        test = wald(fit.residual, basis, (n, f), fit.rank, sparse_if_white=True)
        if not test.tested and test.reason != "absorbed":
            continue                         # too sparse to test on this residual: no evidence to take it out
        score = test.pvalue / bars[i]
        if score > 1.0 and (worst is None or score > worst[0]):
            worst = (score, i, test)
    return None if worst is None else (worst[1], worst[2], bars[worst[1]])


def _verdict(winner_adds: bool, rival_adds: bool) -> str | None:
    """Encompassing: 'beaten' (only the winner adds over the other), 'switch' (only the
    rival does), 'confusable' (neither), None (both)."""
    if winner_adds != rival_adds:
        return "beaten" if winner_adds else "switch"
    return None if winner_adds else "confusable"


def resolve(winner: int, rivals: list[int], bases: dict, fit: Fit, shape: tuple[int, int], dof: int,
            alpha: float, nested_level: float | None = None,
            generalises: Callable[[int, int], bool] | None = None,
            sparse_if_coloured: bool = False) -> tuple[int, list[Rival], list[Rival]]:
    """Compare the winner with each rival by encompassing tests (does each add significantly
    to the other?). A rival nested in the winner (an offset inside a spring on the same
    independent coordinate) replaces it unless the winner's extra directions are significant
    at ``nested_level`` (default ``alpha``; ``select`` passes Bonferroni's alpha / m, the bar
    the most significant of m candidates clears to enter the model under Holm): those extra
    directions are a further effect and must clear the same bar as any other, or the larger
    effect would be named whenever its extra directions fluctuate past alpha (an offset named
    a spring in 12-15 % of datasets at alpha = 0.05, benchmarks/bench_diagnose.py, where
    low-frequency directions make the HAC test somewhat liberal). A rival that adds over the winner
    while the winner adds nothing over it replaces the winner. Rivals over which the winner
    adds nothing, and that add nothing over the winner, are confusable with it: the data
    cannot tell them apart. When each adds over the other at alpha, both are effects only if
    each clears ``nested_level`` too (the same argument: the second is a further effect);
    otherwise the one that clears it wins, and if neither does they are confusable. (Before,
    'both add' named the winner and let the rival compete at the next step, where it failed
    Holm's bar: the slider-crank's crank offset was named for a hidden coupler offset, cos
    0.9999, in 3 of 40 datasets.) Differences acting on few samples are tested with the
    classical variance when the residual is white (``wald(..., sparse_if_white=True)``), and
    with ``sparse_if_coloured`` with the stationary variance when it is not."""
    nested_level = alpha if nested_level is None else nested_level
    seen = {winner}
    rivals = [winner] + list(rivals)       # after a switch the first winner is a rival too
    while True:
        A = bases[winner]
        confusable: list[Rival] = []
        beaten: list[Rival] = []
        switch: list[Rival] = []
        others = [j for j in rivals if j != winner]
        pairs = encompassing_each(A, [bases[j] for j in others], fit.residual, shape, dof, sparse_if_coloured)
        for j, (t_ab, t_ba) in zip(others, pairs):
            rival = Rival(j, t_ab, t_ba, correlation(fit.residual, A, bases[j]))
            a_adds = t_ab.tested and t_ab.pvalue <= alpha
            b_adds = t_ba.tested and t_ba.pvalue <= alpha
            if not t_ba.tested:                 # rival nested in the winner
                (beaten if t_ab.tested and t_ab.pvalue <= nested_level else switch).append(rival)
            elif not t_ab.tested:               # winner nested in the rival
                (switch if t_ba.pvalue <= nested_level else beaten).append(rival)
            else:
                # who adds over whom at alpha decides; when both do, two distinct effects only
                # if each adds at the bar of a further effect (nested_level), else one of them
                # is a fluke of alpha; both at that bar: the rival competes again next step
                verdict = _verdict(a_adds, b_adds) or _verdict(t_ab.pvalue <= nested_level,
                                                               t_ba.pvalue <= nested_level)
                if verdict == "confusable" and abs(rival.correlation) < CONFUSABLE_CORRELATION:
                    verdict = None      # unrelated, each too weak to add over the other: it competes again
                if verdict == "confusable" and generalises is not None:
                    # a kind that generalises the other (cogging's harmonics an offset over a small
                    # range) is not named for what the simpler kind explains as well
                    verdict = ("beaten" if generalises(j, winner) else
                               "switch" if generalises(winner, j) else verdict)
                if verdict is not None:
                    {"beaten": beaten, "switch": switch, "confusable": confusable}[verdict].append(rival)
        fresh = [r for r in switch if r.index not in seen]
        if not fresh:
            confusable += [r for r in switch if r.index in seen]
            return winner, confusable, beaten
        # the simplest (fewest directions), then the strongest rival that explains the winner's signal
        best = min(fresh, key=lambda r: (bases[r.index].shape[1], -r.rival_over_winner.z))
        winner = best.index
        seen.add(winner)
