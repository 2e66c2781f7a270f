"""One uniform piece of a run, filtered as Gautier's parallel filtering asks.

Positions low-passed by a zero-phase Butterworth filter whose cut-off is a multiple of their
bandwidth (:func:`auto_cutoff`), differentiated by central differences (a measured velocity
filtered and checked against the positions' derivative), irregular stamps resampled onto a
grid and the filtered motion taken back to each sample's own time; the torques and the
model's columns then filtered and decimated alike (:class:`~.data.Segment`). Coordinates the
run holds still (:func:`_still`) get velocities and accelerations of exactly 0.
"""

import math

import numpy as np

from baseparams.dynamics.forces import Motion
from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.data import UNIFORM_TOLERANCE, MeasuredData, Segment
from baseparams.recordings.smoothing import MIN_SAMPLES, STILL_RANGE, bandwidth
from baseparams.recordings.values import _number

# Default filter: the positions' cut-off is this multiple of their bandwidth (Gautier's rule
# of thumb: 5 to 10 times the dynamics' band keeps the derivatives' phase and amplitude).
CUTOFF_PER_BANDWIDTH = 10.0
BUTTERWORTH_ORDER = 4
# The parallel filter's cut-off sits at this fraction of the decimated Nyquist frequency.
DECIMATION_BAND = 0.8
# Rows dropped at each end of a segment: this many periods of the cut-off (filter transients).
EDGE_PERIODS = 3.0
VELOCITY_MISMATCH = 0.05          # measured velocity vs the positions' derivative: a note above this
SLOW_BAND = 0.1                    # Hz: a motion slower than this over a whole log: a time unit wrong?


def auto_cutoff(signal: np.ndarray, step: float, what: str) -> tuple[float, str]:
    """The default cut-off (Hz) for ``signal`` sampled every ``step`` s, and how it was chosen:
    CUTOFF_PER_BANDWIDTH times its bandwidth (:func:`.smoothing.bandwidth`: the spectrum above the
    noise), at most DECIMATION_BAND times Nyquist. A motion slower than SLOW_BAND over the
    whole log is said: a time column in the wrong unit (a sample index read as seconds)?"""
    fs = 1 / step
    band = bandwidth(signal, step)
    cutoff = min(CUTOFF_PER_BANDWIDTH * band if band > 0 else fs, DECIMATION_BAND * fs / 2)
    how = f"{CUTOFF_PER_BANDWIDTH:g} x the {what}' bandwidth {band:.3g} Hz"
    if cutoff < CUTOFF_PER_BANDWIDTH * band:
        how += f", capped at {DECIMATION_BAND:g} x the Nyquist frequency"
    if 0 < band < SLOW_BAND:
        how += (f"; a motion slower than {SLOW_BAND:g} Hz over the whole log, sampled at {fs:.4g} Hz: is the time "
                "in the right unit (a sample index read as seconds: time_unit = \"samples\" with the rate)?")
    return cutoff, how


def _still(q: np.ndarray, mechanism: Mechanism, coordinates: tuple[str, ...], run: str
           ) -> tuple[np.ndarray, list[str]]:
    """(which coordinates do not move in this run, a note): a range of 0, or below STILL_RANGE
    times the largest range of the coordinates of its kind (angles, lengths), unless none
    moves. Their velocity and acceleration are then exactly 0 (:func:`_filtered`), so an
    effect of theirs has no column in this run. Why: a joint the log holds still (a Kinova's
    single-joint trapezoid) had a velocity of rounding noise, 1e-17 rad/s after the filter,
    and its viscous friction came out at -1.4e18 +- 1.4e17 with exit 0; a joint deflecting
    0.2 mrad under its brake got -109 +- 50."""
    finite = np.where(np.isfinite(q), q, np.nan)
    ranges = np.nan_to_num(np.nanmax(finite, axis=0) - np.nanmin(finite, axis=0)) if len(q) else np.zeros(q.shape[1])
    angle = np.array([mechanism.is_angle(c) for c in coordinates], dtype=bool)
    still = np.zeros(len(coordinates), dtype=bool)
    for kind in (angle, ~angle):
        if kind.any() and ranges[kind].max() > 0:
            still |= kind & (ranges < STILL_RANGE * ranges[kind].max())
    if not still.any():
        return still, []
    unit = {True: "rad", False: "m"}
    shown = ", ".join(f"{c} ({ranges[j]:.3g} {unit[bool(angle[j])]})" for j, c in enumerate(coordinates) if still[j])
    return still, [f"held still in run {run!r} (a range below {STILL_RANGE:g} of the largest): {shown}; their "
                   "velocities and accelerations taken as 0, so no effect of theirs (friction) is fitted from "
                   "this run"]


