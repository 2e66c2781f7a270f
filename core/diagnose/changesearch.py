"""The search for a change between recordings (:mod:`.change`): autoregressive whitening,
F tests, a forward search with its noise model re-estimated (Cochrane-Orcutt), and the checks
a named change must pass (it adds to the others, it predicts held-out blocks, it is not
negligible beside the noise). Every function works on the paired difference (n, f) and the
candidates' columns on its rows."""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.signal import lfilter
from scipy.special import fdtrc, ndtri

from baseparams.identify.linear import WeightedLinearModel
from baseparams.diagnose.lagged import fast_size, lagged_cross, spectra
from baseparams.diagnose.selection import Candidate
from baseparams.diagnose.wald import holm, orthonormal_basis, project_out, wilson_hilferty

# With nothing named, the rest of the difference must be significant at alpha / UNEXPLAINED_BAR
# to call it unexplained (the first step's Holm test already spent alpha on "nothing changed").
UNEXPLAINED_BAR = 10.0


# The longest autoregression fitted to a residual to whiten it for the test of what is left.
AR_ORDER = 20
# Singular values of a coordinate's share of the fitted directions below which they are left
# out of the projection's correction (noise_model).
COMPRESS = 0.05
# _bic_filter's order-recursive route: the lagged Gram matrix's condition number at most this (both
# routes then solve the same full-rank equations, to about this times eps).
BIC_CONDITION = 1e12
# A search's F tests count their noise level's degrees of freedom (effective_df) only below this
# p on the residual's: fewer only raise p, so above it they change no decision.
LAZY_P = 0.2


