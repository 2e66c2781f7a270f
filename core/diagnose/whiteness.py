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

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:            # its Test only for the types
    from baseparams.diagnose.wald import Test

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


# ----- is what remains predictable from the motion? -------------------------------------------
# Why not whiteness: real residuals are always coloured (the recording's filter, the drives'
# dynamics), and a Ljung-Box test against a noise level reads any colour as structure: with
# nothing missing and AR(1) noise at 0.9 every diagnosis said "unexplained". Structure that a
# model can still take up is a force that follows the motion, so the verdict asks that: does
# a generic basis of each coordinate's motion (its position, speed, direction, acceleration,
# and the blocks of the recording) predict the final residual? The test is a Wald test after
# generalised least squares: data, model and basis are filtered by each coordinate's AR(p)
# fit of the residual (order by BIC), so stationary coloured noise, whatever its spectrum,
# leaves a nearly white residual and the test its size; what colour remains goes to the
# (prewhitened) HAC variance of wald.wald.

# blocks of the recording, each one indicator column per coordinate
MOTION_BLOCKS = 5
# the reversal bump's width, in RMS speeds: exp(-(qd / (REVERSAL_WIDTH rms))^2)
REVERSAL_WIDTH = 0.2
# the largest AR order tried (and at most samples / AR_SAMPLES_PER_ORDER)
MAX_AR_ORDER = 20
AR_SAMPLES_PER_ORDER = 20
MOTION_BASIS_NAMES = ("q", "q^2", "q^3", "qd", "qd|qd|", "sign(qd)", "reversal", "qdd")


