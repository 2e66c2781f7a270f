"""The one weighted linear model (baseparams.identify.linear): its covariance against the
textbook formula, the HAC sandwich against statsmodels, and the fit without some columns
(Frisch-Waugh-Lovell from one factorisation) against a refit."""

import numpy as np
import pytest
from statsmodels.stats.sandwich_covariance import S_hac_simple

from baseparams.identify.linear import WeightedLinearModel


def test_covariance_is_the_classical_one_and_s2_is_one_at_the_fixed_point():
    """At the fixed point each coordinate's SD divides its own sum of squares by its own
    degrees of freedom, so s^2 = 1 and Cov = (X_w^T X_w)^-1, the textbook weighted covariance
    computed here independently with numpy's inverse."""
    rng = np.random.default_rng(4)
    n, f, p = 200, 2, 5
    model = rng.standard_normal((n, f, p))
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f)) * np.array([0.5, 2.0])
    fit = WeightedLinearModel(model, y).fit(tolerance=1e-10)
    assert fit.scale_variance == pytest.approx(1.0, rel=1e-6)
    X = (model * fit.weights[None, :, None]).reshape(n * f, p)
    assert np.allclose(fit.covariance, np.linalg.inv(X.T @ X), rtol=1e-6)
    assert np.allclose(fit.coefficients, np.linalg.lstsq(X, (y * fit.weights).reshape(-1), rcond=None)[0])


def test_hac_covariance_is_the_sandwich_of_the_per_sample_scores():
    """cov_type="hac": (X^T X)^-1 S (X^T X)^-1 with S statsmodels' Newey-West of the scores
    summed per sample, scaled by rows / dof, at the lag window the residual asks for."""
    rng = np.random.default_rng(5)
    n, f, p = 400, 2, 3
    model = rng.standard_normal((n, f, p))
    e = np.zeros((n, f))
    for t in range(1, n):
        e[t] = 0.8 * e[t - 1] + rng.standard_normal(f)
    y = model @ np.ones(p) + e
    weights = np.array([1.0, 0.5])
    fit = WeightedLinearModel(model, y).fit(weights, cov_type="hac")
    X = (model * weights[None, :, None]).reshape(n * f, p)
    r = (y * weights).reshape(-1) - X @ fit.coefficients
    from baseparams.identify.longrun import hac_lags
    lags = hac_lags(r.reshape(n, f))
    assert lags > 0
    S = S_hac_simple((X * r[:, None]).reshape(n, f, p).sum(axis=1), nlags=lags) * (n * f) / (n * f - p)
    bread = np.linalg.inv(X.T @ X)
    assert np.allclose(fit.covariance, bread @ S @ bread, rtol=1e-8)


@pytest.mark.parametrize("seed", range(5))
def test_without_equals_a_refit_without_the_columns(seed):
    """Residual, rank and the projection on the smaller model's complement from the complete
    fit's factorisation agree with a fit of the smaller model, on random models with columns
    of very different sizes."""
    rng = np.random.default_rng(seed)
    n, f, p = 150, 3, 9
    model = rng.standard_normal((n, f, p)) * np.logspace(-2, 3, p)
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f))
    weights = rng.uniform(0.5, 2.0, f)
    complete = WeightedLinearModel(model, y).fit(weights)
    drop = sorted(rng.choice(p, size=int(rng.integers(1, 4)), replace=False).tolist())
    keep = [k for k in range(p) if k not in drop]
    refit = WeightedLinearModel(model[:, :, keep], y).fit(weights)
    reduced = complete.without(drop)
    assert reduced is not None and reduced.rank == refit.rank == len(keep)
    assert np.allclose(reduced.residual, refit.residual, atol=1e-9 * np.linalg.norm(refit.residual))
    Z = rng.standard_normal((n * f, 2))
    assert np.allclose(reduced.orthogonal(Z), refit.orthogonal(Z), atol=1e-9 * np.linalg.norm(Z))


def test_without_refuses_columns_a_rank_deficiency_involves():
    rng = np.random.default_rng(6)
    model = rng.standard_normal((50, 2, 3))
    model[:, :, 2] = model[:, :, 0]
    fit = WeightedLinearModel(model, rng.standard_normal((50, 2))).fit(np.ones(2))
    assert fit.rank == 2 and fit.without([2]) is None and fit.without([0]) is None


@pytest.mark.parametrize("seed", range(4))
def test_without_on_a_rank_deficient_fit_equals_a_refit_when_the_deficiency_lies_elsewhere(seed):
    """Two of the kept columns are collinear (the deficiency); leaving out others gives what a
    fit without them gives: residual, rank, projections."""
    rng = np.random.default_rng(10 + seed)
    n, f, p = 120, 3, 8
    model = rng.standard_normal((n, f, p)) * np.logspace(-1, 2, p)
    model[:, :, 1] = 3.0 * model[:, :, 0]
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f))
    weights = rng.uniform(0.5, 2.0, f)
    complete = WeightedLinearModel(model, y).fit(weights)
    assert complete.rank == p - 1
    drop = sorted(rng.choice(np.arange(2, p), size=int(rng.integers(1, 3)), replace=False).tolist())
    keep = [k for k in range(p) if k not in drop]
    refit = WeightedLinearModel(model[:, :, keep], y).fit(weights)
    reduced = complete.without(drop)
    assert reduced is not None and reduced.rank == refit.rank == len(keep) - 1
    assert np.allclose(reduced.residual, refit.residual, atol=1e-9 * np.linalg.norm(refit.residual))
    Z = rng.standard_normal((n * f, 2))
    assert np.allclose(reduced.orthogonal(Z), refit.orthogonal(Z), atol=1e-9 * np.linalg.norm(Z))


