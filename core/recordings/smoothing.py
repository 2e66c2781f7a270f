"""How fast positions move and their derivatives: the positions' bandwidth (the spectrum
above the noise) and Savitzky-Golay smoothing differentiation of uniformly sampled positions.

The bandwidth sets the project's CSV layout's smoothing window (:func:`savgol_window`) and a
recording's default low-pass (:func:`.filtering.auto_cutoff`); diagnosis reads it too.
"""

import numpy as np

# Savitzky-Golay differentiation: polynomial order, and the least number of samples it needs.
SG_ORDER = 4
MIN_SAMPLES = 2 * SG_ORDER + 1
# The smoothing window's largest relative error on the second derivative of a sinusoid at
# the positions' bandwidth (see savgol_window).
SG_BIAS = 1e-3
# Bandwidth: the frequency below which this fraction of the (detrended) positions' power lies.
BANDWIDTH_POWER = 0.9999
# A coordinate with half its power above this fraction of the Nyquist frequency does not move
# beyond its noise (white noise has half its power above 0.5): its bandwidth is the noise's.
STILL_BAND = 0.25
# The noise floor of a spectrum: the median power above half the Nyquist frequency; a bin
# counts as motion when its power exceeds this many times the floor (a bin of white noise
# does with probability exp(-NOISE_MARGIN ln 2), 1e-9). Why: an encoder's noise (1e-6 rad)
# under a trapezoid or a ramp holds more than 1e-4 of the power, so the bandwidth was the
# noise's (150-500 Hz on a real Kinova log) and nothing was filtered.
NOISE_MARGIN = 30.0
# A coordinate whose range is below this fraction of the largest range of the coordinates
# given (a joint held by its brake that deflects, a locked joint's encoder ticks) does not move.
STILL_RANGE = 1e-3
# The bandwidth is at most these multiples of the frequencies below which 90 % and 99 % of
# the power above the noise lies. A smooth motion meets its 99.99 % well inside them (a
# sinusoid: at once; a trapezoid, power falling as f^-6: at 1.6 and 2.5 times its
# fundamental for 90 and 99 %, 6.3 for 99.99 %); a real arm's last 1 % is its vibration and
# the loop's jitter, up to 100 Hz on a Kinova's trapezoid (bandwidth 51 Hz, 2.9 with them).
BULK_90, BULK_99 = 10.0, 4.0


def bandwidth(q: np.ndarray, step: float) -> float:
    """The positions' bandwidth (Hz): the frequency below which a fraction BANDWIDTH_POWER of
    their power lies (detrended, Blackman-tapered so the ends leak no power to high
    frequencies; the largest over the coordinates that move); 0 for constant positions.

    Only the spectrum above the noise is counted: the bins whose power exceeds NOISE_MARGIN
    times the noise floor (the median power above half the Nyquist frequency); and the
    bandwidth is at most BULK_90 and BULK_99 times the frequencies below which 90 and 99 %
    of that power lies (a smooth motion's 99.99 % lies well within them). Why: on a
    ramp, a trapezoid or a single-joint motion the encoder's noise holds more than 1e-4 of
    the power, and the bandwidth came out at 60-500 Hz on a real Kinova log (nothing was
    filtered; a prediction's RMS was 46 N m). On clean data the floor is rounding and the
    bandwidth is as before.

    A coordinate that does not move (constant; a range below STILL_RANGE times the largest
    range of the coordinates; no bin above the noise) or not beyond its noise (a locked
    joint's encoder jitter: a flat spectrum, half its power above STILL_BAND times the
    Nyquist frequency) is left out, unless no coordinate moves. Why: one still Panda finger
    made the bandwidth 12 Hz instead of 0.5, the filter kept 121 Hz and the decimation 3
    instead of 70: every other joint's residual was 3.5 times its noise level, and diagnose
    took 28 s instead of 5."""
    n = q.shape[0]
    moving, still = 0.0, 0.0
    frequencies = np.fft.rfftfreq(n, step)
    columns = np.atleast_2d(np.asarray(q, float).T)
    ranges = np.array([np.ptp(c) if np.isfinite(c).all() else 0.0 for c in columns])
    largest = float(ranges.max(initial=0.0))
    for column, size in zip(columns, ranges):
        if size == 0:
            continue
        detrended = column - np.polyval(np.polyfit(np.arange(n), column, 1), np.arange(n))
        power = np.abs(np.fft.rfft(detrended * np.blackman(n))) ** 2     # tapered: no leakage
        if power.sum() <= 0:
            continue
        cumulative = np.cumsum(power) / power.sum()
        band = float(frequencies[min(int(np.searchsorted(cumulative, BANDWIDTH_POWER)), len(power) - 1)])
        half = float(frequencies[min(int(np.searchsorted(cumulative, 0.5)), len(power) - 1)])
        signal = _above_noise(power)
        if half > STILL_BAND * frequencies[-1] or not signal.any() or size < STILL_RANGE * largest:
            still = max(still, band)
            continue
        above = np.cumsum(np.where(signal, power, 0.0))
        above /= above[-1]

        def at(share: float) -> float:
            return float(frequencies[min(int(np.searchsorted(above, share)), len(power) - 1)])
        band = min(band, at(BANDWIDTH_POWER), BULK_90 * at(0.9), BULK_99 * at(0.99))
        moving = max(moving, band)
    return moving if moving > 0 else still