def _filtered(t: np.ndarray, q: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None, tau: np.ndarray,
              settings: dict, path: str, coordinates: tuple[str, ...] = (), still: np.ndarray | None = None
              ) -> tuple[MeasuredData, list[str]]:
    """One uniform piece: resampled if irregular, positions filtered and differentiated, the
    parallel filter and decimation planned (:class:`Segment`); the ``still`` coordinates
    (:func:`_still`) with velocity and acceleration exactly 0."""
    from scipy.interpolate import CubicSpline      # here: scipy.signal's import is 0.3-0.5 s of a run that filters nothing
    from scipy.signal import butter, sosfiltfilt
    notes = []
    steps = np.diff(t)
    step = float(np.median(steps))
    own_times = None                      # irregular stamps: the samples' own times
    if np.any(np.abs(steps - step) > UNIFORM_TOLERANCE * step):
        grid = t[0] + step * np.arange(int(math.floor((t[-1] - t[0]) / step + 1e-9)) + 1)
        notes.append(f"irregular time steps ({steps.min() * 1e3:.4g} to {steps.max() * 1e3:.4g} ms): positions "
                     f"and velocities resampled to a uniform {step * 1e3:.4g} ms grid (cubic) to be filtered and "
                     "differentiated, then taken back to each sample's own time; the torques are not "
                     "resampled (the model is evaluated where they were measured)")
        own_times = t
        q = CubicSpline(t, q, axis=0)(grid)
        qd = None if qd is None else CubicSpline(t, qd, axis=0)(grid)
        qdd = None if qdd is None else CubicSpline(t, qdd, axis=0)(grid)
        t = grid
    fs = 1 / step
    order = int(settings.get("order", BUTTERWORTH_ORDER))
    if not 1 <= order <= 12:
        raise InputError(f"order {order}: between 1 and 12", file=path, key="filter.order")
    if "cutoff" in settings:
        cutoff = _number(settings["cutoff"], path, "filter.cutoff")
        how = settings.get("how", "as set")
        if settings.get("fit") and cutoff >= DECIMATION_BAND * fs / 2:     # the fit's, above this log's band
            cutoff = DECIMATION_BAND * fs / 2
            how += f", capped at {DECIMATION_BAND:g} x this log's Nyquist frequency"
    else:
        # from the positions, even beside a measured velocity: a velocity's noise (a Panda's, differentiated
        # by its controller) set the cut-off at 33 Hz and nothing was filtered (NRMS 0.83 against 0.080)
        moving = slice(None) if still is None or still.all() else ~still
        cutoff, how = auto_cutoff(q[:, moving], step, "positions")
    if not 0 < cutoff < 0.5 * fs:
        raise InputError(f"cut-off {cutoff:.4g} Hz: must lie between 0 and the Nyquist frequency "
                         f"{0.5 * fs:.4g} Hz", file=path, key="filter.cutoff")
    if "decimate" in settings:
        factor = int(settings["decimate"])
        if factor < 1:
            raise InputError("must be at least 1", file=path, key="filter.decimate")
    else:
        factor = max(1, int(DECIMATION_BAND * fs / (2 * cutoff)))
    sos = butter(order, cutoff, fs=fs, output="sos")
    parallel = butter(order, min(cutoff, DECIMATION_BAND * fs / (2 * factor)) if factor > 1 else cutoff,
                      fs=fs, output="sos")
    edge = int(math.ceil(EDGE_PERIODS * fs / cutoff))
    if len(t) - 2 * edge < MIN_SAMPLES * factor:
        raise InputError(f"{len(t)} samples at {fs:.4g} Hz: too short for a {cutoff:.3g} Hz filter "
                         f"(it drops {edge} at each end) and decimation by {factor}", file=path)
    if qd is None:
        qf = sosfiltfilt(sos, q, axis=0)
        qd = np.gradient(qf, step, axis=0)
        qdd = np.gradient(qd, step, axis=0)
        estimated: tuple[str, ...] = ("qd", "qdd")
        what = "positions"
    else:
        qf = sosfiltfilt(sos, q, axis=0)
        qd = sosfiltfilt(sos, qd, axis=0)
        estimated = ("qdd",) if qdd is None else ()
        qdd = np.gradient(qd, step, axis=0) if qdd is None else sosfiltfilt(sos, qdd, axis=0)
        what = "measured velocities" + ("" if estimated else " and accelerations")
        notes += _velocity_check(qf, qd, step, edge, coordinates, still)
    if own_times is not None:             # the filtered motion at the samples' own times
        qf, qd, qdd = (CubicSpline(t, x, axis=0)(own_times) for x in (qf, qd, qdd))
        t = own_times
    if still is not None and still.any():
        qd, qdd = qd.copy(), qdd.copy()
        qd[:, still] = 0.0
        qdd[:, still] = 0.0
    kept = len(range(edge, len(t) - edge, factor))
    notes.append(f"{what} low-passed at {cutoff:.4g} Hz ({how}; Butterworth order {order}, zero-phase)"
                 + (f", {' and '.join(estimated)} by central differences" if estimated else "")
                 + f"; torques and model columns filtered alike and decimated by {factor} "
                 f"({fs:.4g} -> {fs / factor:.4g} Hz; {edge} samples dropped at each end): {kept} samples")
    segment = Segment(0, len(t), 0, parallel, factor, edge)
    data = MeasuredData(Motion(t, qf, qd, qdd), segment.reduce(tau), (), None, (), estimated,
                        segments=(segment,), unfiltered=tau[segment.kept()],
                        filters=({"cutoff": float(cutoff), "order": order},))
    return data, notes


