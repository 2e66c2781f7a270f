"""The one weighted linear model of identification and diagnosis (statsmodels' model/results
split): :class:`WeightedLinearModel` holds the measured forces y (N, f) and the model's
columns (N, f, p); :meth:`WeightedLinearModel.fit` factors the weighted, column-scaled matrix
once (an SVD) and returns a :class:`LinearFit` from which everything else is derived lazily:
minimum-norm coefficients, the weighted range's orthonormal basis, the residual, the
covariance, standard errors, prediction variance and the condition number.

Why these choices:

- Rows are sample-major (the f coordinates of sample 1, then of sample 2 ...), each
  coordinate's rows divided by its noise level (Gautier's weighting, :mod:`.weighting`, at
  its fixed point when no weights are given), so a coordinate with large forces does not
  drown the others.
- One covariance convention: s^2 (X_w^T X_w)^+ with s^2 the weighted residual's sum of
  squares over its degrees of freedom (rows minus rank). At the weighting's fixed point
  s^2 = 1 exactly (each coordinate's SD divides its sum of squares by its own degrees of
  freedom), so the diagnosis's unit-variance spread and identify's classical covariance are
  the same number there. ``cov_type="hac"`` gives the Driscoll-Kraay Newey-West sandwich
  (scores summed per sample over the coordinates, Bartlett window from the residual's own
  autocorrelation), for filtered, decimated recordings whose rows are correlated;
  ``"hac_prewhitened"`` the same after Andrews and Monahan's VAR(1) prewhitening
  (:func:`.longrun.long_run`).
- The SVD of the unit-norm columns decides the rank (:func:`baseparams.numeric.rank.numerical_rank`
  at :data:`RANK_TOL` of the largest singular value by default): structural zeros of a regressor sit near 1e-15 in float64, and a
  direction kept at that level would put noise into the coefficients.
- Every SVD here is :func:`baseparams.numeric.linalg.svd`: numpy's (LAPACK gesdd), and the QR
  iteration (gesvd) where gesdd fails to converge, as it does for particular bits of such
  rank-deficient matrices (a real Kinova Gen3 recording's cross-validation fit); the fit of
  the N f rows goes through :func:`~baseparams.numeric.linalg.thin_svd` (Cholesky QR when
  the scaled columns are well conditioned, Householder QR and the SVD of its R otherwise).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
from scipy.linalg import solve_triangular

from baseparams.identify.longrun import hac_lags, long_run
from baseparams.identify.weighting import PASSES, TOLERANCE, coordinate_statistics, fixed_point, noise_levels
from baseparams.numeric.linalg import svd, thin_svd
from baseparams.numeric.rank import numerical_rank

# A model direction is kept when its singular value, columns scaled to unit norm, exceeds
# RANK_TOL times the largest (structural zeros of K sit near 1e-15 in float64).
RANK_TOL = 1e-6
# LinearFit.reweighted refactors only when the largest weight ratio is within this factor of
# the smallest (Cholesky QR's orthogonality error grows as its square times the rounding).
RESCALE_LIMIT = 4.0
# A null direction of a rank-deficient fit involves a column when its component there exceeds this
# (unit-norm directions; an exact deficiency elsewhere leaves rounding, about 1e-15).
NULL_INVOLVEMENT = 1e-9

CovType = Literal["nonrobust", "hac", "hac_prewhitened"]


@dataclass(frozen=True)
class LinearFit:
    """A weighted least-squares fit. The SVD factors are kept so that every statistic is
    derived from the one factorisation, and only when asked for."""
    weights: np.ndarray            # (f,): 1 / noise level per coordinate
    samples: int                   # N
    scale: np.ndarray              # (p,): norms of the weighted columns (1 for a zero column)
    singular_values: np.ndarray    # (min(N f, p),): all of them, largest first
    right: np.ndarray              # (min(N f, p), p): right singular vectors (scaled columns)
    basis: np.ndarray              # (N f, rank): orthonormal basis of the weighted model's range
    residual: np.ndarray           # (N f,): weighted residual
    coefficients: np.ndarray       # (p,): minimum-norm solution
    rank: int
    projection: np.ndarray         # (rank,): the weighted measurements' coordinates on ``basis``
    cov_type: CovType = "nonrobust"
    _columns: np.ndarray | None = field(default=None, repr=False)   # weighted (N f, p), for HAC

    @property
    def coordinates(self) -> int:
        return len(self.weights)

    @property
    def dof(self) -> int:
        """Residual degrees of freedom: rows minus the directions fitted."""
        return self.samples * self.coordinates - self.rank

    @cached_property
    def scale_variance(self) -> float:
        """s^2: the weighted residual's sum of squares over :attr:`dof` (1 at the weighting's
        fixed point)."""
        return float(self.residual @ self.residual) / max(self.dof, 1)

    @cached_property
    def spread(self) -> np.ndarray:
        """(p, rank) with (X_w^T X_w)^+ = spread spread^T: the coefficients' covariance for
        unit-variance weighted rows."""
        s, vt = self.singular_values[: self.rank], self.right[: self.rank]
        return (vt.T / s) / self.scale[:, None]

    @cached_property
    def covariance(self) -> np.ndarray:
        """Cov(coefficients): s^2 (X_w^T X_w)^+, or the HAC sandwich (``cov_type="hac"``)."""
        bread = self.spread @ self.spread.T
        if self.cov_type == "nonrobust":
            return self.scale_variance * bread
        n, f = self.samples, self.coordinates
        p = len(self.coefficients)
        assert self._columns is not None
        scores = (self._columns * self.residual[:, None]).reshape(n, f, p).sum(axis=1)
        lags = hac_lags(self.residual.reshape(n, f))
        # "hac" is not prewhitened: on filtered recordings the VAR(1) prewhitening overstated
        # the spread 1.6 times (tests/test_recordings.py); "hac_prewhitened" is for short
        # blocks of strongly coloured residuals (the stability test), where the plain window
        # understates it; scaled for the unknowns fitted
        middle = long_run(scores, lags, prewhiten=self.cov_type == "hac_prewhitened") * (n * f) / max(self.dof, 1)
        return bread @ middle @ bread

    @property
    def std(self) -> np.ndarray:
        """Standard errors of the coefficients."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))

    @property
    def condition_number(self) -> float:
        """Of the weighted matrix with unit-norm columns (all its singular values)."""
        s = self.singular_values
        return float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")

    def null_direction(self) -> np.ndarray:
        """The unit-norm column combination (p,) with the smallest singular value: which
        columns a rank deficiency involves."""
        return self.right[-1]

    def orthogonal(self, columns: np.ndarray) -> np.ndarray:
        """``columns`` (N f, k), weighted rows, less their projection on the model's range."""
        return columns - self.basis @ (self.basis.T @ columns)

    def without(self, columns: Sequence[int]) -> Reduced | None:
        """The fit of the model with ``columns`` left out, at the same weights, from this
        fit's factorisation (Frisch-Waugh-Lovell): the left-out columns' part orthogonal to
        the others is spanned by A (A^T A)^-1 E = U S^-1 V^T E, so the smaller model's range is
        this one's less that span. A rank-deficient fit works the same when no null direction
        involves the left-out columns (the deficiency lies among the others: each left-out
        column is then in the row space, and A (A^T A)^+ E is orthogonal to the others'
        range); None when one does (they share directions with the others: refit). Why: on
        a recording an ambiguous group's members or the model's own collinear columns made
        every backward test a refit (68 SVD fits of the TX40's rows, 1.2 of its 9 CPU s)."""
        cols = list(columns)
        if not cols:
            return None
        if self.rank < len(self.coefficients) and np.max(np.abs(self.right[self.rank:, cols])) > NULL_INVOLVEMENT:
            return None
        dual = self.right[:self.rank, cols] / self.singular_values[:self.rank, None]   # (r, k) in U's coordinates
        removed, _ = np.linalg.qr(dual)
        leaving = self.basis @ removed
        residual = self.residual + leaving @ (leaving.T @ self.weighted_target())
        return Reduced(self.weights, self.samples, self.rank - removed.shape[1], residual, self.basis, leaving)

    def _in_basis(self) -> np.ndarray:
        """The weighted columns in the basis' coordinates, S V^T D (p x p): A = U S V^T D for a
        full-rank fit, so every update below factors only this."""
        p = len(self.coefficients)
        return (self.singular_values[:p, None] * self.right[:p]) * self.scale

    def extended(self, columns: np.ndarray, rank_tol: float = RANK_TOL) -> LinearFit | None:
        """This fit with the weighted ``columns`` (N f, k) appended, at the same weights, from
        this fit's factors (an SVD update): [A C] = [U Q] [[S V^T D, U^T C], [0, R]] with
        Q R the QR factors of C's part beyond the range, so only the small (p + k) square core
        is factored again. Why: a selection step first fits the previous step's model with
        the new effect at the previous weights, and an SVD of the N f rows costs ten times
        this. None when this fit is rank-deficient (the directions it dropped are not kept),
        not "nonrobust", or the rows are too few."""
        n_rows, p = self.basis.shape[0], len(self.coefficients)
        k = columns.shape[1]
        if self.rank < p or self.cov_type != "nonrobust" or n_rows < p + k:
            return None
        U = self.basis
        inside = U.T @ columns
        beyond = columns - U @ inside
        again = U.T @ beyond                      # once more: orthogonal to working precision
        inside, beyond = inside + again, beyond - U @ again
        Q, R = np.linalg.qr(beyond)
        scale = np.concatenate([self.scale, np.linalg.norm(columns, axis=0)])
        scale[p:][scale[p:] == 0] = 1.0
        core = np.zeros((p + k, p + k))
        core[:p, :p] = self._in_basis()
        core[:p, p:], core[p:, p:] = inside, R
        um, s, vt = svd(core / scale, full_matrices=False)
        rank = numerical_rank(tol=rank_tol, singular_values=s)
        target = np.concatenate([self.projection, Q.T @ self.residual])   # [U Q]^T b
        proj = um[:, :rank].T @ target
        coefficients = (vt[:rank].T @ (proj / s[:rank])) / scale
        basis = U @ um[:p, :rank] + Q @ um[p:, :rank]
        residual = self.residual + U @ self.projection - basis @ proj
        return LinearFit(self.weights, self.samples, scale, s, vt, basis, residual, coefficients, rank, proj)

    def subset(self, keep: Sequence[int], rank_tol: float = RANK_TOL) -> LinearFit | None:
        """The fit of the columns ``keep`` only, at the same weights, from this fit's factors:
        they lie in the range, A[:, keep] = U (S V^T D)[:, keep], so only that p x k core is
        factored. None when this fit is rank-deficient or not "nonrobust". Why: a shape
        changed or an effect taken out leaves a model whose columns the last fit had."""
        p = len(self.coefficients)
        keep = list(keep)
        if self.rank < p or self.cov_type != "nonrobust" or not keep:
            return None
        columns = self._in_basis()[:, keep]
        scale = self.scale[keep]
        um, s, vt = svd(columns / scale, full_matrices=False)
        rank = numerical_rank(tol=rank_tol, singular_values=s)
        proj = um[:, :rank].T @ self.projection                        # U^T b = projection
        basis = self.basis @ um[:, :rank]
        coefficients = (vt[:rank].T @ (proj / s[:rank])) / scale
        residual = self.residual + self.basis @ self.projection - basis @ proj
        return LinearFit(self.weights, self.samples, scale, s, vt, basis, residual, coefficients, rank, proj)

    def reweighted(self, weights: np.ndarray, rank_tol: float = RANK_TOL) -> LinearFit | None:
        """The same columns and measurements fitted at other ``weights`` (f,), from this fit's
        factors: with R the rows' weight ratios, R A = (R U) S V^T D, and R U = Q T by Cholesky
        QR, exact here because R U is as well conditioned as R (a weighting's step changes the
        weights by a few per cent); then only the square core T S V^T D is factored again.
        Why: each selection step refits its model at the weights its noise levels moved to,
        and an SVD of the N f rows costs several times this. None when this fit is
        rank-deficient or not "nonrobust", or the weights change by more than RESCALE_LIMIT."""
        p = len(self.coefficients)
        ratio = np.asarray(weights, dtype=float) / self.weights
        if (self.rank < p or self.cov_type != "nonrobust" or not np.all(np.isfinite(ratio))
                or np.min(ratio) <= 0 or np.max(ratio) / np.min(ratio) > RESCALE_LIMIT):
            return None
        rows = np.tile(ratio, self.samples)[:, None]
        RU = rows * self.basis
        try:
            T = np.linalg.cholesky(RU.T @ RU).T                      # upper: (R U)^T (R U) = T^T T
        except np.linalg.LinAlgError:
            return None
        columns = self._in_basis()
        core = T @ columns
        scale = np.linalg.norm(core, axis=0)                          # column norms of R A (Q orthonormal)
        scale[scale == 0] = 1.0
        um, s, vt = svd(core / scale)
        rank = numerical_rank(tol=rank_tol, singular_values=s)
        target = rows[:, 0] * self.weighted_target()
        basis = RU @ solve_triangular(T, um[:, :rank])                # Q um with Q = R U T^-1
        proj = basis.T @ target
        coefficients = (vt[:rank].T @ (proj / s[:rank])) / scale
        return LinearFit(np.asarray(weights, dtype=float), self.samples, scale, s, vt, basis,
                         target - basis @ proj, coefficients, rank, proj)

    def reordered(self, order: Sequence[int]) -> LinearFit:
        """The same fit with its columns (coefficients, scale, right singular vectors) in ``order``."""
        order = list(order)
        return LinearFit(self.weights, self.samples, self.scale[order], self.singular_values, self.right[:, order],
                         self.basis, self.residual, self.coefficients[order], self.rank, self.projection,
                         self.cov_type, None if self._columns is None else self._columns[:, order])

    def weighted_target(self) -> np.ndarray:
        """The weighted measurements (N f,): the residual plus their projection on the range."""
        return self.residual + self.basis @ self.projection

    def unweighted_residual(self) -> np.ndarray:
        """The residual (N, f) in the measurement's units."""
        return self.residual.reshape(self.samples, self.coordinates) / self.weights

    def noise_variance(self) -> np.ndarray:
        """Each coordinate's noise variance (f,) in the measurement's units: s^2 / w_c^2."""
        return self.scale_variance / self.weights ** 2

    def prediction_variance(self, rows: np.ndarray) -> np.ndarray:
        """The variance (m, f) of the error of predicting new measurements at model rows
        (m, f, p) not in the fit: each coordinate's noise variance plus the coefficients'
        error propagated to the row, sigma_c^2 + x^T Cov x (linear regression's prediction
        variance). A held-out row far outside the fitted rows (the SLA's near-toggle sample)
        amplifies the coefficients' error, so the noise SD alone understates what any fitted
        model can reach there."""
        propagated = np.einsum("mfp,pq,mfq->mf", rows, self.covariance, rows)
        return self.noise_variance()[None, :] + propagated


