"""Measured data: :class:`MeasuredData` and its segments (the fit's rows, filtered and
decimated alike), and the CSV layout of docs/design.md, read with every error named, and
written back. The text is parsed by :mod:`.delimited`, derivatives estimated by :mod:`.smoothing`.

Layout: a header row, then one sample a row. Columns (any order): ``t`` (s); for each
independent coordinate ``c`` of the mechanism ``q_c``, optional ``qd_c`` and ``qdd_c``, and
``tau_c`` (the generalized force on ``c``). Other columns are ignored with a note. Rows are
named by their line in the file (the header is row 1), as a spreadsheet numbers them.

Velocities and accelerations that the file does not give are estimated by Savitzky-Golay
smoothing differentiation (:func:`.smoothing.savgol_derivatives`), which needs uniform sampling: a file
whose time steps vary by more than :data:`UNIFORM_TOLERANCE` must give ``qd_c`` and ``qdd_c``.
The positions must close the mechanism's loops and respect its coordinate limits: the first
sample that does not is named by its row and time.
"""

import io
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.errors import InputError, KinematicsError
from baseparams.io.atomic import atomic_write  # noqa: F401  (re-exported: one atomic writer)
from baseparams.dynamics.forces import Motion, evaluate, independent_names
from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Float64
# the text reader and the differentiation have their own modules; these names are read from here too
from baseparams.recordings.delimited import MAX_MAGNITUDE, NUMBER, _read_text, read_columns  # noqa: F401
from baseparams.recordings.smoothing import MIN_SAMPLES, SG_ORDER, bandwidth, savgol_derivatives, savgol_window  # noqa: F401

# Relative spread of the time steps up to which sampling counts as uniform (SG needs it).
UNIFORM_TOLERANCE = 1e-3
# Model rows evaluated at once when the model's columns are built for a fit (bounded memory
# on long recordings), and how far beyond its kept rows a chunk reaches: this many times the
# rows a segment drops at its ends (each 3 periods of the cut-off), so the zero-phase
# filter's transient at a chunk's border has decayed below 1e-12 where rows are kept.
CHUNK_ROWS = 20_000
CHUNK_PAD = 4
# Bytes of columns given to the zero-phase filter at once (it copies what it is given 4 times).
FILTER_BATCH_BYTES = 32 << 20


