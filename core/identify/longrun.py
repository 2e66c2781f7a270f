"""Long-run (HAC) covariance of per-sample scores: the one home of the lag window and of the
Newey-West (Bartlett) estimate, optionally VAR(1)-prewhitened, that the coefficient
covariance (:mod:`.linear`), the selection's Wald tests (:mod:`.selection`) and the
stability test (:mod:`.outofsample`) share."""

import numpy as np

from baseparams.numeric.linalg import svd


def correlation_length(n: int, lags: int) -> int:
    """The FFT length for correlations of n samples up to ``lags`` apart: zero-padded to at
    least n + lags, no circular wrap reaches those lags. A fast length (2, 3, 5 smooth), not
    the next power of two above 2 n: 3 times fewer points at a short window (issue 42)."""
    from scipy.fft import next_fast_len      # here: scipy.fft is 0.06 CPU s of every identify, which never asks
    return next_fast_len(n + lags, real=True)


def newey_west_lags(n: int) -> int:
    return int(np.floor(4 * (n / 100.0) ** (2.0 / 9.0)))


# lags hac_lags computes one by one before it turns to an FFT for the rest
DIRECT_LAGS = 6


def hac_lags(residual: np.ndarray) -> int:
    """The HAC window for a residual (N, f), from its mean autocorrelation over the
    coordinates: 0 (White's covariance) when already the first lag is inside the 95 % band
    +-1.96/sqrt(N) of a white sequence; otherwise twice the number of leading lags outside
    it, at least the Newey-West rule 4 (N/100)^(2/9), at most N/4. (A fixed Newey-West window
    on a white residual makes small-sample tests reject too often; one too short for a
    correlated residual makes them reject far too often.)"""
    return int(hac_lags_each(residual[:, :, None])[0])


def hac_lags_each(residuals: np.ndarray) -> np.ndarray:
    """:func:`hac_lags` of each residual in ``residuals`` (N, f, m) (or (N, m): one
    coordinate each) at once: the first DIRECT_LAGS autocorrelations directly (most windows
    end there; an FFT costs as much as ~20 of them), the rest by one FFT for the residuals
    still open. Why: a selection step tests a hundred candidate forms, each with its own
    residual, and one call each was most of the step's small numpy calls."""
    x = residuals[:, None, :] if residuals.ndim == 2 else residuals
    n, f, m = x.shape
    base = newey_west_lags(n)
    out = np.full(m, base, dtype=int)
    if n < 8 or m == 0:
        return out
    limit = max(base, n // 4)
    nlags = min(limit, n - 1)
    centred = x - x.mean(axis=0)
    energy = np.einsum("tjm,tjm->jm", centred, centred)
    live = energy > 0
    count = live.sum(axis=0)
    open_ = count > 0                               # nothing live: the Newey-West window
    safe = np.where(live, energy, 1.0)
    band = 1.96 / np.sqrt(n)

    def mean_autocorrelation(lagged: np.ndarray) -> np.ndarray:
        return np.where(live, lagged / safe, 0.0).sum(axis=0) / np.maximum(count, 1)

    for k in range(1, min(DIRECT_LAGS, nlags) + 1):
        if not open_.any():
            return out
        inside = open_ & (np.abs(mean_autocorrelation(np.einsum("tjm,tjm->jm", centred[k:], centred[:-k]))) < band)
        out[inside] = 0 if k == 1 else min(limit, max(base, 2 * (k - 1)))
        open_ &= ~inside
    rest = np.nonzero(open_)[0]
    if rest.size:                                   # every coordinate's autocorrelation by one FFT
        size = correlation_length(n, nlags)
        spectrum = np.fft.rfft(centred[:, :, rest], n=size, axis=0)
        autocovariance = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=0)[:nlags + 1]
        mean = (np.where(live[:, rest], autocovariance / safe[:, rest], 0.0).sum(axis=1)
                / count[rest])                                          # (nlags + 1, len(rest))
        for column, j in enumerate(rest):
            inside = np.nonzero(np.abs(mean[1:, column]) < band)[0]
            leading = int(inside[0]) if inside.size else nlags
            out[j] = 0 if leading == 0 else min(limit, max(base, 2 * leading))
    return out


