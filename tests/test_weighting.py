"""Gautier's noise weighting (baseparams.identify.weighting), shared by identify and diagnose."""

import numpy as np

from baseparams.identify import selection as S
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
    levels = weighting.noise_levels(residual, fit.basis)
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
    one_pass = weighting.noise_levels(first.residual.reshape(n, 2), first.basis)
    fit = WeightedLinearModel(model, y).fit()
    assert np.allclose(1.0 / fit.weights, truth, rtol=0.15)
    assert one_pass[1] > 5 * truth[1]
