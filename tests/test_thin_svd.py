"""The tall-matrix SVD through Cholesky QR twice (baseparams.numeric.linalg.thin_svd), and
the correlation length the long-run variances zero-pad to (baseparams.identify.longrun):
each checked against an independent computation (LAPACK's SVD; sums over the samples)."""

import numpy as np
import pytest

from baseparams.identify.longrun import correlation_length, hac_lags_each, newey_west_lags
from baseparams.numeric.linalg import CHOLESKY_QR_CONDITION, thin_svd


def tall(rows: int, columns: int, condition: float, seed: int) -> np.ndarray:
    """A rows x columns matrix with singular values spread log-evenly from 1 to 1/condition."""
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.standard_normal((rows, columns)))
    v, _ = np.linalg.qr(rng.standard_normal((columns, columns)))
    return (u * np.logspace(0, -np.log10(condition), columns)) @ v.T


@pytest.mark.parametrize("columns, condition", [(1, 1.0), (2, 10.0), (4, 1e3), (10, 1e4), (40, 3e4)])
def test_factors_agree_with_lapack(columns, condition):
    a = tall(4000, columns, condition, seed=columns)
    u, s, vt = thin_svd(a)
    u0, s0, vt0 = np.linalg.svd(a, full_matrices=False)
    assert u.shape == u0.shape and vt.shape == vt0.shape
    assert np.allclose(s, s0, rtol=1e-13, atol=0)
    assert np.allclose(u.T @ u, np.eye(columns), atol=1e-14)
    assert np.allclose((u * s) @ vt, a, atol=1e-14)
    # the same directions up to sign (singular values distinct here): the projections agree
    x = np.random.default_rng(0).standard_normal(4000)
    for k in range(1, columns + 1):
        assert np.allclose(u[:, :k] @ (u[:, :k].T @ x), u0[:, :k] @ (u0[:, :k].T @ x), atol=1e-12 * condition)


@pytest.mark.parametrize("case", ["rank deficient", "ill conditioned", "wide", "not finite"])
def test_lapack_where_cholesky_qr_is_not_accurate(case):
    """Outside Cholesky QR's range the result is LAPACK's own, bit for bit."""
    a = tall(3000, 6, 10.0, seed=1)
    if case == "rank deficient":
        a[:, 5] = a[:, 0]
    elif case == "ill conditioned":
        a = tall(3000, 6, 100 * CHOLESKY_QR_CONDITION, seed=2)
    elif case == "wide":
        a = a[:20]
    else:
        a[7, 2] = np.inf
    for x, y in zip(thin_svd(a), np.linalg.svd(a, full_matrices=False)):
        assert np.array_equal(x, y, equal_nan=True)


def test_correlation_length_leaves_no_circular_wrap():
    """Autocovariances through an FFT of the padded length equal the sums over the samples up
    to the lags asked for (a shorter length would fold the far end onto them)."""
    rng = np.random.default_rng(3)
    n, lags = 777, 120
    x = rng.standard_normal(n)
    size = correlation_length(n, lags)
    assert n + lags <= size < 2 * n
    spectrum = np.fft.rfft(x, n=size)
    through_fft = np.fft.irfft(spectrum * np.conj(spectrum), n=size)[:lags + 1]
    direct = np.array([x[h:] @ x[:n - h] for h in range(lags + 1)])
    assert np.allclose(through_fft, direct, rtol=0, atol=1e-10 * direct[0])
    short = np.fft.irfft(np.abs(np.fft.rfft(x, n=n)) ** 2, n=n)[:lags + 1]
    assert not np.allclose(short, direct, rtol=0, atol=1e-3 * direct[0])


def test_a_long_window_is_the_rule_applied_to_direct_autocorrelations():
    """hac_lags_each's FFT branch (windows longer than its direct lags): twice the leading
    lags outside the 95 % band of the mean autocorrelation, at least Newey-West's window."""
    rng = np.random.default_rng(4)
    n, f = 1500, 3
    e = np.zeros((n, f))
    for t in range(1, n):
        e[t] = 0.97 * e[t - 1] + rng.standard_normal(f)
    centred = e - e.mean(axis=0)
    energy = np.sum(centred ** 2, axis=0)
    band, limit = 1.96 / np.sqrt(n), max(newey_west_lags(n), n // 4)
    leading = next(h for h in range(1, n) if abs(np.mean([centred[h:, j] @ centred[:-h, j] / energy[j]
                                                           for j in range(f)])) < band) - 1
    assert leading > 6
    assert hac_lags_each(e[:, :, None])[0] == min(limit, max(newey_west_lags(n), 2 * leading))


def rank_deficient(rows: int, columns: int, rank: int, condition: float, seed: int) -> np.ndarray:
    """A rows x columns matrix of the given rank (exactly collinear columns beyond it), its
    nonzero singular values log-even from 1 to 1/condition, columns of unequal norms."""
    rng = np.random.default_rng(seed)
    a = tall(rows, rank, condition, seed) @ rng.standard_normal((rank, columns))
    return a * np.logspace(0, 1, columns)


@pytest.mark.parametrize("columns, rank, condition", [(6, 5, 10.0), (30, 21, 1e3), (12, 12, 1e7)])
def test_kept_directions_of_an_ill_conditioned_matrix(columns, rank, condition):
    """With ``keep`` (a numerical rank), a matrix Cholesky QR cannot factor (rank-deficient,
    or worse conditioned than CHOLESKY_QR_CONDITION) goes through Householder QR: the
    singular values are LAPACK's to rounding, u has the kept columns only, orthonormal, and
    spans LAPACK's leading directions; the right vectors' null space is LAPACK's."""
    a = rank_deficient(3000, columns, rank, condition, seed=columns)
    cut = 1e-9 if rank == columns else 1e-12
    keep = lambda s: int(np.sum(s > cut * s[0]))                       # noqa: E731
    u, s, vt = thin_svd(a, keep=keep)
    u0, s0, vt0 = np.linalg.svd(a, full_matrices=False)
    k = keep(s0)
    assert k == rank and u.shape == (3000, k) and vt.shape == vt0.shape
    assert np.allclose(s, s0, rtol=0, atol=1e-14 * s0[0])
    assert np.allclose(u.T @ u, np.eye(k), atol=1e-14)
    x = np.random.default_rng(0).standard_normal(3000)
    assert np.allclose(u @ (u.T @ x), u0[:, :k] @ (u0[:, :k].T @ x), atol=1e-13 * s0[0] / s0[k - 1])
    assert np.allclose((u * s[:k]) @ vt[:k], a, atol=1e-13 * s0[0])
    null, null0 = vt[k:], vt0[k:]
    assert np.allclose(null.T @ (null @ null0.T), null0.T, atol=1e-12)


@pytest.mark.parametrize("keep", [None, lambda s: int(np.sum(s > 1e-12 * s[0]))])
def test_a_known_zero_column_gives_the_same_factors_to_the_bit(keep):
    """``zero_column``: the caller says a column is exactly zero, so Cholesky QR (whose Gram
    matrix then has a zero pivot) is not tried; the factors are those of the route it falls
    back to, bit for bit, with or without ``keep``."""
    a = rank_deficient(2000, 12, 9, 1e3, seed=3)
    a[:, 4] = 0.0
    plain, told = thin_svd(a, keep=keep), thin_svd(a, keep=keep, zero_column=True)
    for x, y in zip(plain, told):
        assert x.shape == y.shape and np.array_equal(x, y)
