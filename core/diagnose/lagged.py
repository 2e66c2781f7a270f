"""Lagged cross products of two multichannel series over the rows an autoregression of order
up to ``top`` is fitted on, for :func:`.changesearch.noise_model`: all 2 top + 1 lags from one
FFT per column, the few rows near the ends that a lag leaves out taken off directly.

Why: the noise model corrects each coordinate's lagged Gram matrix by what the projection on
the fitted columns takes from it, the lagged products of 10-34 columns of 5,000 rows at 41
lags; one running sum per lag (a numpy call per lag and product) was a seventh of a diagnosis
between recordings (0.50 CPU s on the PUMA's 5,000 samples; 0.06 with these and one product a
round instead of two)."""

import numpy as np


def fast_size(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n: a length numpy's FFT transforms fast."""
    best = 1 << max(int(n - 1).bit_length(), 0)
    power5 = 1
    while power5 < best:
        power35 = power5
        while power35 < best:
            size = power35
            while size < n:
                size *= 2
            best = min(best, size)
            power35 *= 3
        power5 *= 5
    return best


def spectra(x: np.ndarray, top: int) -> np.ndarray:
    """The columns of ``x`` (n, k) transformed as :func:`lagged_cross` needs them (zero-padded
    to at least n + top: the lags do not wrap around), for a series used in several calls."""
    return np.fft.rfft(x, fast_size(len(x) + top), axis=0)


def lagged_cross(A: np.ndarray, B: np.ndarray, top: int, spectrum_b: np.ndarray | None = None) -> np.ndarray:
    """(top + 1, top + 1): entry (i, l) the sum over t = top .. n - 1 of A[t - i] . B[t - l]
    (rows of A and B (n, k) as vectors). The sums over every row pair at lag h = l - i come
    from the columns' spectra (``spectrum_b``: :func:`spectra` of B when made already; B
    given as A itself is transformed once); the at most ``top`` rows at each end that entry
    (i, l) leaves out are then subtracted, their products formed directly. Rounding: FFT
    correlation's, relative to the largest lag's sum (eps log n), where running sums were
    relative to each sum."""
    n = len(A)
    out = np.zeros((top + 1, top + 1))
    if n <= top:
        return out                                              # no row t >= top
    fa = spectra(A, top)
    fb = fa if B is A and spectrum_b is None else spectra(B, top) if spectrum_b is None else spectrum_b
    size = fast_size(n + top)
    lags = np.arange(-top, top + 1)
    whole = np.fft.irfft(np.einsum("fk,fk->f", fa, fb.conj()), size)
    full = whole[lags % size]                                   # the sum over s of A[s] . B[s - h]
    # the rows entry (i, i + h) leaves out: s < top - i (head), s > n - 1 - i (tail); n > top, so
    # the first and last top rows hold them all and no row is in both
    padded = np.zeros((n + 2 * top, A.shape[1]))
    padded[top:top + n] = B

    def products(rows: np.ndarray) -> np.ndarray:               # (rows, lags): A[s] . B[s - h], 0 outside
        return np.einsum("sk,shk->sh", A[rows], padded[rows[:, None] - lags[None, :] + top])

    zero = np.zeros((1, len(lags)))
    head = np.concatenate([zero, np.cumsum(products(np.arange(top)), axis=0)])        # [j]: rows < j
    tail = np.concatenate([zero, np.cumsum(products(np.arange(n - 1, n - top - 1, -1)), axis=0)])  # [j]: last j
    i, l = np.indices((top + 1, top + 1))
    h = l - i + top
    return full[h] - head[top - i, h] - tail[i, h]