def _velocity_check(q: np.ndarray, qd: np.ndarray, step: float, edge: int, names: tuple[str, ...],
                    still: np.ndarray | None = None) -> list[str]:
    """A note when measured velocities are not the positions' derivative (both filtered alike;
    the filter's transients at the ends left out): their RMS difference over VELOCITY_MISMATCH
    of the derivative's on a coordinate, with the lag (up to 1 s) that aligns them best.
    Why: a controller often logs a filtered velocity (the TIAGo's lags its positions by 0.2 s),
    which then stood in the model's velocity terms without a word."""
    inside = slice(edge, len(q) - edge) if len(q) > 2 * edge + 2 else slice(None)
    derivative, measured = np.gradient(q, step, axis=0)[inside], qd[inside]
    found = []
    for j in range(q.shape[1]):
        if still is not None and still[j]:              # a joint held still: noise against noise
            continue
        size = float(np.sqrt(np.mean(derivative[:, j] ** 2)))
        miss = float(np.sqrt(np.mean((measured[:, j] - derivative[:, j]) ** 2))) / size if size > 0 else 0.0
        if miss <= VELOCITY_MISMATCH:
            continue
        longest = min(len(measured) // 4, int(round(1.0 / step)))
        errors = {k: float(np.sqrt(np.mean((measured[max(k, 0):len(measured) + min(k, 0), j]
                                            - derivative[max(-k, 0):len(measured) - max(k, 0), j]) ** 2))) / size
                  for k in range(-longest, longest + 1)}
        lag = min(errors, key=errors.__getitem__)
        name = names[j] if j < len(names) else f"coordinate {j + 1}"
        found.append(f"{name} {100 * miss:.0f} %" + (f" ({'lags' if lag > 0 else 'leads'} by "
                                                    f"{abs(lag) * step * 1e3:.4g} ms: {100 * errors[lag]:.0f} % "
                                                    "once aligned)" if lag else ""))
    if not found:
        return []
    return ["measured velocities differ from the positions' derivative (RMS, of the derivative's): "
            + ", ".join(found) + ": filtered or delayed velocities? Without [velocity] the velocities are derived "
            "from the positions"]
