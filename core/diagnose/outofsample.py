"""Whether a named effect holds up out of sample: block cross-validation over the whole
recording, the stability of its coefficients from block to block, and its physical
plausibility. Diagnosis names only what passes all three (``docs/diagnosis.md``).

Why blocks: the residual of a filtered recording is correlated over many samples, so
random hold-out rows would leak the fit into the test. Contiguous blocks spread over the
whole recording (not only the last one) each see another part of the motion; ``MARGIN``
samples on each side of a held-out block are dropped from its training rows.

Why the stability test: an effect that stands in for one the catalogue lacks (viscous
friction imitating a torque delay, an offset imitating a smooth friction's shape) fits
each part of the motion with another coefficient, while a real effect has one value for
the whole recording. Each block's coefficient is estimated with the rest of the model held
at the whole-recording fit; their spread is tested (chi-square with HAC variances) and
must also be large (a third of the coefficient) to count, so that a real friction that
drifts a little with temperature is still named.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from baseparams.identify.linear import LinearFit, WeightedLinearModel

FOLDS = 5
MARGIN = 10                 # samples dropped from the training rows beside a held-out block
UNSTABLE = 1.0 / 3.0        # a spread (RMS over blocks of the force's change / the force) counted as real


def blocks(n: int, folds: int = FOLDS) -> list[np.ndarray]:
    """``folds`` contiguous blocks of sample indices covering 0..n-1."""
    return [b for b in np.array_split(np.arange(n), folds) if len(b)]


@dataclass
class CrossValidation:
    """Held-out weighted residuals of each block (in sample order): ``residual`` (n, f),
    unweighted; ``sse`` the weighted sum of squares per block. For a model less some columns,
    ``determined`` per block: whether the other blocks' fit of the whole model predicts the
    left-out columns' part in that block to within the noise (:func:`cross_validate`)."""
    residual: np.ndarray
    sse: np.ndarray
    determined: np.ndarray | None = None

    @property
    def total(self) -> float:
        return float(self.sse.sum())


def held_out_gain(without: CrossValidation, whole: CrossValidation) -> float:
    """How much better ``whole`` predicts a typical held-out block than ``without`` (the model
    less an effect): the geometric mean over blocks of their weighted SSE ratio, minus 1,
    where a block that cannot determine the effect (when at least half the blocks can) does
    not count against it. Why the typical block and not the totals: with few effective
    samples (AR noise) one block extrapolated badly, with the effect or without, decided
    alone (a viscous friction at z 29 'did not predict better', -4 %, while four of five
    blocks improved 6 to 33 times). Why not against it: an effect nearly collinear with the
    model on the rows a block leaves (a pendulum's spring beside gravity, with the block
    holding the motion's only large negative angles out) cannot be predicted there from the
    others, and that block alone held back a spring at z 15. Why still for it: an SLA's
    viscous friction is seen most near the arms' toggle, where the others' fit states a large
    variance and yet predicts the block 13-115 times better; left out, it was too small to
    name. Blocks both predict exactly count as no change."""
    both_exact = (without.sse <= 0) & (whole.sse <= 0)
    ratio = np.where(both_exact, 1.0, np.maximum(without.sse, 1e-300) / np.maximum(whole.sse, 1e-300))
    use = np.ones(len(ratio), dtype=bool)
    if without.determined is not None and 2 * int(without.determined.sum()) >= len(ratio):
        use = without.determined | (ratio >= 1.0)
    return float(np.exp(np.mean(np.log(ratio[use])))) - 1.0


