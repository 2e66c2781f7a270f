"""local_cubic (core/diagnose/timeshift.py) reads the four rows around each instant as slices
where the sampling is uniform: the same operations on the same numbers as gathering them
(the rule written out below), so the result is the gathers' to the bit, on uniform,
clipped and irregular sampling, zero columns included; and it is exact on cubics."""

import numpy as np
import pytest

from baseparams.diagnose.timeshift import local_cubic


def gathered(t: np.ndarray, x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The Lagrange cubic through the nearest four samples, each row gathered by index."""
    first = np.clip(np.searchsorted(t, at, side="right") - 2, 0, len(t) - 4)
    nodes = t[first[:, None] + np.arange(4)]
    flat = x.reshape(len(x), -1)
    rows = np.zeros((len(at), flat.shape[1]))
    for k in range(4):
        weight = np.ones(len(at))
        for j in range(4):
            if j != k:
                weight *= (at - nodes[:, j]) / (nodes[:, k] - nodes[:, j])
        rows += np.take(flat, first + k, axis=0) * weight[:, None]
    return rows.reshape((len(at),) + x.shape[1:])


@pytest.mark.parametrize("n, delay, uniform", [(3000, 0.0123, True), (3000, -0.0311, True), (3000, 7.0, True),
                                               (7, 0.02, True), (3000, 0.02, False)])
def test_slices_are_the_gathers_to_the_bit(n, delay, uniform):
    rng = np.random.default_rng(n)
    t = np.arange(n) * 0.01 if uniform else np.sort(rng.uniform(0, 0.01 * n, n))
    x = rng.standard_normal((n, 3, 40))
    x[:, :, ::4] = 0.0
    at = np.clip(t - delay, t[0], t[-1])
    assert np.array_equal(local_cubic(t, x, at), gathered(t, x, at))


def test_exact_on_a_cubic():
    t = np.arange(500) * 0.002
    x = np.stack([1 + t - 3 * t ** 2 + 0.5 * t ** 3, 2 * t ** 3], axis=1)
    at = np.clip(t - 0.0037, t[0], t[-1])
    expected = np.stack([1 + at - 3 * at ** 2 + 0.5 * at ** 3, 2 * at ** 3], axis=1)
    assert np.allclose(local_cubic(t, x, at), expected, rtol=0, atol=1e-12)