def _above_noise(power: np.ndarray) -> np.ndarray:
    """Which bins of a power spectrum (DC first) rise above its noise: power over NOISE_MARGIN
    times the median of the bins above half the Nyquist frequency (all True below 16 bins)."""
    if len(power) < 16:
        return np.ones(len(power), dtype=bool)
    floor = float(np.median(power[len(power) // 2:]))
    signal = power > NOISE_MARGIN * floor
    signal[0] = False                         # the mean (detrended away): not motion
    return signal


def savgol_window(q: np.ndarray, step: float) -> int:
    """The Savitzky-Golay window (odd number of samples) for positions ``q`` (N, f).

    The positions' bandwidth f_b is the frequency below which a fraction BANDWIDTH_POWER of
    their power lies (detrended, Blackman-tapered so the ends leak no power to high
    frequencies; largest over the coordinates). The window is the longest whose second
    derivative of a sinusoid at f_b is off by at most SG_BIAS (relative): the signal passes
    almost untouched, and everything above it, noise included, is smoothed as much as that
    allows. At least SG_ORDER + 1 samples (odd), at most N/10 (read_measured drops half a
    window at each end, where the derivatives would be extrapolated).
    """
    n = q.shape[0]
    fb = bandwidth(q, step)
    smallest = (SG_ORDER + 2) // 2                        # half-widths: window = 2 half + 1
    largest = max(smallest, (n // 10 - 1) // 2)
    if fb <= 0:
        return 2 * smallest + 1
    omega = 2 * np.pi * fb * step                          # radians per sample

    def bias(half: int) -> float:
        from scipy.signal import savgol_coeffs      # here, not at the top: scipy.signal takes 0.3-0.5 s to import
        c = savgol_coeffs(2 * half + 1, SG_ORDER, deriv=2, use="dot")
        response = np.sum(c * np.exp(1j * omega * np.arange(-half, half + 1)))
        return float(abs(response / -(omega ** 2) - 1))

    if bias(smallest) > SG_BIAS:
        return 2 * smallest + 1
    lo, hi = smallest, largest                               # bias grows with the window
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if bias(mid) <= SG_BIAS else (lo, mid - 1)
    return 2 * lo + 1


def savgol_derivatives(q: np.ndarray, step: float, window: int | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(qd, qdd) of uniformly sampled positions ``q`` (N, f) by Savitzky-Golay differentiation
    (order SG_ORDER; ends fitted by the polynomial of the end window, scipy's mode 'interp')."""
    from scipy.signal import savgol_filter
    window = savgol_window(q, step) if window is None else window
    d1 = savgol_filter(q, window, SG_ORDER, deriv=1, delta=step, axis=0, mode="interp")
    d2 = savgol_filter(q, window, SG_ORDER, deriv=2, delta=step, axis=0, mode="interp")
    return d1, d2