# Andrews and Monahan's bound on the prewhitening filter's singular values: a near-unit
# root would make (I - A)^-1 explode.
PREWHITEN_LIMIT = 0.97


def long_run(scores: np.ndarray, lags: int, prewhiten: bool = True) -> np.ndarray:
    """The long-run covariance of per-sample ``scores`` (n, r): Newey-West (Bartlett) with
    ``lags``; when ``lags`` > 0 and ``prewhiten``, Andrews and Monahan's (Econometrica 1992)
    VAR(1)-prewhitened form: fit s_t = A s_(t-1) + e_t, Newey-West on e (window from e's own
    autocorrelation), recoloured by (I - A)^-1. Why: with strongly autocorrelated residuals
    (AR(1) at 0.9) the Bartlett kernel alone underestimates the long-run variance by a
    fifth or more at any practical window, and the tests named effects in noise (4 of 10
    datasets); prewhitening removes most of that bias."""
    return long_run_each(scores[None], np.array([lags]), prewhiten)[0]


def long_run_each(scores: np.ndarray, lags: np.ndarray, prewhiten: bool = True) -> np.ndarray:
    """:func:`long_run` of each of m score series (m, n, r), each with its ``lags`` (m,), as
    (m, r, r), in matrix form (a least-squares fit of the prewhitening filter per series
    when r > 1). Why: as for :func:`hac_lags_each`."""
    m, n, r = scores.shape
    lags = np.asarray(lags, dtype=int)
    coloured = (lags > 0) & prewhiten & (n >= 20)
    out = bartlett_each(scores, np.where(coloured, 0, lags))
    which = np.nonzero(coloured)[0]
    if which.size == 0:
        return out
    before, after = scores[which, :-1], scores[which, 1:]
    if r == 1:                                      # one direction (most tests): in scalars
        energy = np.einsum("mt,mt->m", before[:, :, 0], before[:, :, 0])
        a = np.einsum("mt,mt->m", before[:, :, 0], after[:, :, 0]) / np.where(energy > 0, energy, 1.0)
        A = np.clip(np.where(energy > 0, a, 0.0), -PREWHITEN_LIMIT, PREWHITEN_LIMIT)[:, None, None]
    else:
        At = np.stack([np.linalg.lstsq(b, c, rcond=None)[0] for b, c in zip(before, after)])
        u, sv, vt = svd(np.swapaxes(At, 1, 2))
        A = np.einsum("mab,mb,mbc->mac", u, np.minimum(sv, PREWHITEN_LIMIT), vt)
    e = after - before @ np.swapaxes(A, 1, 2)
    S = bartlett_each(e, hac_lags_each(np.moveaxis(e, 0, 2)))
    B = np.linalg.inv(np.eye(r) - A)
    out[which] = B @ S @ np.swapaxes(B, 1, 2)
    return out


