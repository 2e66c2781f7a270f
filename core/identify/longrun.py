"""Long-run (HAC) covariance of per-sample scores: the one home of the lag window and of the
Newey-West (Bartlett) estimate, optionally VAR(1)-prewhitened, that the coefficient
covariance (:mod:`.linear`), the selection's Wald tests (:mod:`.selection`) and the
stability test (:mod:`.outofsample`) share."""

import numpy as np
from scipy.ndimage import uniform_filter1d
from statsmodels.stats.sandwich_covariance import S_hac_simple


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
    n = residual.shape[0]
    base = newey_west_lags(n)
    limit = max(base, n // 4)
    if n < 8:
        return base
    nlags = min(limit, n - 1)
    centred = residual - residual.mean(axis=0)
    energy = np.sum(centred ** 2, axis=0)
    live = energy > 0
    if not live.any():
        return base
    band = 1.96 / np.sqrt(n)
    first = np.sum(centred[1:, live] * centred[:-1, live], axis=0) / energy[live]
    if abs(float(np.mean(first))) < band:      # white already at lag 1 (most tests): no FFT
        return 0
    # the next few lags directly (most windows end there; an FFT costs as much as ~20 of them)
    live_centred = centred[:, live]
    for k in range(2, min(DIRECT_LAGS, nlags) + 1):
        mean_k = float(np.mean(np.sum(live_centred[k:] * live_centred[:-k], axis=0) / energy[live]))
        if abs(mean_k) < band:
            return int(min(limit, max(base, 2 * (k - 1))))
    # every coordinate's autocorrelation at once (statsmodels' acf, one FFT for all columns)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(centred[:, live], n=size, axis=0)
    autocovariance = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=0)[:nlags + 1]
    mean = np.mean(autocovariance / energy[live], axis=1)
    inside = np.nonzero(np.abs(mean[1:]) < band)[0]
    leading = int(inside[0]) if inside.size else nlags
    if leading == 0:
        return 0
    return int(min(limit, max(base, 2 * leading)))


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
    if lags == 0 or not prewhiten or len(scores) < 20:
        return S_hac_simple(scores, nlags=lags)
    before, after = scores[:-1], scores[1:]
    if scores.shape[1] == 1:                  # one direction (most tests): the same in scalars
        energy = float(before[:, 0] @ before[:, 0])
        a = float(before[:, 0] @ after[:, 0]) / energy if energy > 0 else 0.0
        a = float(np.clip(a, -PREWHITEN_LIMIT, PREWHITEN_LIMIT))
        e = after - a * before
        return S_hac_simple(e, nlags=hac_lags(e)) / (1.0 - a) ** 2
    At, *_ = np.linalg.lstsq(before, after, rcond=None)
    u, sv, vt = np.linalg.svd(At.T)
    A = (u * np.minimum(sv, PREWHITEN_LIMIT)) @ vt
    e = after - before @ A.T
    S = S_hac_simple(e, nlags=hac_lags(e))
    B = np.linalg.inv(np.eye(A.shape[0]) - A)
    return B @ S @ B.T


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
    size = 1 << int(np.ceil(np.log2(2 * n)))
    e = np.fft.rfft(residual, n=size, axis=0)                       # (M, f)
    b = np.fft.rfft(directions, n=size, axis=0)                     # (M, f, r)
    noise = np.fft.irfft(np.conj(e)[:, :, None] * e[:, None, :], n=size, axis=0)      # R^e_jk(h)
    shape = np.fft.irfft(np.conj(b)[:, :, None, :, None] * b[:, None, :, None, :], n=size, axis=0)
    h = np.concatenate([np.arange(lags + 1), np.arange(size - lags, size)])
    terms = np.einsum("hjk,hjkab->hab", noise[h], shape[h]) / scale
    bartlett = np.einsum("h,hab->ab", 1.0 - np.minimum(h, size - h) / (lags + 1.0), terms)
    if not truncated or lags == 0:
        return bartlett
    return at_least(terms.sum(axis=0), bartlett)


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
    window = min(max(LOCAL_WINDOW, 2 * lags + 1), len(residual))
    mean = np.mean(residual ** 2, axis=0)
    live = mean > 0
    power = np.ones_like(residual)
    power[:, live] = uniform_filter1d(residual[:, live] ** 2, size=window, axis=0, mode="nearest") / mean[live]
    return power
