"""Gautier's noise weighting (baseparams.identify.weighting), shared by identify and diagnose."""

import numpy as np
import pytest

from baseparams.identify.linear import WeightedLinearModel
from baseparams.identify import weighting


def test_each_coordinate_gets_its_own_degrees_of_freedom():
    """p columns acting on coordinate 0 only: its SD divides by n - p, coordinate 1's by n."""
    rng = np.random.default_rng(1)
    n, p = 50, 7
    model = np.zeros((n, 2, p))
    model[:, 0, :] = rng.standard_normal((n, p))
    y = rng.standard_normal((n, 2))
    fit = WeightedLinearModel(model, y).fit(np.ones(2))
    residual = fit.residual.reshape(n, 2)
    levels = weighting.noise_levels(*weighting.coordinate_statistics(residual, fit.basis), n)
    expected = np.sqrt(np.sum(residual ** 2, axis=0) / np.array([n - p, n]))
    assert np.allclose(levels, expected, rtol=1e-12)


def test_fixed_point_recovers_very_different_noise_levels():
    """Shared parameters, forces of one size, noise SDs 1 and 1e-3: the fixed point finds both
    within sampling error; the first (unweighted) pass leaves the quiet one's far too large
    (its residual carries the loud coordinate's noise through the shared parameters)."""
    rng = np.random.default_rng(2)
    n, p = 400, 6
    model = rng.standard_normal((n, 2, p))
    truth = np.array([1.0, 1e-3])
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, 2)) * truth
    first = WeightedLinearModel(model, y).fit(np.ones(2))
    one_pass = weighting.noise_levels(*weighting.coordinate_statistics(first.residual.reshape(n, 2), first.basis), n)
    fit = WeightedLinearModel(model, y).fit()
    assert np.allclose(1.0 / fit.weights, truth, rtol=0.15)
    assert one_pass[1] > 5 * truth[1]


def _own_levels(fit, n):
    return weighting.noise_levels(*weighting.coordinate_statistics(fit.unweighted_residual(), fit.basis), n)


def test_the_fit_returned_is_at_its_own_fixed_point_even_when_the_gram_matrices_are_ill_conditioned():
    """The weights are first found on the Gram matrices (normal equations), whose condition
    number is squared; the SVD fit returned must still be within the tolerance of its own noise
    levels. Columns scaled over 1e5 and two nearly collinear (1e-6) put the Gram matrices near
    the edge of float64."""
    rng = np.random.default_rng(3)
    n, f, p = 300, 3, 8
    model = rng.standard_normal((n, f, p)) * np.logspace(0, 5, p)
    model[:, :, -1] = model[:, :, 0] + 1e-6 * rng.standard_normal((n, f))
    truth = np.array([1.0, 1e-2, 1e-4])
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f)) * truth
    fit = WeightedLinearModel(model, y).fit(tolerance=1e-6)
    assert np.allclose(_own_levels(fit, n), 1.0 / fit.weights, rtol=1e-5)
    assert np.allclose(1.0 / fit.weights, truth, rtol=0.2)