def cross_validate(model: np.ndarray, y: np.ndarray, weights: np.ndarray, folds: int = FOLDS,
                   margin: int = MARGIN, leave_out: Sequence[Sequence[int]] = ()) -> list[CrossValidation]:
    """Block cross-validation of the weighted least-squares fit of ``y`` (n, f) on ``model``
    (n, f, p) with fixed per-coordinate ``weights``: each block predicted from the others.
    The first result is the whole model's; then one for the model without each set of
    columns in ``leave_out``, from the same fit per block (:func:`_without`), with the blocks
    where those columns are ``determined``: the variance they add to the whole model's
    prediction of the block (s^2 tr(X^T X (H_whole - H_smaller)), H the fits' (X_w^T X_w)^+:
    linear regression's prediction variance) is at most one coordinate's noise over the
    block (s^2 times its samples). A real effect's coefficients, fitted on four of five
    blocks, add a fraction of that; one the other blocks cannot pin down adds many times it."""
    n, f, p = model.shape
    sets: list[np.ndarray | None] = [None] + [np.asarray(list(c), dtype=int) for c in leave_out]
    residuals = [np.empty_like(y) for _ in sets]
    sse: list[list[float]] = [[] for _ in sets]
    determined: list[list[bool]] = [[] for _ in sets]
    for block in blocks(n, folds):
        lo, hi = max(block[0] - margin, 0), min(block[-1] + 1 + margin, n)
        train = np.r_[0:lo, hi:n]
        fit = WeightedLinearModel(model[train], y[train]).fit(weights, rank_tol=CV_RANK_TOL) if p else None
        Xb = (model[block] * weights[None, :, None]).reshape(len(block) * f, p)
        gram = Xb.T @ Xb
        whole_H = np.zeros((p, p)) if fit is None else fit.spread @ fit.spread.T
        triangle = _Triangle(model[train], y[train], weights)
        for k, drop in enumerate(sets):
            beta, H = (np.zeros(p), whole_H) if fit is None else _without(fit, whole_H, drop, triangle)
            r = y[block] - model[block] @ beta
            residuals[k][block] = r
            sse[k].append(float(np.sum((r * weights[None, :]) ** 2)))
            if k:
                determined[k].append(float(np.sum(gram * (whole_H - H))) <= len(block))
    return [CrossValidation(r, np.array(e), np.array(d, dtype=bool) if k else None)
            for k, (r, e, d) in enumerate(zip(residuals, sse, determined))]


# directions of the scaled training model below this fraction of the largest are dropped
CV_RANK_TOL = 1e-10


class _Triangle:
    """The weighted training rows X_w (N f, p) and y_w as R and Q^T y_w of X_w = Q R, made on
    first use: a least-squares fit on any subset of the columns is the same fit on R's columns
    (Q is orthonormal: the same singular values, coefficients and spread), at p rows instead of
    N f. Why: a rank-deficient model refitted for every left-out set cost a sixth of
    ``diagnose --params``."""

    def __init__(self, model: np.ndarray, y: np.ndarray, weights: np.ndarray) -> None:
        self.model, self.y, self.weights = model, y, weights
        self._factors: tuple[np.ndarray, np.ndarray] | None = None

    def fit(self, keep: np.ndarray) -> LinearFit:
        """The weighted fit on the columns ``keep`` (its coefficients and spread)."""
        if self._factors is None:
            n, f, p = self.model.shape
            A = (self.model * self.weights[None, :, None]).reshape(n * f, p)
            q, r = np.linalg.qr(A)
            self._factors = (r, q.T @ (self.y * self.weights[None, :]).reshape(n * f))
        r, qty = self._factors
        return WeightedLinearModel(r[:, None, keep], qty[:, None]).fit(np.ones(1), rank_tol=CV_RANK_TOL)