def bartlett_each(scores: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Newey-West sums (statsmodels' S_hac_simple: Bartlett weights, not divided by n) of
    each of m score series (m, n, r), each with its window ``lags`` (m,), as (m, r, r)."""
    transposed = np.swapaxes(scores, 1, 2)
    S = transposed @ scores
    for lag in range(1, int(np.max(lags, initial=0)) + 1):
        on = np.nonzero(lags >= lag)[0]
        s = transposed[on, :, lag:] @ scores[on, :-lag]
        S[on] += (1.0 - lag / (lags[on] + 1.0))[:, None, None] * (s + np.swapaxes(s, 1, 2))
    return S


def stationary_variance(residual: np.ndarray, directions: np.ndarray, lags: int, scale: float,
                        truncated: bool = False) -> np.ndarray:
    """The covariance (r, r) of directions^T e for noise e (n, f) whose cross-autocovariance
    is the same at every sample: the residual's (Bartlett-tapered to ``lags``, estimated over
    all samples, divided by ``scale``) seen through the directions' own (n, f, r)
    autocorrelation: sum over h, j, k of w(h) R^e_jk(h) R^b_jk(h). Why: a direction acting on
    a few samples (a friction step, whitened) has a HAC variance resting on a few scores; this
    one rests on every sample, and with ``lags`` 0 it is the classical sigma^2 I.

    ``truncated``: weights 1 up to ``lags`` (no taper), never below the Bartlett form (in
    the matrix order). Why: for a direction on a few neighbouring samples the taper only
    biases (under AR(1) 0.6 it leaves out a sixth of the variance and the test rejects 7.2 %
    at 5 %, 5.1 % truncated: benchmarks/bench_stationary_variance.py), and the estimate rests
    on every sample, so the taper buys no stability; the floor keeps the variance positive
    where the truncated kernel is not."""
    n, f, r = directions.shape
    size = correlation_length(n, lags)
    e = np.fft.rfft(residual, n=size, axis=0)                       # (M, f)
    noise = np.fft.irfft(np.conj(e)[:, :, None] * e[:, None, :], n=size, axis=0)      # R^e_jk(h)
    h = np.concatenate([np.arange(lags + 1), np.arange(size - lags, size)])
    b = np.fft.rfft(directions, n=size, axis=0)                     # (M/2 + 1, f, r)
    bartlett = _weighted_sum(noise, h, 1.0 - np.minimum(h, size - h) / (lags + 1.0), directions, b, size) / scale
    if not truncated or lags == 0:
        return bartlett
    return at_least(_weighted_sum(noise, h, np.ones(len(h)), directions, b, size) / scale, bartlett)


def _weighted_sum(noise: np.ndarray, h: np.ndarray, weight: np.ndarray, directions: np.ndarray, b: np.ndarray,
                  size: int) -> np.ndarray:
    """sum over the lags h of weight(h) sum_jk R^e_jk(h) R^b_jk(h), R^b_jk(h)_ab = sum_t
    b_{t,j,a} b_{t+h,k,b}: as sum_t b_{t,j,a} c_{t,j,b}, c the directions filtered by the
    kernel weight(h) R^e_jk(h) (one filter per coordinate pair, applied in the frequency
    domain). Why: the directions' own autocorrelation for every pair of columns (r^2 f^2
    series) cost a quarter of a diagnosis; filtering costs r f series, the same sum. ``b``: the
    directions' transform at length ``size``."""
    kernel = np.zeros((size,) + noise.shape[1:])                    # g_jk(h) at h mod M
    kernel[h] = weight[:, None, None] * noise[h]
    # c_t = sum_h g(h) b_{t+h}: a correlation, so the kernel's transform enters conjugated
    c = np.fft.irfft(np.einsum("mjk,mkb->mjb", np.conj(np.fft.rfft(kernel, axis=0)), b), n=size, axis=0)
    n = directions.shape[0]
    return np.einsum("tja,tjb->ab", directions, c[:n])


def at_least(V: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """``V`` raised to at least ``floor`` in the matrix order (floor positive definite):
    the directions where V is smaller take floor's variance."""
    try:
        L = np.linalg.cholesky((floor + floor.T) / 2)
    except np.linalg.LinAlgError:
        return floor
    inner = np.linalg.solve(L, np.linalg.solve(L, (V + V.T) / 2).T)
    values, vectors = np.linalg.eigh((inner + inner.T) / 2)
    raised = (vectors * np.maximum(values, 1.0)) @ vectors.T
    return L @ raised @ L.T


# samples in the moving window of the local noise level (at least; wider with the HAC window)
LOCAL_WINDOW = 25


def local_power(residual: np.ndarray, lags: int) -> np.ndarray:
    """Each sample's noise power (n, f) relative to its coordinate's mean: the moving mean of
    the squared residual over ``LOCAL_WINDOW`` or 2 ``lags`` + 1 samples, whichever is wider.
    Why: real residuals are larger in some regimes (at velocity reversals, under load) and a
    direction acting on a few samples there has a larger variance than the residual's
    overall level says."""
    from scipy.ndimage import uniform_filter1d    # here: 0.04 CPU s of every identify, which never asks
    window = min(max(LOCAL_WINDOW, 2 * lags + 1), len(residual))
    mean = np.mean(residual ** 2, axis=0)
    live = mean > 0
    power = np.ones_like(residual)
    power[:, live] = uniform_filter1d(residual[:, live] ** 2, size=window, axis=0, mode="nearest") / mean[live]
    return power