@dataclass(frozen=True)
class Reduced:
    """A fit with some columns left out, held as the full fit's basis less the directions
    ``leaving`` (:meth:`LinearFit.without`): what the tests need (weights, residual, rank,
    projections on the range's complement) without a factorisation of its own."""
    weights: np.ndarray
    samples: int
    rank: int
    residual: np.ndarray
    full_basis: np.ndarray
    leaving: np.ndarray            # (N f, r): orthonormal, inside full_basis's span

    def orthogonal(self, columns: np.ndarray) -> np.ndarray:
        """``columns`` (N f, k), weighted rows, less their projection on this model's range."""
        return (columns - self.full_basis @ (self.full_basis.T @ columns)
                + self.leaving @ (self.leaving.T @ columns))


@dataclass(frozen=True)
class WeightedLinearModel:
    """y (N, f) ≈ model (N, f, p) @ coefficients, rows weighted per coordinate."""
    model: np.ndarray
    y: np.ndarray

    def fit(self, weights: np.ndarray | None = None, *, start: np.ndarray | None = None,
            tolerance: float = TOLERANCE, floor: float = 0.0, rank_tol: float = RANK_TOL,
            cov_type: CovType = "nonrobust", near: LinearFit | None = None) -> LinearFit:
        """Least squares with per-coordinate ``weights`` (f,); None: Gautier's noise weighting
        iterated to its fixed point (to ``tolerance``, each SD at least ``floor``), starting
        from the weights ``start``. ``near``: a fit of these columns and measurements at other
        weights, refitted from its factors when it can be (:meth:`LinearFit.reweighted`)."""
        n, f, p = self.model.shape
        if weights is None:
            return self._at_fixed_point(start, tolerance, floor, rank_tol, cov_type, near)
        if near is not None and cov_type == "nonrobust":
            again = near.reweighted(weights, rank_tol)
            if again is not None:
                return again
        A = (self.model * weights[None, :, None]).reshape(n * f, p)
        b = (self.y * weights[None, :]).reshape(n * f)
        scale = np.linalg.norm(A, axis=0)
        zero = scale == 0
        scale[zero] = 1.0
        # scaled in place when A is not kept (24 MB of fresh pages fewer on TIAGo's 9,600 rows)
        scaled = np.divide(A, scale, out=A) if cov_type == "nonrobust" else A / scale
        u, s, vt = thin_svd(scaled, keep=lambda values: numerical_rank(tol=rank_tol, singular_values=values),
                            zero_column=bool(np.any(zero)))
        rank = numerical_rank(tol=rank_tol, singular_values=s)
        proj = u[:, :rank].T @ b
        coefficients = (vt[:rank].T @ (proj / s[:rank])) / scale
        residual = b - u[:, :rank] @ proj
        return LinearFit(weights, n, scale, s, vt, u[:, :rank], residual, coefficients, rank, proj, cov_type,
                         None if cov_type == "nonrobust" else A)

    def _at_fixed_point(self, start: np.ndarray | None, tolerance: float, floor: float, rank_tol: float,
                        cov_type: CovType, near: LinearFit | None = None) -> LinearFit:
        """The fit at Gautier's weights: the fixed point is first found on the per-coordinate
        Gram matrices (p x p: a pass costs no factorisation of the N f rows), then confirmed,
        and if need be continued, by the SVD fits themselves (each pass after the first, or
        from ``near``, refitted from the last one's factors), so the result is the SVD's
        whatever the Gram matrices' squared condition number lost."""
        n, f, _ = self.model.shape
        sigma, _ = fixed_point(_GramStatistics(self.model, self.y, rank_tol), n, f, floor,
                               start=None if start is None else 1.0 / start, tolerance=tolerance)
        for _ in range(PASSES):
            fit = near = self.fit(1.0 / sigma, rank_tol=rank_tol, cov_type=cov_type, near=near)
            again = noise_levels(*coordinate_statistics(fit.unweighted_residual(), fit.basis), n, floor)
            if np.max(np.abs(again / sigma - 1.0)) < tolerance:
                break
            sigma = again
        return fit