def _without(fit: LinearFit, H: np.ndarray, drop: np.ndarray | None, triangle: _Triangle
             ) -> tuple[np.ndarray, np.ndarray]:
    """The coefficients (p,) of the fit without the columns ``drop`` (zero there) and their
    (X_w^T X_w)^+ (p, p; zero rows and columns there): from the whole fit and its inverse
    normal matrix ``H`` when it has full rank (partitioned inverse: beta_o - H_od H_dd^-1
    beta_d, and the Schur complement H_oo - H_od H_dd^-1 H_do), else by a fit of the others
    (on the training rows' triangle)."""
    beta = fit.coefficients
    if drop is None or not drop.size:
        return beta, H
    p = len(beta)
    keep = np.setdiff1d(np.arange(p), drop)
    out, cov = np.zeros(p), np.zeros((p, p))
    if fit.rank == p:
        step = np.linalg.solve(H[np.ix_(drop, drop)], np.column_stack([beta[drop], H[np.ix_(drop, keep)]]))
        out[keep] = beta[keep] - H[np.ix_(keep, drop)] @ step[:, 0]
        cov[np.ix_(keep, keep)] = H[np.ix_(keep, keep)] - H[np.ix_(keep, drop)] @ step[:, 1:]
    elif keep.size:
        smaller = triangle.fit(keep)
        out[keep] = smaller.coefficients
        cov[np.ix_(keep, keep)] = smaller.spread @ smaller.spread.T
    return out, cov


def block_coefficients(partial: np.ndarray, columns: np.ndarray, weights: np.ndarray, folds: int = FOLDS
                       ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each block's least-squares coefficients of ``columns`` (n, f, c) on the ``partial``
    residual (n, f) (the data minus the rest of the model), and their HAC covariances; blocks
    where the columns barely act are left out (rows of NaN)."""
    n, f, c = columns.shape
    estimates, covariances = [], []
    total = np.sum((columns * weights[None, :, None]) ** 2)
    for block in blocks(n, folds):
        if np.sum((columns[block] * weights[None, :, None]) ** 2) < 1e-3 * total / folds or len(block) < 20:
            estimates.append(np.full(c, np.nan))
            covariances.append(np.full((c, c), np.nan))
            continue
        fit = WeightedLinearModel(columns[block], partial[block]).fit(weights, cov_type="hac_prewhitened")
        estimates.append(fit.coefficients)
        covariances.append(fit.covariance)
    return np.array(estimates), covariances


@dataclass(frozen=True)
class Stability:
    pvalue: float
    spread: float               # RMS over blocks of |X (gamma_k - pooled)| / |X pooled| (X: the columns, weighted)
    blocks: int
    values: list                # per block (None where the effect barely acts)

    def unstable(self, level: float) -> bool:
        return self.pvalue <= level and self.spread > UNSTABLE


def stability(partial: np.ndarray, columns: np.ndarray, weights: np.ndarray, folds: int = FOLDS
              ) -> Stability:
    """Homogeneity of an effect's coefficients over the blocks (see the module docstring)."""
    estimates, covariances = block_coefficients(partial, columns, weights, folds)
    ok = [k for k in range(len(estimates)) if np.all(np.isfinite(estimates[k]))]
    values = [estimates[k].tolist() if k in ok else None for k in range(len(estimates))]
    if len(ok) < 2:
        return Stability(1.0, 0.0, len(ok), values)
    precisions = [np.linalg.pinv(covariances[k]) for k in ok]
    P = sum(precisions)
    pooled = np.linalg.pinv(P) @ sum(Pk @ estimates[k] for Pk, k in zip(precisions, ok))
    q = float(sum((estimates[k] - pooled) @ Pk @ (estimates[k] - pooled) for Pk, k in zip(precisions, ok)))
    c = estimates.shape[1]
    pvalue = float(stats.chi2.sf(q, (len(ok) - 1) * c))
    # the spread in the force the effect exerts over the whole recording (weighted), not in
    # its coefficients: for one coefficient the same ratio; for several (a changed body's ten,
    # in kg, kg m and kg m^2) a block's estimate along a direction the motion barely excites
    # is not a change of the effect
    n, f = columns.shape[:2]
    exerted = (columns * weights[None, :, None]).reshape(n * f, c)
    norm = float(np.linalg.norm(exerted @ pooled))
    spread = float(np.sqrt(np.mean([np.sum((exerted @ (estimates[k] - pooled)) ** 2) for k in ok])) / norm) \
        if norm > 0 else np.inf
    return Stability(pvalue, spread, len(ok), values)
