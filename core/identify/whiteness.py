"""Is what remains after a fit white noise? A Ljung-Box test per coordinate whose null
distribution is simulated through the fit itself.

Why not the textbook chi-square: the residual of a least-squares fit is (I - H) e, not e.
When the model's columns are smooth functions of time (every regressor of a smooth
trajectory is), removing them takes the noise's low-frequency content with them and leaves
the residual with negative autocorrelations of the order of (parameters per coordinate) /
samples at every short lag. The chi-square test then rejects white noise in 20-25 % of
datasets on the PUMA 560 and the Stewart platform (36 and 60 parameters over 210 samples;
benchmarks/bench_diagnose.py, nothing hidden), and the exit code would say "structure
remains" when nothing does. Simulating the null instead (Gaussian white noise at the
weighted fit's unit level, projected out of the same weighted model, Q computed the same
way) gives the test its size whatever the model, for a few hundred projections, one matrix
product each.
"""

import numpy as np

# Replicates per test: enough that Holm over the coordinates can reach alpha (p >= 1/(B+1)).
MIN_REPLICATES = 200
# Replicates simulated at once (memory: samples x coordinates x CHUNK floats).
CHUNK = 50
# Values of coloured noise drawn at once, its circulant embedding included (memory: 8 bytes each).
COLOURED_VALUES = 8_000_000
SEED = 20241123


def ljung_box(residual: np.ndarray, lags: int) -> np.ndarray:
    """The Ljung-Box statistic Q = n (n + 2) sum_k rho_k^2 / (n - k), k = 1..lags, of each
    column of ``residual`` (n, ...) along its first axis (statsmodels' ``acorr_ljungbox``
    computes the same for one column; tests/test_diagnose.py checks it)."""
    n = residual.shape[0]
    x = residual - residual.mean(axis=0)
    denominator = np.sum(x * x, axis=0)
    denominator = np.where(denominator > 0, denominator, 1.0)
    q = np.zeros(residual.shape[1:])
    for k in range(1, lags + 1):
        rho = np.sum(x[k:] * x[:-k], axis=0) / denominator
        q += rho * rho / (n - k)
    return n * (n + 2) * q


def replicates(coordinates: int, alpha: float) -> int:
    """Enough replicates for the smallest attainable p value, 1 / (B + 1), to pass Holm's
    first bar alpha / coordinates with room to spare."""
    return max(MIN_REPLICATES, int(np.ceil(4 * coordinates / alpha)))


def coloured_noise(rng: np.random.Generator, n: int, rest: tuple[int, ...], correlation: np.ndarray) -> np.ndarray:
    """Stationary Gaussian noise (n, *rest) of unit variance with the autocorrelation
    ``correlation`` (r[0] = 1, r[k] at lag k, zero beyond) along its first axis, by circulant
    embedding (exact where the embedding's spectrum is non-negative, as a zero-phase
    low-pass's is; clipped at zero elsewhere)."""
    k = min(len(correlation) - 1, n - 1)
    if k <= 0:
        return rng.standard_normal((n,) + rest)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    row = np.zeros(size)
    row[:k + 1] = correlation[:k + 1]
    row[size - k:] = correlation[1:k + 1][::-1]
    gain = np.sqrt(np.clip(np.fft.rfft(row).real, 0.0, None)).reshape((size // 2 + 1,) + (1,) * len(rest))
    white = rng.standard_normal((size,) + rest)
    return np.fft.irfft(gain * np.fft.rfft(white, axis=0), size, axis=0)[:n]


def monte_carlo_pvalues(residual: np.ndarray, basis: np.ndarray, lags: int, alpha: float,
                        seed: int = SEED, correlation: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Per coordinate: the Ljung-Box statistic of ``residual`` (n, f; the weighted fit's
    residual) and its p value (B + 1 counting) under noise of unit level per weighted
    coordinate projected out of ``basis`` (n f, rank; orthonormal, the weighted model's range,
    rows sample-major): white, or with the autocorrelation ``correlation`` the recording's
    filter and decimation give white noise (:meth:`.data.MeasuredData.noise_correlation`).
    Seeded: the same data always gets the same answer."""
    n, f = residual.shape
    observed = ljung_box(residual, lags)
    total = replicates(f, alpha)
    rng = np.random.default_rng(seed)
    exceed = np.zeros(f)
    done = 0
    while done < total:
        b = min(CHUNK, total - done)
        if correlation is not None and len(correlation) > 1:
            b = min(b, max(1, COLOURED_VALUES // (4 * n * f)))      # the embedding is 2-4 times n
            noise = coloured_noise(rng, n, (f, b), correlation).reshape(n * f, b)
        else:
            noise = rng.standard_normal((n * f, b))
        noise -= basis @ (basis.T @ noise)
        exceed += np.sum(ljung_box(noise.reshape(n, f, b), lags) >= observed[:, None], axis=1)
        done += b
    return observed, (exceed + 1.0) / (total + 1.0)