class _GramStatistics:
    """Per-coordinate residual sums of squares and leverages of a weighted fit, from the
    coordinates' Gram matrices X_c^T X_c (the normal equations; accurate enough to find the
    weights, which the SVD fit then checks)."""

    # the Gram matrix resolves singular values only down to sqrt(eps) of the largest
    RESOLUTION = 1e-7

    def __init__(self, model: np.ndarray, y: np.ndarray, rank_tol: float) -> None:
        self.model, self.y = model, y
        self.gram = np.stack([model[:, c, :].T @ model[:, c, :] for c in range(model.shape[1])])
        self.moment = np.stack([model[:, c, :].T @ y[:, c] for c in range(model.shape[1])])
        self.rank_tol = max(rank_tol, self.RESOLUTION)

    def __call__(self, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w2 = weights ** 2
        normal = np.tensordot(w2, self.gram, axes=1)
        scale = np.sqrt(np.diag(normal))
        scale[scale == 0] = 1.0
        values, vectors = np.linalg.eigh(normal / np.outer(scale, scale))
        values, vectors = values[::-1], vectors[:, ::-1]
        rank = numerical_rank(tol=self.rank_tol, singular_values=np.sqrt(np.clip(values, 0.0, None)))
        inverse = (vectors[:, :rank] / values[:rank]) @ vectors[:, :rank].T / np.outer(scale, scale)
        coefficients = inverse @ np.tensordot(w2, self.moment, axes=1)
        residual = self.y - self.model @ coefficients
        leverage = w2 * np.einsum("cpq,pq->c", self.gram, inverse)
        return np.sum(residual ** 2, axis=0), leverage