def zero_phase(sos: np.ndarray, x: np.ndarray, rows: slice | np.ndarray = slice(None),
               live: np.ndarray | None = None) -> np.ndarray:
    """``x`` (rows, ...) through the zero-phase filter ``sos`` (scipy's sosfiltfilt) along the
    rows, then its ``rows``; columns that are zero throughout left as they are (they filter
    to zero). ``live``: which columns of x (flattened after the rows) are not zero, when
    known. Why: on a serial chain 40 % of the inertial columns are zero (a body moves no
    joint before it), and an effect acts on one coordinate of f; the zero columns are only
    placed at the kept rows. The columns go through the filter FILTER_BATCH_BYTES at a time
    (each column is filtered on its own, so the result is the same): sosfiltfilt holds four
    copies of what it is given, 2.4 GB for a Panda's inertial columns over 120 s at 1 kHz."""
    from scipy.signal import sosfiltfilt     # here: scipy.signal's import is 0.3-0.5 s of a run that filters nothing
    flat = x.reshape(len(x), -1)
    live = live_columns(flat) if live is None else live
    kept = np.arange(len(x))[rows]
    out = np.zeros((len(kept), flat.shape[1]))
    columns = np.flatnonzero(live)
    width = max(1, FILTER_BATCH_BYTES // (8 * max(1, len(x))))
    for first in range(0, len(columns), width):
        batch = columns[first:first + width]
        if len(batch) == flat.shape[1]:
            out[:] = sosfiltfilt(sos, flat, axis=0)[kept]
        elif len(batch) == batch[-1] - batch[0] + 1:          # a run of columns: a view, no copy
            out[:, batch[0]:batch[-1] + 1] = sosfiltfilt(sos, flat[:, batch[0]:batch[-1] + 1], axis=0)[kept]
        else:
            out[:, batch] = sosfiltfilt(sos, flat[:, batch], axis=0)[kept]
    return out.reshape((len(kept),) + x.shape[1:])


def live_columns(flat: np.ndarray) -> np.ndarray:
    """Which columns of ``flat`` (rows, c) are not zero throughout; column by column when
    there are few (numpy's any along the rows of a C-ordered array reads every element
    several times: 3 times slower on an effect's 6 columns)."""
    if flat.shape[1] <= 32:
        return np.fromiter((column.any() for column in flat.T), dtype=bool, count=flat.shape[1])
    return np.any(flat != 0, axis=0)


@dataclass(frozen=True)
class Segment:
    """One stretch of uniformly sampled rows of the model's rows (a run, or a piece of one
    split at a gap), reduced to the fit's rows on its own, so no filter runs across a seam.

    Gautier's parallel filtering: ``sos`` (a zero-phase low-pass, None for none) is applied
    to the torques and to every model column alike, ``edge`` rows are dropped at each end
    (the filters' transients), and every ``factor``-th row is kept."""
    start: int
    stop: int
    run: int = 0
    sos: np.ndarray | None = field(default=None, repr=False, compare=False)
    factor: int = 1
    edge: int = 0
    skip: tuple[int, ...] = ()    # coordinates (indices) without a measured force here: zero rows

    def kept(self) -> np.ndarray:
        """The model rows (absolute) this segment keeps."""
        return np.arange(self.start + self.edge, self.stop - self.edge, self.factor)

    def reduce(self, x: np.ndarray, live: np.ndarray | None = None) -> np.ndarray:
        """``x`` (the segment's rows, ...) filtered and decimated to its kept rows; ``live``:
        as :func:`zero_phase` takes it."""
        rows = slice(self.edge, len(x) - self.edge, self.factor)
        out = zero_phase(self.sos, x, rows, live) if self.sos is not None else x[rows]
        return self.masked(out)

    def masked(self, x: np.ndarray) -> np.ndarray:
        """``x`` (rows, f, ...) with the coordinates in ``skip`` zero: a force channel left
        out of this run (a dead sensor, ``skip`` in its [[runs]], ``"none"`` in [torque])
        is left out of the fit, its model columns and its torque alike, while its motion
        still drives the other coordinates. Why: one dead sensor refused a whole run."""
        if not self.skip or x.ndim < 2:
            return x
        out = np.array(x, copy=True)
        out[:, list(self.skip)] = 0.0
        return out

    def noise_correlation(self) -> np.ndarray:
        """The autocorrelation r[0], r[1], ... (r[0] = 1) at the kept rows' lags of white noise
        reduced as this segment reduces the torques: the zero-phase filter's impulse response
        g (over CHUNK_PAD edges each side, where its transient has decayed), r[k] =
        sum_m g[m] g[m + k factor] / sum_m g[m]^2. Why: filtered and decimated noise is
        correlated at the fit's rows, and a whiteness test that expects white noise there
        says "structure remains" on a recording with nothing missing."""
        if self.sos is None:
            return np.ones(1)
        half = max(CHUNK_PAD * self.edge, 8 * self.factor)
        impulse = np.zeros(2 * half + 1)
        impulse[half] = 1.0
        from scipy.signal import sosfiltfilt
        g = sosfiltfilt(self.sos, impulse)
        size = 1 << int(np.ceil(np.log2(2 * len(g))))
        spectrum = np.fft.rfft(g, size)
        R = np.fft.irfft(spectrum * np.conj(spectrum), size)[:len(g)]
        r = R[::self.factor] / R[0]
        return r[: int(np.nonzero(np.abs(r) > 1e-9)[0].max()) + 1]


@dataclass
class MeasuredData:
    """Samples of the independent coordinates and their generalized forces.

    ``motion``: t, q, qd, qdd (N, f) at the model's rows, columns in ``coordinates`` order (the
    mechanism's independent coordinates); ``tau`` (n, f) at the fit's rows: the model's rows
    reduced by ``segments`` (filtered and decimated per segment; one identity segment when
    nothing is reduced, so n = N); ``path``: the file read (None when simulated);
    ``notes``: what reading did that a user should know (ignored columns, estimated
    derivatives, filters, resampling); ``estimated``: which of "qd", "qdd" were estimated.
    ``sample``: the kinematics at every model row (loops closed), kept so a fit need not
    evaluate it again. ``runs``: the name of each run (file or experiment); ``payloads``:
    (run, body label, ten inertial parameters) of known loads added to a run's mechanism.
    ``gain_names``/``gain_columns`` (n, f, G): currents whose gains are unknown, each as the
    force it makes per unit gain; the measured force is ``tau + gain_columns @ gains``.
    ``quanta``: the step of the grid each force was logged on (a current in counts, a torque
    rounded to 0.001), mapped through the drive chain; 0 where not on a grid.
    """
    motion: Motion
    tau: np.ndarray
    coordinates: tuple[str, ...]
    path: str | None = None
    notes: tuple[str, ...] = ()
    estimated: tuple[str, ...] = ()
    sample: Sample | None = field(default=None, repr=False, compare=False)
    segments: tuple[Segment, ...] = ()
    runs: tuple[str, ...] = ()
    payloads: tuple = ()
    gain_names: tuple[str, ...] = ()
    gain_columns: np.ndarray | None = field(default=None, repr=False, compare=False)
    quanta: np.ndarray | None = None   # (f,) each force's quantisation step as logged (0: none), or None
    # the forces at the fit's rows without the parallel filter ((n, f), and (n, f, G) per unknown gain), where
    # they differ from tau: an NRMS beside the fit's band's, comparable with another tool's (None: tau itself)
    unfiltered: np.ndarray | None = field(default=None, repr=False, compare=False)
    unfiltered_gains: np.ndarray | None = field(default=None, repr=False, compare=False)
    filters: tuple[dict, ...] = ()     # per run: the positions' low-pass {"cutoff" (Hz), "order"}; () when none

    def __post_init__(self) -> None:
        if not self.segments:
            self.segments = (Segment(0, self.motion.count),)
        if not self.runs:
            self.runs = (self.path or "data",)
        if self.gain_columns is None:
            self.gain_columns = np.zeros(self.tau.shape + (len(self.gain_names),))

    @property
    def count(self) -> int:
        """Rows of the fit (after reduction)."""
        return len(self.tau)

    def unfiltered_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """(tau, gain columns) at the fit's rows without the parallel filter (the measured
        samples as logged, mapped to the joints); ``tau`` and ``gain_columns`` when nothing
        was filtered."""
        assert self.gain_columns is not None
        if self.unfiltered is None:
            return self.tau, self.gain_columns
        gains = self.unfiltered_gains if self.unfiltered_gains is not None else np.zeros_like(self.gain_columns)
        return self.unfiltered, gains

    def unreduced(self) -> "MeasuredData":
        """The fit's rows as unfiltered data: the motion at the kept rows, the unfiltered forces,
        each run's segment without filter or decimation (its payloads and masked channels
        kept), so that a model's forces there are compared with the forces as measured."""
        tau, gains = self.unfiltered_forces()
        segments, first = [], 0
        for s in self.segments:
            count = len(s.kept())
            segments.append(Segment(first, first + count, s.run, skip=s.skip))
            first += count
        return MeasuredData(self.motion.take(self.kept_rows()), tau, self.coordinates, self.path, self.notes,
                            self.estimated, None, tuple(segments), self.runs, self.payloads, self.gain_names, gains)

    def noise_correlation(self) -> np.ndarray:
        """The autocorrelation at the fit's lags of white noise in the torques as read, after the
        reduction (:meth:`Segment.noise_correlation`, averaged over the segments by their kept
        rows); [1.0] when nothing is filtered."""
        parts = [(len(s.kept()), s.noise_correlation()) for s in self.segments]
        out = np.zeros(max(len(r) for _, r in parts))
        for count, r in parts:
            out[:len(r)] += count * r
        return out / out[0]

    @property
    def masked(self) -> bool:
        """Some run has a coordinate without a measured force (:meth:`Segment.masked`)."""
        return any(s.skip for s in self.segments)

    def measured(self) -> np.ndarray:
        """(n, f) bool: which forces at the fit's rows were measured (False where a run's
        channel was left out)."""
        out = np.ones(self.tau.shape[:2], dtype=bool)
        first = 0
        for s in self.segments:
            count = len(s.kept())
            out[first:first + count, list(s.skip)] = False
            first += count
        return out

    @property
    def reduced(self) -> bool:
        return any(s.sos is not None or s.factor != 1 or s.edge for s in self.segments)

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """Model-row quantities (N, ...) at the fit's rows (n, ...), segment by segment."""
        if not self.reduced and not self.masked:
            return x
        live = live_columns(x.reshape(len(x), -1))          # once for all segments
        return np.concatenate([s.reduce(x[s.start:s.stop], live) for s in self.segments], axis=0)

    def kept_rows(self) -> np.ndarray:
        """The model row of each fit row."""
        return np.concatenate([s.kept() for s in self.segments])

    @property
    def t(self) -> np.ndarray:
        """The time of each fit row."""
        return self.motion.t[self.kept_rows()]

    def run_of_row(self) -> np.ndarray:
        """The run index of each fit row."""
        return np.concatenate([np.full(len(s.kept()), s.run) for s in self.segments])

    def payload_of_run(self, run: int) -> np.ndarray | None:
        """The known payloads' parameters added to run ``run`` (P,), or None."""
        added = [(label, phi) for r, label, phi in self.payloads if r == run]
        if not added:
            return None
        total = np.zeros(10 * max(label for label, _ in added))
        for label, phi in added:
            total[10 * (label - 1): 10 * label] += phi
        return total

    def reduced_columns(self, build: Callable[[Motion, Sample | None, int], np.ndarray]) -> np.ndarray:
        """Columns at the fit's rows (n, f, c): ``build(motion, sample, run)`` gives them at
        some model rows (``sample`` None: evaluate the kinematics there), and each segment
        reduces them as it reduced the torques. Long data go chunk by chunk (CHUNK_ROWS model
        rows and a margin of CHUNK_PAD times the segment's edge), so memory stays bounded."""
        if self.motion.count <= CHUNK_ROWS and len({s.run for s in self.segments}) == 1:
            return self.reduce(build(self.motion, self.sample, self.segments[0].run))
        return self._reduced_chunks(build)

    def _reduced_chunks(self, build: Callable[[Motion, Sample | None, int], np.ndarray]) -> np.ndarray:
        out = []
        for s in self.segments:
            kept = s.kept()
            pad = CHUNK_PAD * s.edge
            step = max(1, CHUNK_ROWS // s.factor)
            for first in range(0, len(kept), step):
                rows = kept[first:first + step]
                lo, hi = max(s.start, rows[0] - pad), min(s.stop, rows[-1] + pad + 1)
                if lo - s.start < s.edge:            # the segment's own start: same rows as reduce
                    lo = s.start
                if s.stop - hi < s.edge:
                    hi = s.stop
                block = build(self.motion.take(slice(lo, hi)), None, s.run)
                out.append(s.masked(zero_phase(s.sos, block, rows - lo) if s.sos is not None else block[rows - lo]))
        return np.concatenate(out, axis=0)

    def payload_force(self, inertial: np.ndarray) -> np.ndarray:
        """The known payloads' forces at the model rows (N, f), from the standard columns
        K (N, f, P): each run's payloads (:meth:`payload_of_run`) on that run's rows."""
        force = np.zeros(inertial.shape[:2])
        for s in self.segments:
            payload = self.payload_of_run(s.run)
            if payload is not None:
                force[s.start:s.stop] = inertial[s.start:s.stop, :, :len(payload)] @ payload
        return force

    def take(self, rows: np.ndarray | slice) -> "MeasuredData":
        """The samples ``rows`` (a training part, a holdout block) of unreduced data; the
        kinematics are dropped."""
        if self.reduced or self.masked or self.payloads or len(self.segments) > 1:
            raise ValueError("take() needs unreduced data of one segment")
        return MeasuredData(self.motion.take(rows), self.tau[rows], self.coordinates, self.path,
                            self.notes, self.estimated)


def concatenate(parts: list["MeasuredData"], path: str | None = None) -> "MeasuredData":
    """Several measured data (runs, files) as one: rows stacked, each part's segments and runs
    kept apart (no filter crosses a seam); the kinematics are evaluated again when needed."""
    if len(parts) == 1:
        return parts[0]
    coordinates = parts[0].coordinates
    motions: list = []
    segments: list = []
    runs: list = []
    payloads: list = []
    notes: list[str] = []
    offset = 0
    gain_names = tuple(dict.fromkeys(name for part in parts for name in part.gain_names))
    gains = []
    for part in parts:
        block = np.zeros(part.tau.shape + (len(gain_names),))
        for k, name in enumerate(part.gain_names):
            block[:, :, gain_names.index(name)] = part.gain_columns[:, :, k]  # type: ignore[index]
        gains.append(block)
        if part.coordinates != coordinates:
            raise InputError("the data files are for different coordinates", file=part.path)
        motions.append(part.motion)
        for s in part.segments:
            segments.append(Segment(s.start + offset, s.stop + offset, s.run + len(runs), s.sos,
                                    s.factor, s.edge, s.skip))
        payloads += [(run + len(runs), label, phi) for run, label, phi in part.payloads]
        runs += list(part.runs)
        notes += [f"{part.path}: {n}" if len(parts) > 1 and part.path else n for n in part.notes]
        offset += part.motion.count
    motion = Motion(*(np.concatenate([getattr(m, k) for m in motions]) for k in ("t", "q", "qd", "qdd")))
    estimated = tuple(sorted({k for p in parts for k in p.estimated}))
    quanta = [p.quanta for p in parts if p.quanta is not None]
    unfiltered, unfiltered_gains = None, None
    if any(p.unfiltered is not None for p in parts):
        unfiltered = np.concatenate([p.unfiltered_forces()[0] for p in parts])
        blocks = []
        for part in parts:
            raw = part.unfiltered_forces()[1]
            block = np.zeros(part.tau.shape + (len(gain_names),))
            for k, name in enumerate(part.gain_names):
                block[:, :, gain_names.index(name)] = raw[:, :, k]
            blocks.append(block)
        unfiltered_gains = np.concatenate(blocks)
    return MeasuredData(motion, np.concatenate([p.tau for p in parts]), coordinates,
                        path or ", ".join(str(p.path) for p in parts), tuple(notes), estimated,
                        None, tuple(segments), tuple(runs), tuple(payloads), gain_names,
                        np.concatenate(gains), np.max(quanta, axis=0) if quanta else None,
                        unfiltered, unfiltered_gains, tuple(f for p in parts for f in p.filters))


# ----- reading ----------------------------------------------------------------------------
def read_measured(path: str | os.PathLike, mechanism: Mechanism, *, check_kinematics: bool = True
                  ) -> MeasuredData:
    """Read measured data for ``mechanism`` from the CSV file ``path`` (InputError naming the
    file, the row and/or column and the reason otherwise). ``check_kinematics``: close the
    loops at every sample now (and keep the result in ``sample``)."""
    path = str(path)
    from baseparams.recordings.arrays import is_array_file
    if is_array_file(path):
        raise InputError("a log saved as arrays is read through a recording description (a TOML file whose "
                         "[[runs]] file is this log and whose channels name its columns: docs/identification.md)",
                         file=path)
    text = _read_text(path)
    coordinates = independent_names(mechanism)
    found: list = []
    header, values, rows = read_columns(path, text,            # every field checked (docs/design.md)
                                        on_header=lambda header: found.extend(_columns(path, header, coordinates)))
    columns, notes = found
    t = values["t"]
    _check_times(path, t, rows)
    if len(t) < MIN_SAMPLES:
        raise InputError(f"{len(t)} samples; at least {MIN_SAMPLES} are needed", file=path)

    def block(prefix: str) -> np.ndarray:
        return np.stack([values[f"{prefix}_{c}"] for c in coordinates], axis=1)

    q, tau = block("q"), block("tau")
    given = {kind: all(f"{kind}_{c}" in columns for c in coordinates) for kind in ("qd", "qdd")}
    partial = [kind for kind in ("qd", "qdd") if not given[kind]
               and any(f"{kind}_{c}" in columns for c in coordinates)]
    for kind in partial:
        missing = [f"{kind}_{c}" for c in coordinates if f"{kind}_{c}" not in columns]
        raise InputError(f"columns {', '.join(missing)} missing: give {kind} for every coordinate "
                         f"or for none (then it is estimated)", file=path, key="header")
    estimated = tuple(kind for kind in ("qd", "qdd") if not given[kind])
    qd = block("qd") if given["qd"] else None
    qdd = block("qdd") if given["qdd"] else None
    if estimated:
        step = _uniform_step(path, t, rows, estimated)
        window = savgol_window(q, step)
        d1, d2 = savgol_derivatives(q, step, window)
        qd = d1 if qd is None else qd
        qdd = d2 if qdd is None else qdd
        trim = window // 2
        notes.append(f"{' and '.join(estimated)} estimated by Savitzky-Golay differentiation "
                     f"(order {SG_ORDER}, window {window} samples = {window * step:.4g} s); the first "
                     f"and last {trim} samples are dropped (their derivatives would be extrapolated)")
        keep = slice(trim, len(t) - trim)
        t, q, qd, qdd, tau, rows = t[keep], q[keep], qd[keep], qdd[keep], tau[keep], rows[keep]
    assert qd is not None and qdd is not None      # given, or estimated above
    motion = Motion(t, q, qd, qdd)
    data = MeasuredData(motion, tau, coordinates, path, tuple(notes), estimated)
    if check_kinematics:
        data.sample = kinematics(mechanism, data, rows)
    return data


def kinematics(mechanism: Mechanism, data: MeasuredData, rows: list[int] | None = None) -> Sample | None:
    """The kinematics at every sample, loops closed; a sample that cannot close (or leaves a
    coordinate's range) is an InputError naming the file's row (``rows``: each sample's line;
    default: sample k on line k + 2) and the time."""
    lines = rows if rows is not None else [k + 2 for k in range(data.motion.count)]
    try:
        if data.motion.count > CHUNK_ROWS:         # checked chunk by chunk, not kept: the fit
            for start in range(0, data.motion.count, CHUNK_ROWS):   # evaluates what it needs
                _chunk_kinematics(mechanism, data, start)
            return None
        return evaluate(mechanism, data.motion)
    except KinematicsError as exc:
        message, k = str(exc), None
        if mechanism.loops:
            found = _first_unreachable(mechanism, data.motion)
            if found is not None:
                k, message = found
        if k is None:
            match = re.search(r"at t = ([-+0-9.eEinfa]+) s", message)
            if match:
                k = int(np.argmin(np.abs(data.motion.t - float(match.group(1)))))
        raise InputError(f"the positions cannot be reached by {mechanism.name}: {message}",
                         file=data.path, key=None if k is None else f"row {lines[k]}") from None


def _chunk_kinematics(mechanism: Mechanism, data: MeasuredData, start: int) -> None:
    rows = slice(start, start + CHUNK_ROWS)
    try:
        evaluate(mechanism, data.motion.take(rows))
    except KinematicsError as exc:
        raise KinematicsError(str(exc)) from None


def _first_unreachable(mechanism: Mechanism, motion: Motion) -> tuple[int, str] | None:
    """The first sample whose loops do not close from the reference configuration, and why;
    by bisection over batches (each sample of a batch is closed on its own), so a bad sample
    is named even when following the data in time would fail earlier on a coarse step."""
    evaluator = Evaluator(mechanism, Float64())

    def fails(rows: slice) -> str | None:
        z = [np.ascontiguousarray(motion.q[rows, j]) for j in range(motion.q.shape[1])]
        try:
            evaluator.assemble(z, None, where=f"at t = {motion.t[rows][0]:.6g} s: ")
        except KinematicsError as exc:
            return str(exc)
        return None

    lo, hi = 0, motion.count
    if fails(slice(lo, hi)) is None:
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if fails(slice(lo, mid)) is not None:
            hi = mid
        else:
            lo = mid
    message = fails(slice(lo, hi))
    return None if message is None else (lo, message)


def _columns(path: str, header: list[str], coordinates: tuple[str, ...]) -> tuple[dict[str, int], list[str]]:
    """Column index by name; missing, empty and duplicate names are errors, unknown ones notes."""
    for k, name in enumerate(header):
        if not name:
            raise InputError(f"column {k + 1} has no name", file=path, key="header")
    seen: dict[str, int] = {}
    for k, name in enumerate(header):
        if name in seen:
            raise InputError(f"column {name!r} appears twice (columns {seen[name] + 1} and {k + 1})",
                             file=path, key="header")
        seen[name] = k
    known = {"t"} | {f"{kind}_{c}" for c in coordinates for kind in ("q", "qd", "qdd", "tau")}
    required = ["t"] + [f"{kind}_{c}" for c in coordinates for kind in ("q", "tau")]
    missing = [name for name in required if name not in seen]
    if missing:
        raise InputError(f"missing columns {', '.join(missing)} (the independent coordinates of this "
                         f"mechanism are {', '.join(coordinates)}; layout in docs/design.md)",
                         file=path, key="header")
    notes = []
    unknown = [name for name in header if name not in known]
    if unknown:
        notes.append(f"columns ignored (not part of the layout): {', '.join(unknown)}")
    return {name: k for name, k in seen.items() if name in known}, notes


def _check_times(path: str, t: np.ndarray, rows: list[int]) -> None:
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        k = int(bad[0]) + 1
        raise InputError(f"t = {t[k]:.17g} does not increase (previous row: t = {t[k - 1]:.17g})",
                         file=path, key=f"row {rows[k]}, column t")


class NonUniform(InputError):
    """Derivatives to estimate from irregular stamps: Savitzky-Golay cannot; a recording
    description's pipeline can (resampled, filtered and taken back to each sample's time),
    and :func:`baseparams.recordings.recording.read_data` reads the file through it."""


def _uniform_step(path: str, t: np.ndarray, rows: list[int], estimated: tuple[str, ...]
                  ) -> float:
    """The sampling step, checked uniform (Savitzky-Golay assumes it)."""
    steps = np.diff(t)
    step = float(np.median(steps))
    off = np.nonzero(np.abs(steps - step) > UNIFORM_TOLERANCE * step)[0]
    if off.size:
        k = int(off[0]) + 1
        raise NonUniform(f"time step {steps[k - 1]:.6g} s differs from the median step {step:.6g} s: "
                         f"{' and '.join(estimated)} can only be estimated from uniformly sampled data "
                         f"(Savitzky-Golay); resample, or give the columns "
                         f"{', '.join(kind + '_<coordinate>' for kind in estimated)}",
                         file=path, key=f"row {rows[k]}, column t")
    return step


# ----- writing ----------------------------------------------------------------------------
def header_for(coordinates: tuple[str, ...], derivatives: bool = True) -> list[str]:
    """The columns :func:`write_measured` writes, in order."""
    kinds = ("q", "qd", "qdd", "tau") if derivatives else ("q", "tau")
    return ["t"] + [f"{kind}_{c}" for c in coordinates for kind in kinds]


def write_measured(path: str | os.PathLike, data: MeasuredData, *, derivatives: bool = True) -> None:
    """Write ``data`` in the CSV layout (``derivatives``: with qd and qdd columns), each number
    to 17 significant digits (read back exactly); atomically (a temporary file renamed), so
    a failed write never leaves a truncated file behind."""
    path = Path(path)
    columns = [data.motion.t[:, None]]
    for j in range(len(data.coordinates)):
        parts = ((data.motion.q, data.motion.qd, data.motion.qdd, data.tau) if derivatives
                 else (data.motion.q, data.tau))
        columns += [a[:, j:j + 1] for a in parts]
    table = np.hstack(columns)
    buffer = io.StringIO()
    buffer.write(",".join(header_for(data.coordinates, derivatives)) + "\n")
    np.savetxt(buffer, table, fmt="%.17g", delimiter=",")
    atomic_write(path, buffer.getvalue())