def ar_whitening(residual: np.ndarray, order: int = AR_ORDER) -> list[np.ndarray]:
    """Per coordinate, the prediction-error filter [1, -a_1, ..., -a_p] of an autoregression
    fitted to ``residual`` (n, f) by least squares, its order p <= ``order`` chosen by BIC.
    Why not AR(1), nor Yule-Walker: low-pass-filtered noise (a drive's or the logger's
    filter) is an ARMA process whose spectrum falls by decades; an AR(1) filter leaves it
    coloured and Yule-Walker's estimate is biased there, and a test of many directions on
    either was liberal (p < 1e-30 on pure noise)."""
    n, f = residual.shape
    filters = []
    for j in range(f):
        x = residual[:, j] - residual[:, j].mean()
        top = min(order, max(n // 20, 0))
        if top == 0 or not np.any(x):
            filters.append(np.array([1.0]))
            continue
        lagged = np.stack([x[top - k:n - k] for k in range(1, top + 1)], axis=1)
        target = x[top:]
        m = len(target)
        best, best_bic = np.array([1.0]), m * np.log(max(target @ target / m, 1e-300))
        for p in range(1, top + 1):
            a, *_ = np.linalg.lstsq(lagged[:, :p], target, rcond=None)
            error = target - lagged[:, :p] @ a
            bic = m * np.log(max(error @ error / m, 1e-300)) + p * np.log(m)
            if bic < best_bic:
                best, best_bic = np.concatenate([[1.0], -a]), bic
        filters.append(best)
    return filters


def ar_autocovariance(filter_: np.ndarray, variance: float, n: int) -> np.ndarray:
    """The autocovariances at lags 0..n-1 of the autoregression whose prediction-error filter
    is ``filter_`` [1, -a_1, ...] and innovation variance ``variance`` (its spectrum's inverse
    FFT on a grid at least 4 times longer: the aliasing of a slowly decaying one is negligible)."""
    size = 1 << int(np.ceil(np.log2(max(4 * n, 4096))))
    spectrum = variance / np.maximum(np.abs(np.fft.rfft(filter_, size)) ** 2, 1e-300)
    return np.fft.irfft(spectrum, size)[:n]


def toeplitz_times(autocovariance: np.ndarray, x: np.ndarray, spectra: np.ndarray | None = None) -> np.ndarray:
    """The symmetric Toeplitz matrix of ``autocovariance`` (n,) times ``x`` (n, k), by FFT
    (circulant embedding). ``spectra``: :func:`toeplitz_spectra` of x, when made already (the
    noise model multiplies the same columns in every round)."""
    n = len(autocovariance)
    size = fast_size(2 * n - 1)
    column = np.concatenate([autocovariance, np.zeros(size - 2 * n + 1), autocovariance[:0:-1]])
    if spectra is None:
        spectra = toeplitz_spectra(x)
    return np.fft.irfft(np.fft.rfft(column)[None, :] * spectra, size, axis=1)[:, :n].T


def toeplitz_spectra(x: np.ndarray) -> np.ndarray:
    """The transforms of x's columns (n, k) that :func:`toeplitz_times` multiplies: along
    contiguous rows (the same transforms, 2.4 times faster than down the columns)."""
    return np.fft.rfft(np.ascontiguousarray(x.T), fast_size(2 * len(x) - 1), axis=1)


def _bic_filter(gram: np.ndarray, rows: int) -> tuple[np.ndarray, float]:
    """(prediction-error filter, innovation variance) of the autoregression whose order
    (<= the lagged cross products ``gram``'s size - 1) has the least BIC, by least squares.
    Every order's fit from one Cholesky factor L of the lagged Gram matrix: order p's normal
    equations are its leading p x p block, whose factor is L's, so z = L^-1 g holds every
    order's explained sum of squares as a prefix sum of z^2 (order-recursive least squares).
    Why: a least-squares solve per order was a twentieth of a diagnosis between recordings.
    A lagged Gram matrix worse conditioned than BIC_CONDITION is left to the solve per order
    (least squares' own cut, eps 20 times the largest singular value, is then near)."""
    top = len(gram) - 1
    values = np.linalg.eigvalsh(gram[1:, 1:]) if top > 0 else np.zeros(1)
    if values[0] > values[-1] / BIC_CONDITION:           # every leading block as well conditioned (interlacing)
        try:
            factor = np.linalg.cholesky(gram[1:, 1:])
        except np.linalg.LinAlgError:
            factor = None
        if factor is not None:
            z = solve_triangular(factor, gram[1:, 0], lower=True, check_finite=False)
            explained = np.concatenate([[0.0], np.cumsum(z * z)])
            variances = np.maximum((float(gram[0, 0]) - explained) / rows, 1e-300)
            bics = rows * np.log(variances) + np.arange(top + 1) * np.log(rows)
            order = int(np.argmin(bics))
            coefficients = solve_triangular(factor[:order, :order].T, z[:order], lower=False, check_finite=False)
            return np.concatenate([[1.0], -coefficients]), float(variances[order])
    best_bic, best = np.inf, (np.array([1.0]), max(float(gram[0, 0]) / rows, 1e-300))
    for p in range(len(gram)):
        a = np.linalg.lstsq(gram[1:p + 1, 1:p + 1], gram[1:p + 1, 0], rcond=None)[0] if p else np.zeros(0)
        variance = max(float(gram[0, 0] - a @ gram[1:p + 1, 0]) / rows, 1e-300)
        bic = rows * np.log(variance) + p * np.log(rows)
        if bic < best_bic:
            best_bic, best = bic, (np.concatenate([[1.0], -a]), variance)
    return best


def _corrected(plain: np.ndarray, taken: np.ndarray, rows: int, previous: tuple[np.ndarray, float]
               ) -> tuple[np.ndarray, float]:
    """:func:`_bic_filter` of the cross products ``plain`` with what the projection ``taken``
    added back; ``previous`` where that adds more than nine times the residual's sum of
    squares (the projection cannot have taken 90 % of the noise), leaves no innovation
    variance, or makes the autoregression non-stationary: at a root near one the expected
    loss diverges (seen on the PUMA, 800 samples, a 45 g payload)."""
    gram = plain + taken
    if gram[0, 0] > 10.0 * plain[0, 0]:
        return previous
    filter_, variance = _bic_filter(gram, rows)
    if variance <= 1e-9 * plain[0, 0] / rows or (len(filter_) > 1 and np.max(np.abs(np.roots(filter_))) >= 0.999):
        return previous
    return filter_, variance


def noise_filters(signal: np.ndarray, design: np.ndarray, order: int = AR_ORDER, rounds: int = 3,
                  unit: bool = True) -> list[np.ndarray]:
    """:func:`noise_model`'s filters alone."""
    return noise_model(signal, design, order, rounds, unit)[0]


def noise_model(signal: np.ndarray, design: np.ndarray, order: int = AR_ORDER, rounds: int = 3,
                unit: bool = True) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    """Per coordinate, the prediction-error filter of an autoregression (order <= ``order`` by
    BIC, least squares) of the noise that ``signal`` (n, f) leaves once ``design`` (n, f, k)
    is fitted to it (least squares over the stacked rows), divided by its innovation SD so
    that every coordinate's whitened noise has unit variance (``unit``; else the plain
    prediction-error filter). Each coordinate's lagged cross
    products of that residual are corrected by what the projection takes from them in
    expectation under the autoregressions (:func:`_projection_bias`), ``rounds`` times from
    the plain fit. Why the correction: a residual fitted by many slow columns has lost the
    noise's low frequencies, and an autoregression fitted to it is too weak there (AR(1) 0.9
    on 1000 samples: 0.85 with 20 slow columns, 0.897 corrected); tests of slow columns
    whitened by it were liberal (a generated chain with nothing changed was called changed in
    3 of 20 datasets: a viscous friction at raw p 2e-6, 0.0013 under the true whitening).
    Returned with each coordinate's (plain filter, covariance of its coefficients a_1..a_p:
    the innovation variance times the inverse of the corrected lagged Gram matrix), for
    :func:`effective_df`. Why the unit innovation variance: an F test pools the coordinates' whitened rows, and on a
    UR5 under low-passed noise with torques quantised to 0.01 N m the whitened noise of the
    shoulder was far below the wrist's: a friction drift there (t = 37 for a perfect-model fit
    with the true noise) went unseen in 20 of 20 datasets."""
    n, f = signal.shape
    Q = orthonormal_basis(design.reshape(n * f, -1), 1e-9) if design.shape[-1] else np.zeros((n * f, 0))
    residual = signal - (Q @ (Q.T @ signal.reshape(-1))).reshape(n, f)
    Q = Q.reshape(n, f, -1)
    top = min(order, max(n // 20, 0))
    rows = n - top
    plain = []
    for j in range(f):
        x = residual[:, j:j + 1]
        plain.append(lagged_cross(x, x, top))
    fitted = [_bic_filter(g, rows) for g in plain]
    grams = list(plain)
    # each coordinate's rows of Q as U S V^T, directions of singular value <= COMPRESS left out
    # (they hold under 0.25 % of a direction each): Q_j^T Sigma Q_j and the lagged sums then
    # run over those few columns (a PUMA's 61 directions: 10-34 per coordinate), whose spectra
    # serve every round
    # (from the eigenvectors of Q_j^T Q_j = V S^2 V^T, U S = Q_j V: S is at most 1 and only S > COMPRESS
    # is kept, far above what the Gram matrix resolves)
    parts, transforms, circulant = [], [], []
    for j in range(f if Q.shape[-1] else 0):
        Qj = Q[:, j]
        squares, V = np.linalg.eigh(Qj.T @ Qj)
        keep = np.flatnonzero(squares > COMPRESS ** 2)[::-1]           # largest first
        parts.append((Qj @ V[:, keep], V[:, keep].T))
        transforms.append(spectra(parts[-1][0], top))
        circulant.append(toeplitz_spectra(parts[-1][0]))
    for _ in range(rounds if Q.shape[-1] else 0):
        Y = [toeplitz_times(ar_autocovariance(c, v, n), US, spectrum)
             for (c, v), (US, _), spectrum in zip(fitted, parts, circulant)]
        W = sum(Vt.T @ (US.T @ y) @ Vt for (US, Vt), y in zip(parts, Y))       # Q^T Sigma Q
        again = []
        for j, ((US, Vt), y) in enumerate(zip(parts, Y)):
            # L(Y, US) + L(Y, US)^T - L(US M, US) with M = Vt W Vt^T symmetric, so L(US M, US) is
            # too: one lagged product X = L(Y - US M / 2, US) and taken = X + X^T
            half = lagged_cross(y - US @ (Vt @ W @ Vt.T) / 2.0, US, top, spectrum_b=transforms[j])
            taken = half + half.T
            again.append(_corrected(plain[j], taken, rows, fitted[j]))
            if again[-1] is not fitted[j]:
                grams[j] = plain[j] + taken
        stable = all(len(c) == len(d) and np.allclose(c, d, atol=1e-4) for (c, _), (d, _) in zip(again, fitted))
        fitted = again
        if stable:
            break
    spread = []
    for (c, v), gram in zip(fitted, grams):
        p = len(c) - 1
        spread.append((c, v * np.linalg.pinv(gram[1:p + 1, 1:p + 1]) if p else np.zeros((0, 0))))
    return [c / np.sqrt(v) if unit else c for c, v in fitted], spread


def effective_df(spread: list[tuple[np.ndarray, np.ndarray]], whitened: np.ndarray,
                 slopes: tuple[int, list[np.ndarray | None]] | None = None) -> float:
    """The degrees of freedom of the noise level that F tests of the columns ``whitened``
    (m, f, k: through :func:`noise_model`'s filters) divide by: 2 / the variance of the
    relative error of the whitened noise's power over their spectrum, from the errors of the
    autoregressions' coefficients (``spread``; the delta method: d log S(w) / d a_m =
    2 Re(e^{-i w m} / A(w))), coordinates weighted by the columns' energy on each. Why: the
    noise's power at the low frequencies where a robot's columns live is fixed by few
    effective samples (AR(1) 0.9 on 1000 samples: S(0) to 28 %, about 26 degrees of
    freedom), and an F test against thousands called changes that the true noise model puts
    at p 0.008 (a gain on a UR5's base, p 4e-4). ``slopes``: :func:`log_spectrum_slopes` of
    ``spread``, when made already."""
    m, f, _ = whitened.shape
    scale = float(np.max(np.abs(whitened), initial=0.0))
    if not np.isfinite(scale) or scale == 0.0:
        return np.inf
    power = np.zeros((m // 2 + 1, f))                              # (bins, f): only shares matter
    for j in range(f):                                             # a column that is zero there adds nothing
        live = np.flatnonzero(np.any(whitened[:, j] != 0, axis=0))
        if len(live):
            power[:, j] = (np.abs(np.fft.rfft(whitened[:, j, live] / scale, axis=0)) ** 2).sum(axis=1)
    energy = power.sum(axis=0)
    total = float(energy.sum())
    if total <= 0:
        return np.inf
    if slopes is None or slopes[0] != m:
        slopes = log_spectrum_slopes(spread, m)
    variance = 0.0
    for j, ((c, cov), slope) in enumerate(zip(spread, slopes[1])):
        if slope is None or energy[j] <= 0:
            continue
        mean = power[:, j] @ slope / energy[j]
        variance += (energy[j] / total) ** 2 * float(mean @ cov @ mean)
    return 2.0 / variance if variance > 0 else np.inf


def log_spectrum_slopes(spread: list[tuple[np.ndarray, np.ndarray]], m: int
                        ) -> tuple[int, list[np.ndarray | None]]:
    """(m, per coordinate d log S(w) / d a (bins, p) at the m-point FFT's frequencies, None
    without an autoregression): the part of :func:`effective_df` that does not depend on the
    tested columns, made once per noise model (a search tests each candidate with it: remade
    for each, it was a tenth of a diagnosis between recordings)."""
    omega = 2 * np.pi * np.fft.rfftfreq(m)
    out: list[np.ndarray | None] = []
    for c, _ in spread:
        p = len(c) - 1
        if p == 0:
            out.append(None)
            continue
        lags = np.exp(-1j * np.outer(omega, np.arange(1, p + 1)))
        out.append(2 * np.real(lags / np.fft.rfft(c, 2 * (len(omega) - 1) if m % 2 == 0 else m)[:len(omega), None]))
    return m, out


def _filtered(filters: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """x (n, f) or (n, f, c) through each coordinate's filter (its first rows dropped). Only
    the columns that are not zero on a coordinate are filtered there: most candidates act on
    one coordinate or a few (the PUMA's: 35-45 % of a coordinate's columns are zero)."""
    start = max(len(a) for a in filters) - 1
    if x.ndim == 2:
        return np.stack([lfilter(a, [1.0], x[:, j], axis=0) for j, a in enumerate(filters)], axis=1)[start:]
    # laid out as lfilter's own output stacked (columns outermost): the products downstream round alike
    out = np.zeros((x.shape[2], x.shape[0], x.shape[1])).transpose(1, 2, 0)
    for j, a in enumerate(filters):
        live = np.flatnonzero(np.any(x[:, j] != 0, axis=0))
        if len(live) == x.shape[2]:
            out[:, j] = lfilter(a, [1.0], x[:, j], axis=0)
        elif len(live):
            out[:, j, live] = lfilter(a, [1.0], x[:, j, live], axis=0)
    return out[start:]


def _filtered_each(filters: list[np.ndarray], blocks: list[np.ndarray], weights: np.ndarray) -> list[np.ndarray]:
    """:func:`_filtered` of each block (n, f, k_i) weighted by ``weights`` (f,), in one pass
    (each column is filtered alone either way: one lfilter call per candidate and coordinate
    cost more than the filtering)."""
    if not blocks:
        return []
    widths = [b.shape[-1] for b in blocks]
    out = _filtered(filters, np.concatenate(blocks, axis=-1) * weights[None, :, None])
    return np.split(out, np.cumsum(widths)[:-1], axis=-1)


def rest_test(residual: np.ndarray, columns: np.ndarray, model: np.ndarray, weights: np.ndarray,
              noise: np.ndarray | None = None, design: np.ndarray | None = None, unit: bool = True,
              whitening: tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]] | None = None) -> dict:
    """Whether what is left (n, f) is predictable from ``columns`` (n, f, k), all at once,
    beyond ``model`` (n, f, p): an F test after each coordinate's residual and columns pass
    its autoregressive whitening (:func:`noise_model`, fitted to ``noise``, default the
    residual itself, as left by a fit of ``design``, default ``model``), rows weighted by
    ``weights``; ``unit``: each coordinate whitened to unit variance; the noise level's
    degrees of freedom :func:`effective_df` when fewer than the residual's. Give ``noise``
    when the residual holds the structure under test: an autoregression fitted to it learns
    that structure as noise (a payload tested beside another body: p = 0.46). ``whitening``:
    that noise model (:func:`noise_model`'s output), when made already for the same noise,
    design, weights and ``unit``."""
    design = model if design is None else design
    filters, spread = whitening if whitening is not None else \
        noise_model((residual if noise is None else noise) * weights[None, :], design * weights[None, :, None], unit=unit)
    r = _filtered(filters, residual * weights[None, :])
    X = _filtered(filters, columns * weights[None, :, None])
    noise_df = effective_df(spread, X)
    m, f = r.shape
    b = r.reshape(-1)
    A = before = X.reshape(m * f, -1)
    used = 0
    if model.shape[-1]:
        M = orthonormal_basis(_filtered(filters, model * weights[None, :, None]).reshape(m * f, -1), 1e-9)
        used = M.shape[1]
        A = project_out(A, M)
        b = project_out(b[:, None], M)[:, 0]
    # directions cut against the columns before the projection: a column inside the model is
    # left as rounding, which measured against itself counted as a direction in some runs and
    # not in others (df 55 to 57 on the PUMA, the statistic over a 6 % range, for relative
    # changes of 1e-15 in the columns); so cut, df 51 and the statistic stable to 6e-14
    basis = orthonormal_basis(A, 1e-7, reference=before)
    k = basis.shape[1]
    dof = m * f - k - used
    if k == 0 or dof <= 0:
        return {"stat": 0.0, "df": 0, "pvalue": 1.0}
    explained = basis.T @ b
    rest = float(b @ b - explained @ explained)
    stat = float(explained @ explained) / k / max(rest / dof, 1e-300)
    return {"stat": stat, "df": int(k), "pvalue": float(fdtrc(k, min(dof, noise_df), stat)),
            "ar_order": [len(a) - 1 for a in filters]}


@dataclass
class Search:
    """The forward search's outcome: ``added`` candidate indices in the order they entered,
    ``ambiguous`` head -> the rivals entered with it (none adds over the other), each
    entered index's test at its step (``tests``: {"pvalue", "pvalue_holm", "z"}), the
    first step's Holm-adjusted p values, each step's strongest candidates, and the noise
    ``weights`` (f,) the tests used."""
    candidates: list[Candidate]
    added: list[int]
    ambiguous: dict[int, list[int]]
    tests: dict[int, dict]
    first: np.ndarray
    steps: list[dict]
    weights: np.ndarray
    unit: bool = True          # each coordinate's whitened noise at unit variance (noise_filters)

    @property
    def in_model(self) -> list[int]:
        return self.added + [j for rivals in self.ambiguous.values() for j in rivals]

    def group(self, head: int) -> list[int]:
        return [head] + self.ambiguous.get(head, [])


def _f_test(residual: np.ndarray, basis: np.ndarray, rest: float, dof: int) -> tuple[float, int, float]:
    """(F, directions, p): the orthonormal ``basis`` (rows, k), orthogonal to the model,
    against the model's ``residual`` (rows,) whose sum of squares is ``rest``."""
    k = basis.shape[1]
    if k == 0:
        return 0.0, 0, 1.0
    explained = basis.T @ residual
    ss = float(explained @ explained)
    left = max(rest - ss, 1e-300)
    df = dof - k
    if df <= 0:
        return 0.0, 0, 1.0
    stat = (ss / k) / (left / df)
    return stat, k, float(fdtrc(k, df, stat))


def _f_test_beyond(residual: np.ndarray, basis: np.ndarray, model: np.ndarray, rest: float, dof: int,
                   noise_df: float = np.inf) -> tuple[float, int, float]:
    """:func:`_f_test` of the orthonormal ``basis``'s directions beyond the orthonormal
    ``model`` (``residual`` orthogonal to it), from k x k products: the directions beyond are
    B (I - M M^T), whose Gram matrix is I - (B^T M)(B^T M)^T; what they explain of the
    residual is g^T G^+ g with g = B^T r (no tall matrix factorised: a step tests every
    candidate, and their SVDs were most of the search's time). ``noise_df``: the noise
    level's own degrees of freedom in these directions (:func:`effective_df`), when fewer
    than the residual's."""
    k = basis.shape[1]
    if k == 0:
        return 0.0, 0, 1.0
    g = basis.T @ residual
    if model.shape[1]:
        overlap = basis.T @ model
        gram = np.eye(k) - overlap @ overlap.T
    else:
        gram = np.eye(k)
    values, vectors = np.linalg.eigh(gram)
    keep = values > 1e-14 * max(float(values.max(initial=0.0)), 1e-300)   # singular values 1e-7 of the largest
    kept = int(np.sum(keep))
    df = dof - kept
    if kept == 0 or df <= 0:
        return 0.0, 0, 1.0
    projected = vectors[:, keep].T @ g
    ss = float(np.sum(projected ** 2 / values[keep]))
    stat = (ss / kept) / (max(rest - ss, 1e-300) / df)
    return stat, kept, float(fdtrc(kept, min(df, noise_df), stat))


def search(candidates: list[Candidate], y: np.ndarray, alpha: float, max_steps: int = 12, rounds: int = 3,
           unit: bool = True) -> Search:
    """:func:`search_once`, its noise model (weights and autoregressions) estimated again from
    the residual of the model it chose, until the choice repeats (Cochrane-Orcutt). Why: the
    first noise model comes from the residual of every candidate at once, which the smooth
    columns have stripped of low frequencies; on low-passed noise that autoregression
    under-whitened, and five changes followed a true payload into the search."""
    n, f = y.shape
    everything = np.concatenate([c.columns for c in candidates], axis=-1) if candidates else np.zeros((n, f, 0))
    found = search_once(candidates, y, alpha, max_steps, everything, unit=unit)
    for _ in range(rounds - 1):
        chosen = [candidates[j].columns for j in found.in_model]
        again = search_once(candidates, y, alpha, max_steps, np.concatenate([np.zeros((n, f, 0))] + chosen, axis=-1),
                            unit=unit)
        if again.added == found.added and again.ambiguous == found.ambiguous:
            return again
        found = again
    return found


def search_once(candidates: list[Candidate], y: np.ndarray, alpha: float, max_steps: int,
                noise_model_columns: np.ndarray, first: np.ndarray | None = None, unit: bool = True) -> Search:
    """Forward selection of the change's candidates by F tests on data whitened by each
    coordinate's autoregression (:func:`noise_model`, fitted to the residual of
    ``noise_model_columns``, every candidate at first: the residual of none would hold the
    change, which an autoregression learns as noise), rows weighted by each coordinate's noise
    level, each candidate's F against its noise level's degrees of freedom (:func:`effective_df`). Each step tests every
    candidate beyond the model, Holm-corrects, adds the most significant (normal
    equivalent z) and, with it, the rivals neither of which adds over the other at ``alpha``
    (an ambiguous group). Why not the diagnosis' own search (HAC Wald tests, AR(1)
    whitening): on low-passed noise its size was not held, and its tests of sparse
    directions took four fifths of the time."""
    n, f = y.shape
    complete = WeightedLinearModel(noise_model_columns, y).fit() if noise_model_columns.shape[-1] else None
    residual = y if complete is None else y - noise_model_columns @ complete.coefficients
    noise = np.sqrt(np.mean(residual ** 2, axis=0))
    weights = 1.0 / np.where(noise > 0, noise, 1.0)
    filters, spread = noise_model(residual * weights[None, :], noise_model_columns * weights[None, :, None], unit=unit)
    wy = _filtered(filters, y * weights[None, :]).reshape(-1)
    shaped = _filtered_each(filters, [c.columns for c in candidates], weights)
    slopes = log_spectrum_slopes(spread, len(wy) // f)
    noise_dfs: dict[int, float] = {}       # counted where they can change a decision (p < LAZY_P)
    columns = [c.reshape(len(wy), -1) for c in shaped]
    rows = len(wy)
    model = np.zeros((rows, 0))
    added: list[int] = []
    ambiguous: dict[int, list[int]] = {}
    tests: dict[int, dict] = {}
    steps: list[dict] = []
    gate = first
    first = np.ones(len(candidates))
    bases = [orthonormal_basis(c, 1e-7) for c in columns]
    while len(added) < max_steps:
        r = wy - model @ (model.T @ wy)
        rest = float(r @ r)
        dof = rows - model.shape[1]
        inside = set(added) | {j for rivals in ambiguous.values() for j in rivals}
        outcome = {}
        for i, basis in enumerate(bases):
            if i in inside:
                continue
            stat, k, pvalue = _f_test_beyond(r, basis, model, rest, dof)
            if k and pvalue < LAZY_P:         # fewer degrees of freedom only raise p
                if i not in noise_dfs:
                    noise_dfs[i] = effective_df(spread, shaped[i], slopes)
                pvalue = float(fdtrc(k, min(dof - k, noise_dfs[i]), stat))
            if k:       # ranked by p: the normal equivalent of the F's own p (its noise df differ)
                outcome[i] = (pvalue, float(ndtri(1.0 - pvalue)) if pvalue > 1e-15 else
                              max(float(-ndtri(pvalue)) if pvalue > 0 else 0.0, wilson_hilferty(stat * k, k)))
        if not outcome:
            break
        order = list(outcome)
        adjusted = dict(zip(order, holm([outcome[i][0] for i in order])))
        if not steps:
            for i, value in adjusted.items():
                first[i] = value
        strongest = sorted(order, key=lambda i: -outcome[i][1])
        steps.append({"tests": [{"candidate": candidates[i].label, "pvalue": outcome[i][0],
                                 "pvalue_holm": float(adjusted[i]), "z": outcome[i][1]} for i in strongest[:10]],
                      "chosen": None})
        significant = [i for i in strongest if adjusted[i] <= alpha]
        if not significant:
            break
        winner = significant[0]
        steps[-1]["chosen"] = candidates[winner].label

        def beyond(i: int) -> np.ndarray:
            return orthonormal_basis(project_out(bases[i], model), 1e-7) if model.shape[1] else bases[i]

        rivals = []
        won = beyond(winner)
        others = {j: beyond(j) for j in significant[1:]}
        if others:
            with_winner = _fitted(wy, np.concatenate([model, won], axis=1))
            for j, other in others.items():
                with_rival = np.concatenate([model, other], axis=1)
                if not _adds(wy, with_winner, other, alpha) and not _adds(wy, _fitted(wy, with_rival), won, alpha):
                    rivals.append(j)
        added.append(winner)
        tests[winner] = {"pvalue": outcome[winner][0], "pvalue_holm": float(adjusted[winner]), "z": outcome[winner][1]}
        if rivals:
            ambiguous[winner] = rivals
        model = orthonormal_basis(np.concatenate([model, won] + [others[j] for j in rivals], axis=1), 1e-9)
    # the first step's p values under the first noise model: the gate's, which the later rounds
    # do not move (they are about the named changes, not about whether anything changed)
    return Search(candidates, added, ambiguous, tests, first if gate is None else gate, steps, weights, unit)


def _fitted(wy: np.ndarray, model: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(an orthonormal basis of ``model``, the residual of ``wy`` off it), for :func:`_adds`
    (made once for a step's winner, not again for each rival)."""
    basis = orthonormal_basis(model, 1e-9)
    return basis, wy - basis @ (basis.T @ wy)


def _adds(wy: np.ndarray, model: tuple[np.ndarray, np.ndarray], extra: np.ndarray, alpha: float) -> bool:
    """Whether ``extra``'s directions add to those of ``model`` (:func:`_fitted`) at ``alpha``
    (whitened rows)."""
    basis, r = model
    beyond = orthonormal_basis(project_out(extra, basis), 1e-7)
    _, k, pvalue = _f_test(r, beyond, float(r @ r), len(wy) - basis.shape[1])
    return k > 0 and pvalue <= alpha


def named_changes(candidates: list[Candidate], difference: np.ndarray, alpha: float, notes: list[str],
                  unit: bool = True) -> tuple[Search, set, dict]:
    """The search and what survives its checks (the module docstring's steps 1-5): the
    search, the kept candidates' indices, and the gate's test. ``unit``: each coordinate's
    whitened noise at unit variance (:func:`noise_filters`): right where the difference is
    noise (paired runs), not where it is the shared model's error (other motions)."""
    f = difference.shape[1]
    empty = np.zeros((len(difference), f, 0))
    spread = np.sqrt(np.mean(difference ** 2, axis=0))
    # closed testing: without the gate, the diagnosis' own Wald tests called 4 of 20 AR(1) nulls changed
    gate = rest_test(difference, np.concatenate([c.columns for c in candidates], axis=-1), empty,
                     1.0 / np.where(spread > 0, spread, 1.0), unit=unit)
    # ... or each candidate alone, its noise model the residual of the model the search chose
    # (Cochrane-Orcutt: from the residual of every candidate, the single tests called 1 in 20
    # low-passed nulls of 800 samples changed; from the difference itself, a change is taken
    # for noise and a 30 % friction drift went unseen)
    found = search(candidates, difference, alpha, unit=unit)
    if gate["pvalue"] > alpha / 2 and float(np.min(found.first, initial=1.0)) > alpha / 2:
        found = Search(candidates, [], {}, {}, found.first, found.steps[:1], found.weights, unit)
    kept = _confirmed(found, difference, alpha, notes)
    kept = _predictive(found, difference, kept, notes)
    return found, _large_enough(found, difference, kept, notes), gate


# What a named change adds to the others' fitted force must reach this fraction of one run's
# noise SD (the difference's residual SD over sqrt 2) on some coordinate: "nothing changed"
# says the runs agree within their noise, and a change far below it is of no consequence to a
# model of the robot.
MIN_CHANGE_TO_NOISE = 0.5


def _large_enough(chosen: Search, y: np.ndarray, kept: set, notes: list[str]) -> set:
    """The kept groups whose naming moves the fitted force (all kept groups against the
    others refitted without it: RMS per coordinate) by MIN_CHANGE_TO_NOISE of one run's noise
    on some coordinate, the smallest taken out first. Why: on a real repeat of one motion (a
    Kinova Gen3's currents) a friction change on joint_6 that predicted held-out blocks took
    the difference from 0.261 to 0.259. Why what it adds, not its own force fitted with the
    others: a candidate nearly collinear with a true change borrows a large force from it
    and gives it back (an offset of 0.12 +- 0.04 N m on the arm's pitch, 6.6 noise SDs,
    fitted beside a true load on the back link whose gravity columns it imitates, moved the
    fitted force by 0.41 of them; named at Holm p 0.049 in 1 of 20 seeds on every link,
    issue 49)."""
    weights = chosen.weights
    groups = {i: chosen.group(i) for i in chosen.added if i in kept}
    while groups:
        members = [j for m in groups.values() for j in m]
        X = np.concatenate([chosen.candidates[j].columns for j in members], axis=-1)
        fitted = X @ WeightedLinearModel(X, y).fit(weights).coefficients
        noise = np.sqrt(np.mean((y - fitted) ** 2, axis=0) / 2.0)
        ratio = {}
        for head, group in groups.items():
            others = [chosen.candidates[j].columns for j in members if j not in group]
            without = 0.0
            if others:
                rest = np.concatenate(others, axis=-1)
                without = rest @ WeightedLinearModel(rest, y).fit(weights).coefficients
            size = np.sqrt(np.mean((fitted - without) ** 2, axis=0))
            ratio[head] = float(np.max(size / np.where(noise > 0, noise, np.inf)))
        smallest = min(ratio, key=lambda h: ratio[h])
        if ratio[smallest] >= MIN_CHANGE_TO_NOISE:
            break
        notes.append(f"{chosen.candidates[smallest].label} passed the tests but what it adds to the fitted force is "
                     f"{ratio[smallest]:.2g} of one run's noise (below {MIN_CHANGE_TO_NOISE:g}): too small to matter, "
                     "not named")
        del groups[smallest]
    return {j for m in groups.values() for j in m}


def _confirmed(chosen: Search, y: np.ndarray, alpha: float, notes: list[str]) -> set:
    """The final model's groups (a named change with its ambiguous companions) that each add
    significantly to the others by the whitened F test of :func:`rest_test` at alpha over
    the number of groups (Bonferroni), the weakest taken out first until all do. Why: the
    search's Wald tests, on few effective samples of strongly coloured noise, named a second
    body and a Coulomb friction beside a true payload (the PUMA, 800 samples, AR(1) 0.9)."""
    weights = chosen.weights
    groups = {i: chosen.group(i) for i in chosen.added}
    while len(groups) > 1:
        everything = np.concatenate([chosen.candidates[j].columns for m in groups.values() for j in m], axis=-1)
        noise = y - everything @ WeightedLinearModel(everything, y).fit(weights).coefficients
        # one noise model for every group's test: the same noise, design and weights
        whitening = noise_model(noise * weights[None, :], everything * weights[None, :, None], unit=chosen.unit)
        pvalues = {}
        for head, members in groups.items():
            others = [j for h, m in groups.items() if h != head for j in m]
            model = np.concatenate([chosen.candidates[j].columns for j in others], axis=-1)
            fit = WeightedLinearModel(model, y).fit(weights)
            residual = y - model @ fit.coefficients
            columns = np.concatenate([chosen.candidates[j].columns for j in members], axis=-1)
            pvalues[head] = rest_test(residual, columns, model, weights, noise, everything, chosen.unit,
                                      whitening)["pvalue"]
        weakest = max(pvalues, key=lambda h: pvalues[h])
        if pvalues[weakest] <= alpha / len(groups):
            break
        notes.append(f"{chosen.candidates[weakest].label} entered the search but does not add to the other changes "
                     f"once the noise's colour is whitened (p = {pvalues[weakest]:.2g} > {alpha / len(groups):.2g}): "
                     "not named")
        del groups[weakest]
    return {j for members in groups.values() for j in members}


# Contiguous blocks of the paired rows for the out-of-sample check of each named change.
BLOCKS = 5


def held_out_gain(y: np.ndarray, X: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per contiguous block (BLOCKS), how much ``X`` (n, f, k), fitted on the other blocks,
    lowers the block's weighted sum of squares of ``y`` (n, f) (negative: it predicts worse
    than nothing)."""
    n = len(y)
    edges = np.linspace(0, n, BLOCKS + 1).astype(int)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        train = np.r_[0:a, b:n]
        fit = WeightedLinearModel(X[train], y[train]).fit(weights)
        before = float(np.sum((y[a:b] * weights) ** 2))
        out.append(before - float(np.sum(((y[a:b] - X[a:b] @ fit.coefficients) * weights) ** 2)))
    return np.array(out)


def predicts(gain: np.ndarray) -> bool:
    """Whether held-out gains per block say the columns predict: in total and in a majority."""
    return bool(np.sum(gain) > 0 and np.sum(gain > 0) > len(gain) // 2)


def _predictive(chosen: Search, y: np.ndarray, kept: set, notes: list[str]) -> set:
    """The kept groups that predict held-out blocks: each contiguous block of the difference
    predicted from the others with and without the group; a group is kept when it lowers the
    weighted held-out error in total and in a majority of the blocks, the worst taken out
    first until all do. Why: on a real pair of runs of one motion (a Kinova Gen3's currents,
    1 kHz, the difference 0.37 NRMS), twelve changes passed the whitened tests and together
    took the difference to 0.365: structure of the current's ripple, not a change."""
    weights = chosen.weights
    groups = {i: chosen.group(i) for i in chosen.added
              if i in kept}
    n = len(y)
    edges = np.linspace(0, n, BLOCKS + 1).astype(int)

    def held_out(members: list[int]) -> np.ndarray:
        if not members:
            return np.array([float(np.sum((y[a:b] * weights) ** 2)) for a, b in zip(edges[:-1], edges[1:])])
        X = np.concatenate([chosen.candidates[j].columns for j in members], axis=-1)
        out = []
        for a, b in zip(edges[:-1], edges[1:]):
            train = np.r_[0:a, b:n]
            fit = WeightedLinearModel(X[train], y[train]).fit(weights)
            out.append(float(np.sum(((y[a:b] - X[a:b] @ fit.coefficients) * weights) ** 2)))
        return np.array(out)

    while groups:
        every = [j for m in groups.values() for j in m]
        full = held_out(every)
        gains = {}
        for head, members in groups.items():
            without = held_out([j for j in every if j not in members])
            gains[head] = without - full
        worst = min(groups, key=lambda h: (np.sum(gains[h] > 0), np.sum(gains[h])))
        gain = gains[worst]
        if predicts(gain):
            break
        notes.append(f"{chosen.candidates[worst].label} passed the tests but does not predict held-out blocks of the "
                     f"difference (better in {int(np.sum(gain > 0))} of {BLOCKS}): not named")
        del groups[worst]
    return {j for m in groups.values() for j in m}