@pytest.mark.parametrize("case", ["random", "nearly collinear", "zero column", "copy of a column"])
def test_extended_equals_a_fit_of_all_the_columns(case):
    """A fit grown by columns from the smaller fit's factors (an SVD update) is the direct
    SVD fit of every column: singular values, rank, coefficients, residual, covariance and
    the range (its basis spans the direct one's, orthonormal), to rounding; on columns of
    very different sizes, a new column nearly or exactly a copy of an old one, a zero one."""
    rng = np.random.default_rng(["random", "nearly collinear", "zero column", "copy of a column"].index(case))
    n, f, p, k = 160, 3, 8, 3
    model = rng.standard_normal((n, f, p + k)) * np.logspace(-2, 3, p + k)
    if case == "nearly collinear":
        model[:, :, p + 1] = 2.0 * model[:, :, 3] + 1e-9 * rng.standard_normal((n, f))
    if case == "zero column":
        model[:, :, p + 2] = 0.0
    if case == "copy of a column":
        model[:, :, p] = model[:, :, 5]
    y = model @ rng.standard_normal(p + k) + rng.standard_normal((n, f))
    weights = rng.uniform(0.5, 2.0, f)
    small = WeightedLinearModel(model[:, :, :p], y).fit(weights)
    grown = small.extended((model[:, :, p:] * weights[None, :, None]).reshape(n * f, k))
    direct = WeightedLinearModel(model, y).fit(weights)
    assert grown is not None and grown.rank == direct.rank
    assert np.allclose(grown.singular_values, direct.singular_values, rtol=0, atol=1e-12 * direct.singular_values[0])
    assert np.allclose(grown.residual, direct.residual, atol=1e-10 * np.linalg.norm(y))
    assert np.allclose(grown.basis.T @ grown.basis, np.eye(grown.rank), atol=1e-12)
    assert np.allclose(grown.basis @ (grown.basis.T @ direct.basis), direct.basis, atol=1e-10)
    if case != "copy of a column":          # minimum-norm coefficients of a deficient fit differ in rounding only
        assert np.allclose(grown.coefficients, direct.coefficients, rtol=1e-8)
        assert np.allclose(grown.covariance, direct.covariance, rtol=1e-7)
    else:
        assert np.allclose(grown.coefficients, direct.coefficients, rtol=1e-6, atol=1e-9)


def test_extended_refuses_a_rank_deficient_fit_and_reordered_permutes_the_columns():
    rng = np.random.default_rng(7)
    model = rng.standard_normal((60, 2, 4))
    model[:, :, 3] = model[:, :, 0]
    y = rng.standard_normal((60, 2))
    deficient = WeightedLinearModel(model, y).fit(np.ones(2))
    assert deficient.rank == 3 and deficient.extended(rng.standard_normal((120, 1))) is None
    fit = WeightedLinearModel(model[:, :, :3], y).fit(np.ones(2))
    swapped = WeightedLinearModel(model[:, :, [2, 0, 1]], y).fit(np.ones(2))
    moved = fit.reordered([2, 0, 1])
    assert np.allclose(moved.coefficients, swapped.coefficients)
    assert np.allclose(moved.covariance, swapped.covariance)
    assert np.allclose(moved.without([0]).residual, swapped.without([0]).residual)


@pytest.mark.parametrize("seed", range(3))
def test_subset_and_reweighted_equal_direct_fits(seed):
    """A fit of some of the columns (from the full fit's factors) and the fit at other weights
    (Cholesky QR of the reweighted basis) are the direct SVD fits, to rounding; the fixed
    point found by refitting from factors is the one found by SVD fits alone."""
    rng = np.random.default_rng(20 + seed)
    n, f, p = 200, 3, 10
    model = rng.standard_normal((n, f, p)) * np.logspace(-2, 3, p)
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f)) * np.array([0.3, 1.0, 3.0])
    weights = rng.uniform(0.5, 2.0, f)
    full = WeightedLinearModel(model, y).fit(weights)
    keep = sorted(rng.choice(p, size=6, replace=False).tolist())
    for got, direct in ((full.subset(keep), WeightedLinearModel(model[:, :, keep], y).fit(weights)),
                        (full.reweighted(weights * rng.uniform(0.7, 1.4, f)), None)):
        if direct is None:
            direct = WeightedLinearModel(model, y).fit(got.weights)
        assert got.rank == direct.rank
        assert np.allclose(got.coefficients, direct.coefficients, rtol=1e-9)
        assert np.allclose(got.residual, direct.residual, atol=1e-10 * np.linalg.norm(y))
        assert np.allclose(got.covariance, direct.covariance, rtol=1e-8)
        assert np.allclose(got.basis.T @ got.basis, np.eye(got.rank), atol=1e-12)
    assert full.reweighted(weights * np.array([1.0, 1.0, 10.0])) is None       # beyond RESCALE_LIMIT
    from_factors = WeightedLinearModel(model, y).fit(near=full, tolerance=1e-9)
    assert np.allclose(from_factors.weights, WeightedLinearModel(model, y).fit(tolerance=1e-9).weights, rtol=1e-7)