def positions(qd: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Positions (n, f) up to a constant, by the trapezoid rule on the speeds ``qd`` (n, f);
    a step of time that is not positive or far beyond the typical one (a gap between runs)
    adds nothing."""
    dt = np.diff(np.asarray(t, float))
    typical = float(np.median(dt)) if dt.size else 0.0
    dt = np.where((dt > 0) & (dt <= 10 * typical), dt, 0.0)
    steps = 0.5 * (qd[1:] + qd[:-1]) * dt[:, None]
    return np.concatenate([np.zeros((1, qd.shape[1])), np.cumsum(steps, axis=0)])


def motion_basis(qd: np.ndarray | None, t: np.ndarray, blocks: int = MOTION_BLOCKS) -> list[np.ndarray]:
    """Per coordinate j, the columns (n, k_j) a force on j that follows the motion would
    share: its position (polynomial to degree 3, the positions integrated from the speeds:
    a constant shift changes nothing), its speed (linear, quadratic with sign, direction), a
    bump at its velocity reversals, its acceleration, and one indicator per block of the
    recording (time-segment dependence; together a constant). Columns that do not vary are
    left out (a still coordinate keeps its blocks)."""
    t = np.asarray(t, float)
    n = len(t)
    edges = np.linspace(0, n, blocks + 1).round().astype(int)
    block = np.zeros((n, blocks))
    for b in range(blocks):
        block[edges[b]:edges[b + 1], b] = 1.0
    if qd is None:
        return [block]
    qd = np.asarray(qd, float)
    q = positions(qd, t)
    dt = np.diff(t)
    ok = n > 2 and np.all(dt > 0)
    qdd = np.gradient(qd, t, axis=0) if ok else np.gradient(qd, axis=0)
    out = []
    for j in range(qd.shape[1]):
        columns = []
        spread = np.std(q[:, j])
        if spread > 0:
            u = (q[:, j] - q[:, j].mean()) / spread
            columns += [u, u * u - np.mean(u * u), u ** 3]
        rms = np.sqrt(np.mean(qd[:, j] ** 2))
        if rms > 0:
            v = qd[:, j] / rms
            columns += [v, v * np.abs(v), np.sign(v), np.exp(-(v / REVERSAL_WIDTH) ** 2)]
        a_rms = np.sqrt(np.mean(qdd[:, j] ** 2))
        if a_rms > 0:
            columns.append(qdd[:, j] / a_rms)
        out.append(np.concatenate([np.stack(columns, axis=1), block], axis=1) if columns else block)
    return out


def ar_fit(residual: np.ndarray, max_order: int | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """Per column of ``residual`` (n, f): the AR coefficients a (x_t - sum a_k x_(t-k) is the
    innovation) of the order BIC picks among 0..max_order (Yule-Walker by Levinson-Durbin:
    always a stable filter), and the innovations' variance (f,)."""
    n, f = residual.shape
    top = max_order if max_order is not None else min(MAX_AR_ORDER, max(0, n // AR_SAMPLES_PER_ORDER))
    top = max(0, min(top, n - 2))
    x = residual - residual.mean(axis=0)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(x, n=size, axis=0)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=0)[:top + 1] / n
    coefficients, variances = [], np.zeros(f)
    for j in range(f):
        r = acov[:, j]
        if r[0] <= 0:
            coefficients.append(np.zeros(0))
            continue
        a = np.zeros(0)
        error = r[0]
        best = (n * np.log(error), a, error)
        for k in range(1, top + 1):
            reflection = (r[k] - a @ r[k - 1:0:-1]) / error if k > 1 else r[1] / error
            a = np.concatenate([a - reflection * a[::-1], [reflection]])
            error = error * (1.0 - reflection ** 2)
            if error <= 0:
                break
            score = n * np.log(error) + k * np.log(n)
            if score < best[0]:
                best = (score, a, error)
        coefficients.append(best[1])
        variances[j] = best[2]
    return coefficients, variances


def ar_filter(x: np.ndarray, coefficients: Sequence[np.ndarray], skip: int) -> np.ndarray:
    """x (n, f, ...) filtered along the samples by each coordinate's AR filter
    (x_t - sum_k a_k x_(t-k)), the first ``skip`` rows (at least the longest filter) dropped."""
    out = x[skip:].copy()
    n = len(x)
    for j, a in enumerate(coefficients):
        for k, value in enumerate(a, start=1):
            out[:, j] -= value * x[skip - k:n - k, j]
    return out


def colour(residual: np.ndarray, t: np.ndarray, coefficients: Sequence[np.ndarray]) -> list[dict]:
    """Per coordinate of ``residual`` (n, f): its lag-1 autocorrelation, the AR order fitted,
    and the frequency below which half its power lies (Hz, from the median step of ``t``)."""
    n = len(residual)
    x = residual - residual.mean(axis=0)
    energy = np.sum(x * x, axis=0)
    lag1 = np.sum(x[1:] * x[:-1], axis=0) / np.where(energy > 0, energy, 1.0)
    dt = np.diff(np.asarray(t, float))
    step = float(np.median(dt)) if dt.size and np.median(dt) > 0 else 1.0
    power = np.abs(np.fft.rfft(x, axis=0)) ** 2
    frequencies = np.fft.rfftfreq(n, step)
    total = power.sum(axis=0)
    out = []
    for j in range(residual.shape[1]):
        half = frequencies[min(int(np.searchsorted(np.cumsum(power[:, j]) / total[j], 0.5)), len(frequencies) - 1)] \
            if total[j] > 0 else 0.0
        out.append({"lag1": float(lag1[j]), "ar_order": int(len(coefficients[j])), "half_power_hz": float(half),
                    "nyquist_hz": float(0.5 / step)})
    return out


# Replicates of the residual's AR fit simulated through the fit (its bias and spread).
AR_REPLICATES = 40
# Rounds of the bias correction (each simulates AR_REPLICATES at the last corrected filter).
AR_ROUNDS = 2
# The share of the replicates' effective count of low-frequency observations (2 / var log S(0))
# the reference F(k, nu) uses: over 40 replicates at the estimated filter the spread is itself
# uncertain, and the full count left the tail liberal (AR(1) 0.9 on the PUMA: 0.89 % at 0.5 %,
# 1.7 % at 1 %); half keeps it under (0.22 %, 0.56 %; 3.6 % at 5 %).
NU_SHARE = 0.5
LAGS = None
# The largest long-run gain 1 / (1 - sum a) a bias-corrected filter may reach (a unit root).
MAX_LONG_RUN_GAIN = 200.0


def _simulate_ar(rng: np.random.Generator, n: int, coefficients: Sequence[np.ndarray], sd: np.ndarray,
                 count: int) -> np.ndarray:
    """``count`` series (n, f, count) of each coordinate's AR process with innovations ``sd``,
    started a burn-in before (long enough for the slowest filter to forget its start)."""
    from scipy.signal import lfilter
    f = len(coefficients)
    out = np.empty((n, f, count))
    for j, a in enumerate(coefficients):
        gain = 1.0 / max(1.0 - float(np.sum(a)), 1.0 / MAX_LONG_RUN_GAIN) if len(a) else 1.0
        burn = int(min(20 * gain, 5 * n)) + len(a)
        e = rng.standard_normal((n + burn, count)) * sd[j]
        out[:, j] = lfilter([1.0], np.concatenate([[1.0], -a]), e, axis=0)[burn:] if len(a) else e[burn:]
    return out


def _fit_orders(residual: np.ndarray, orders: Sequence[int]) -> tuple[list[np.ndarray], np.ndarray]:
    """Yule-Walker AR fits of each column (n, f, ...) at the given orders: coefficients (f, ...,
    order) as a list and innovation variances (f, ...)."""
    n = residual.shape[0]
    x = residual - residual.mean(axis=0)
    top = max(orders, default=0)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(x, n=size, axis=0)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=0)[:top + 1] / n     # (top+1, f, ...)
    coefficients, variances = [], []
    for j, order in enumerate(orders):
        r = acov[:, j]
        if order == 0:
            coefficients.append(np.zeros(r.shape[1:] + (0,)))
            variances.append(r[0])
            continue
        from scipy.linalg import solve_toeplitz
        if r.ndim == 1:
            a = solve_toeplitz(r[:order], r[1:order + 1])
        else:
            a = np.stack([solve_toeplitz(r[:order, c], r[1:order + 1, c]) for c in range(r.shape[1])])
        coefficients.append(a)
        variances.append(r[0] - np.sum(a * np.moveaxis(r[1:order + 1], 0, -1), axis=-1))
    return coefficients, np.array(variances)


def _stable(a: np.ndarray) -> np.ndarray:
    """``a`` shrunk (a_k t^k) until its filter is stable and its long-run gain at most
    MAX_LONG_RUN_GAIN."""
    if len(a) == 0:
        return a
    for _ in range(200):
        roots = np.roots(np.concatenate([[1.0], -a]))
        if np.all(np.abs(roots) < 1.0) and 1.0 - np.sum(a) >= 1.0 / MAX_LONG_RUN_GAIN:
            return a
        a = a * 0.99 ** np.arange(1, len(a) + 1)
    return np.zeros_like(a)


def _wald(residual: np.ndarray, basis: np.ndarray, shape: tuple[int, int], dof: int) -> "Test":
    """Wald statistic of the orthonormal directions ``basis`` (rows, k) against ``residual``
    (rows,; rows sample-major, f coordinates a sample), with the larger (in the matrix order)
    of two variances: White's (per-sample scores summed over the coordinates: a noise level
    that changes with the motion) and the stationary one (each coordinate's residual
    autocovariance, Bartlett-free up to its window, seen through the directions' own:
    :func:`~baseparams.identify.longrun.stationary_variance`, a coordinate at a time: the
    coordinates' noises taken as independent). Why not selection's HAC: after the AR filter
    the directions of steps (a block's edge, a change of direction) act on few samples, and
    prewhitened Newey-West on their sparse scores rejected 26-38 % of nulls at 5 % under
    low-pass-filtered noise."""
    from baseparams.identify.longrun import hac_lags, stationary_variance
    from baseparams.diagnose.wald import Test
    n, f = shape
    k = basis.shape[1]
    gamma = basis.T @ residual
    augmented = residual - basis @ gamma
    noise = augmented.reshape(n, f)
    directions = basis.reshape(n, f, k)
    lags = hac_lags(noise)
    left = max(n * f - dof - k, 1)
    stationary = np.zeros((k, k))
    for j in range(f):
        if np.any(directions[:, j]):
            stationary += stationary_variance(noise[:, j:j + 1], directions[:, j:j + 1], lags, left / f,
                                              truncated=True)
    scores = np.einsum("tjr,tj->tr", directions, noise)
    white = scores.T @ scores * (n * f / left)
    values, vectors = np.linalg.eigh(stationary)
    if values.min() > 0:
        root = vectors * np.sqrt(values)
        inverse = vectors / np.sqrt(values)
        inner_values, inner_vectors = np.linalg.eigh(inverse.T @ white @ inverse)
        inner = (inner_vectors * np.maximum(inner_values, 1.0)) @ inner_vectors.T
        S = root @ inner @ root.T
    else:
        S = stationary + white
    try:
        stat = float(gamma @ np.linalg.solve(S, gamma))
    except np.linalg.LinAlgError:
        stat = float(gamma @ np.linalg.pinv(S) @ gamma)
    return Test(stat, k, 1.0, 0.0, lags)


def predictable(model: np.ndarray, y: np.ndarray, weights: np.ndarray, basis: Sequence[np.ndarray],
                t: np.ndarray, skip: Sequence[bool] = (), seed: int = SEED) -> tuple[list, list[dict], np.ndarray]:
    """Per coordinate j: the Wald test that the final residual of ``model`` (n, f, p; the
    inertial model and every effect in it) fitted to ``y`` (n, f) at ``weights`` (f,) is not
    predicted by the columns ``basis[j]`` (n, k) acting on j (:func:`motion_basis`), after
    generalised least squares with each coordinate's AR(p) filter. Returns (tests:
    wald.Test or None for a coordinate not tested, its ``lags`` the effective count of
    low-frequency observations nu of its reference F(k, nu); the residual's colour per
    coordinate; the final residual (n, f) unweighted).

    The filter: fitted (Yule-Walker, order by BIC) to the residual of the model plus every
    coordinate's basis (under the alternative, so a force that follows the motion is not
    taken for colour), then corrected for the bias of that fit (projecting the model out
    takes the noise's low frequencies with it: AR(1) 0.9 came out 0.86-0.88, and the filtered
    noise was 1.4 times stronger at the motion's frequencies than assumed, the tests
    rejecting 17-33 % at 5 %): AR_REPLICATES series of the fitted process are projected out
    of the same model and fitted again, and the mean shift taken off. What remains uncertain
    is the noise's power at low frequencies, S(0) = s^2 / (1 - sum a)^2; its spread over the
    replicates, as a chi-square's (var log S = 2 / nu), sets the test's reference F(k, nu)
    instead of chi-square: an effective number of low-frequency observations (NU_SHARE of
    it). The variance: :func:`_wald`. An equal-weighted cosine (EWC) long-run variance of the
    scores, tried first, rejected 37-48 % of nulls: the scores' low-frequency cosines are
    what projecting out a smooth model and basis removes."""
    from scipy.special import fdtrc

    from baseparams.identify.linear import RANK_TOL, WeightedLinearModel
    from baseparams.diagnose.wald import ABSORB_TOL, Test, orthonormal_basis, wilson_hilferty

    n, f, p = model.shape
    weights = np.asarray(weights, float)
    fit = WeightedLinearModel(model, y).fit(weights)
    residual = fit.unweighted_residual()
    embedded = []
    for j, columns in enumerate(basis if len(basis) == f else [basis[0]] * f):
        z = np.zeros((n, f, columns.shape[1]))
        z[:, j] = columns
        embedded.append(z)
    everything = np.concatenate([model] + embedded, axis=-1)
    alternative, Q = residual, fit.basis
    if n * f > 2 * everything.shape[-1]:
        complete = WeightedLinearModel(everything, y).fit(weights)
        alternative, Q = complete.unweighted_residual(), complete.basis
    coefficients, innovations = ar_fit(alternative)
    orders = [len(a) for a in coefficients]
    rng = np.random.default_rng(seed)
    sd = np.sqrt(np.maximum(innovations, 0.0))
    corrected = list(coefficients)
    for _ in range(AR_ROUNDS):          # the bias at the corrected filter, the spread there too
        simulated = _simulate_ar(rng, n, corrected, sd, AR_REPLICATES) * weights[None, :, None]
        flat = simulated.reshape(n * f, AR_REPLICATES)
        flat = flat - Q @ (Q.T @ flat)
        again, again_var = _fit_orders(flat.reshape(n, f, AR_REPLICATES) / weights[None, :, None], orders)
        corrected = [_stable(a - (np.mean(again[j], axis=0) - c)) if len(a) else a
                     for j, (a, c) in enumerate(zip(coefficients, corrected))]
    nus = np.full(f, np.inf)
    for j, a in enumerate(coefficients):
        if len(a) == 0:
            continue
        gain = np.maximum(1.0 - np.sum(again[j], axis=-1), 1.0 / MAX_LONG_RUN_GAIN)
        log_power = np.log(np.maximum(again_var[j], 1e-300)) - 2.0 * np.log(gain)
        spread = float(np.var(log_power, ddof=1))
        nus[j] = NU_SHARE * 2.0 / spread if spread > 0 else np.inf
    longest = max(orders, default=0)
    m = n - longest
    whitened = ar_filter(alternative, corrected, longest)
    level = np.sqrt(np.mean(whitened ** 2, axis=0))
    filtered_weights = np.where(level > 0, 1.0 / np.where(level > 0, level, 1.0), weights)
    X = (ar_filter(model, corrected, longest) * filtered_weights[None, :, None]).reshape(m * f, p)
    target = (ar_filter(y, corrected, longest) * filtered_weights).reshape(m * f)
    U = orthonormal_basis(X, RANK_TOL) if p else np.zeros((m * f, 0))
    r = target - U @ (U.T @ target)
    tests: list = []
    for j, z in enumerate(embedded):
        if j < len(skip) and skip[j]:
            tests.append(None)
            continue
        Z = (ar_filter(z, corrected, longest) * filtered_weights[None, :, None]).reshape(m * f, -1)
        B = orthonormal_basis(Z - U @ (U.T @ Z), ABSORB_TOL, reference=Z)
        if B.shape[1] == 0:
            tests.append(None)
            continue
        test = _wald(r, B, (m, f), U.shape[1])
        k = test.df
        nu = min(nus[j], m - int(np.ceil(U.shape[1] / f)) - k)
        pvalue = float(fdtrc(k, max(nu, 1.0), test.stat / k)) if test.tested else 1.0
        tests.append(Test(test.stat, k, pvalue, wilson_hilferty(test.stat, k), int(min(nu, 1e9))))
    return tests, colour(residual, t, corrected), residual
