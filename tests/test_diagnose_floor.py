"""The holdout prediction floor of ``diagnose`` (``gap.holdout_floor``): the mean squared
error a correct model fitted on the training block makes on the held-out block is the noise
variance plus the coefficients' error propagated to the held-out rows, sigma_c^2 + x^T Cov x.
Checked against a Monte-Carlo over noise draws on a linear model with one high-leverage
held-out sample (where the noise-only floor is far off), against statsmodels' WLS covariance,
and wired through ``diagnose`` and the text output."""

import numpy as np
import pytest
import statsmodels.api as sm

from baseparams.cli.diagnose import render_text
from baseparams.diagnose import selection as S
from baseparams.identify.linear import WeightedLinearModel
from baseparams.diagnose.estimates import holdout_floor, nrms
from baseparams.diagnose.problem import Problem
from baseparams.diagnose.workflow import diagnose
from baseparams.io.loader import resolve

N, TRAIN, P = 100, 70, 4
SIGMA = np.array([1.0, 0.1])           # per coordinate: the weighting has something to do
LEVERAGED = 85                         # a held-out sample far outside the training rows
DRAWS = 200


def _linear_model(leverage: float) -> tuple[np.ndarray, np.ndarray]:
    """(X (N, 2, P), theta): random rows; column 3 is small (0.05) everywhere except on
    coordinate 0 of the held-out sample LEVERAGED, where it is ``leverage``: the prediction
    there carries theta_3's error amplified, as at the SLA's near-toggle sample."""
    rng = np.random.default_rng(3)
    X = rng.standard_normal((N, 2, P))
    X[:, :, 3] *= 0.05
    X[LEVERAGED, 0, 3] = leverage
    return X, np.array([1.0, -2.0, 0.5, 3.0])


def _monte_carlo(leverage: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per draw and coordinate: the held-out MSE of the true model fitted (Gautier weighting,
    as diagnose fits) on the training block, and the predicted floor^2 (mean over the held-out
    rows of the prediction variance) from that draw's own fit; and the noise-only floor^2."""
    X, theta = _linear_model(leverage)
    clean = X @ theta
    rng = np.random.default_rng(11)
    mse, predicted, noise_only = (np.empty((DRAWS, 2)) for _ in range(3))
    for k in range(DRAWS):
        y = clean + rng.standard_normal(clean.shape) * SIGMA
        fit = WeightedLinearModel(X[:TRAIN], y[:TRAIN]).fit()
        error = y[TRAIN:] - X[TRAIN:] @ fit.coefficients
        mse[k] = np.mean(error ** 2, axis=0)
        predicted[k] = np.mean(fit.prediction_variance(X[TRAIN:]), axis=0)
        noise_only[k] = 1.0 / fit.weights ** 2
    return mse, predicted, noise_only


def _agrees(mse: np.ndarray, floor2: np.ndarray) -> np.ndarray:
    """Per coordinate: the predicted floor^2 within 4 standard errors of the Monte-Carlo mean
    MSE (SE = the draws' SD / sqrt(DRAWS): about 7 % of the mean on the leveraged coordinate,
    2 % on the other; the noise-only floor^2 is 9 SE below the leveraged mean)."""
    se = np.std(mse, axis=0, ddof=1) / np.sqrt(len(mse))
    return np.abs(mse.mean(axis=0) - floor2.mean(axis=0)) <= 4 * se


def test_prediction_floor_matches_the_monte_carlo_holdout_mse_and_noise_alone_does_not():
    mse, predicted, noise_only = _monte_carlo(leverage=30.0)
    assert _agrees(mse, predicted).all()
    # the leveraged held-out sample more than doubles the leveraged coordinate's floor^2 ...
    assert predicted[:, 0].mean() > 2.0 * noise_only[:, 0].mean()
    # ... and the noise-only floor (Cov left out) fails the same check there: it discriminates
    agrees_without_cov = _agrees(mse, noise_only)
    assert not agrees_without_cov[0]


def test_without_leverage_the_two_floors_nearly_coincide():
    """No held-out row outside the training rows: Cov adds about p / N_train per row."""
    mse, predicted, noise_only = _monte_carlo(leverage=0.05)
    assert _agrees(mse, predicted).all()
    assert np.all(predicted.mean(axis=0) < 1.1 * noise_only.mean(axis=0))


def test_prediction_variance_is_statsmodels_wls_prediction_variance():
    """x^T Cov x with Cov the WLS covariance at the fit's own weights and unit weighted noise
    (statsmodels' ``normalized_cov_params``), plus sigma_c^2."""
    X, theta = _linear_model(30.0)
    y = X @ theta + np.random.default_rng(0).standard_normal((N, 2)) * SIGMA
    fit = WeightedLinearModel(X[:TRAIN], y[:TRAIN]).fit()
    w2 = np.tile(fit.weights ** 2, TRAIN)
    ols = sm.WLS(y[:TRAIN].reshape(-1), X[:TRAIN].reshape(-1, P), weights=w2).fit()
    np.testing.assert_allclose(fit.coefficients, ols.params, rtol=1e-8)
    rows = X[TRAIN:]
    expected = np.einsum("mfp,pq,mfq->mf", rows, ols.normalized_cov_params, rows) + 1.0 / fit.weights ** 2
    np.testing.assert_allclose(fit.prediction_variance(rows), expected, rtol=1e-8)


def test_diagnose_reports_both_floors_in_the_nrms_normalisation():
    """Through diagnose (a Problem on the linear model, one candidate): ``holdout_floor`` is
    nrms(sqrt(prediction variance)) of the final fit on the held-out tau, ``holdout_noise_floor``
    the same with the noise SD alone; the text prints both next to 'holdout after'."""
    X, theta = _linear_model(30.0)
    rng = np.random.default_rng(5)
    tau = X @ theta + rng.standard_normal((N, 2)) * SIGMA
    t = np.linspace(0.0, 1.0, N)
    quad = np.stack([np.cos(40 * t) * t, np.zeros(N)], axis=1)[:, :, None]
    candidate = S.Candidate("offset", "a", ("c",), quad)
    problem = Problem(resolve("pendulum"), ("a", "b"), t, X, np.zeros((N, 2)), [candidate])
    d = diagnose(problem, tau, holdout=1 - TRAIN / N)
    assert d.training == TRAIN and d.effects == []
    fit = WeightedLinearModel(X[:TRAIN], tau[:TRAIN]).fit()
    floor, noise_only = holdout_floor(fit, X[TRAIN:], tau[TRAIN:])
    assert d.gap["holdout_floor"] == pytest.approx(floor, rel=1e-3)
    assert d.gap["holdout_noise_floor"] == pytest.approx(noise_only, rel=1e-3)
    assert floor == pytest.approx(nrms(np.sqrt(fit.prediction_variance(X[TRAIN:])), tau[TRAIN:]))
    sigma = 1.0 / fit.weights
    assert noise_only == pytest.approx(nrms(np.broadcast_to(sigma, (N - TRAIN, 2)), tau[TRAIN:]))
    assert floor > 1.3 * noise_only
    text = render_text(d)
    assert f"prediction floor {d.gap['holdout_floor']:.4g}" in text
    assert f"noise alone {d.gap['holdout_noise_floor']:.4g}" in text
    # no holdout: no floors
    d0 = diagnose(problem, tau, holdout=0.0)
    assert d0.gap["holdout_floor"] is None and d0.gap["holdout_noise_floor"] is None
