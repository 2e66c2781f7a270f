"""The lagged cross products of the change search's noise model (core/diagnose/lagged.py):
one FFT per column for every lag, the rows each entry leaves out at the ends taken off
directly; checked against the defining double sum, and fast_size against a search."""

import numpy as np
import pytest

from baseparams.diagnose.lagged import fast_size, lagged_cross, spectra


def direct(A: np.ndarray, B: np.ndarray, top: int) -> np.ndarray:
    n = len(A)
    return np.array([[sum(A[t - i] @ B[t - l] for t in range(top, n)) for l in range(top + 1)]
                     for i in range(top + 1)])


@pytest.mark.parametrize("n, k, top", [(60, 3, 5), (21, 2, 20), (22, 1, 20), (300, 7, 20), (9, 4, 0)])
def test_lagged_cross_is_the_direct_sum(n, k, top):
    rng = np.random.default_rng(n + k)
    A = np.cumsum(rng.standard_normal((n, k)), axis=0)          # coloured: sums far from zero
    B = rng.standard_normal((n, k)) + 3.0
    expected = direct(A, B, top)
    scale = np.max(np.abs(expected))
    assert np.allclose(lagged_cross(A, B, top), expected, rtol=0, atol=1e-13 * scale)
    assert np.allclose(lagged_cross(A, B, top, spectrum_b=spectra(B, top)), expected, rtol=0, atol=1e-13 * scale)
    assert np.allclose(lagged_cross(A, A, top), direct(A, A, top), rtol=0, atol=1e-13 * np.max(np.abs(direct(A, A, top))))


def test_no_row_past_the_order_gives_zeros():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((5, 2))
    assert np.array_equal(lagged_cross(A, A, 5), np.zeros((6, 6)))
    assert np.array_equal(lagged_cross(A, A, 7), direct(A, A, 7))


def test_fast_size_is_the_least_5_smooth_length():
    def smooth(m: int) -> bool:
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        return m == 1
    for n in list(range(1, 200)) + [5020, 2020, 16385, 30011]:
        size = fast_size(n)
        assert size >= n and smooth(size)
        assert not any(smooth(m) for m in range(n, size))
