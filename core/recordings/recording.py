"""Recordings as robots write them: a small TOML description maps raw logs onto the model.

A robot logs motor or joint positions, torques or currents, with gear ratios, couplings,
gains, sign conventions, zero offsets and clocks of its own. The description
(docs/identification.md, "Recording descriptions") says which column is which coordinate
(a joint coordinate or a motor of the drive chain), the units and gains, and where time comes
from; :func:`read_recording` turns each run into :class:`~.data.MeasuredData` on the
mechanism's independent coordinates:

1. every channel scaled (``scale``, ``unit``, ``gain``) and shifted (``offset``);
2. positions (and velocities) mapped through the drive chain: the channels' rows of gear
   ratios must determine the independent coordinates (a square, nonsingular map); joint
   zero offsets (``[zero]``) added; torques mapped to the joints by the transpose of the
   torque channels' map (power balance: tau = N^T tau_motor);
3. irregular time stamps resampled onto a uniform grid at the median step (cubic for
   positions and velocities, linear for torques), runs split at gaps, each printed;
4. positions low-passed by a zero-phase Butterworth filter whose cut-off is a multiple of
   their bandwidth, differentiated by central differences (a measured velocity is
   filtered and differentiated once), then torques and model columns alike filtered and
   decimated (Gautier's parallel filtering, :class:`~.data.Segment`), each run on its own.

The description is read and checked by :mod:`.description`, each uniform piece filtered by
:mod:`.filtering`. Logs are read as tables of named columns by :mod:`.tables` (text: a header row, or
``names``, or ``stacked``), :mod:`.arrays` (``.npz``, ``.mat``) and :mod:`.bags` (ROS bags,
a table per topic on its own clock).

Nothing here rewrites a raw file; every error names the description or the log, the key
or the row and column, and the reason.
"""

import os
from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path

import numpy as np

from baseparams.dynamics.forces import drive_rows, independent_names
from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.clocks import _merged_rows, _on_one_clock, _owner, _selected, _times, _uniform_pieces
from baseparams.recordings.data import MAX_MAGNITUDE, MeasuredData, NonUniform, concatenate, kinematics
from baseparams.recordings.description import (Channel, Description, _payload, describe, holds,  # noqa: F401
                                               is_description, read_description)
from baseparams.recordings.filtering import _filtered, _still, auto_cutoff
from baseparams.recordings.implied import implied_description, implied_note
from baseparams.recordings.tables import log_files, read_run_tables
from baseparams.recordings.values import _number

GRID_TOLERANCE = 1e-3              # of a step: values on a grid (quantum)
GRID_DIVISORS = 10                 # the step tried: the smallest gap over 1 .. this
QUANTUM_RELEVANT = 1e-6            # a grid finer than this times a channel's RMS is not quantisation
# A torque channel exactly 0 in at least this share of a run's rows, or one value in all of
# them, carries no signal (a dead sensor, a channel the logger did not fill): refused, or left
# out of the run (skip, dead = "skip"). Why: a column of zeros was fitted as measured: "noise
# SD 1e-100", NRMS 0, and a TIAGo's three wrists at 0 in 85-87 % of rows named "gains" of -0.99.
DEAD_SHARE = 0.8


# ----- reading a description ---------------------------------------------------------------
def read_recording(path: str | os.PathLike, mechanism: Mechanism, *, check_kinematics: bool = True,
                   fit_filter: dict | None = None) -> tuple[MeasuredData, Mechanism]:
    """Every run of the description at ``path`` as one MeasuredData (runs kept apart), and
    the mechanism with the description's motors."""
    path, _, chosen = str(path).partition("#")
    return read_described(read_description(path, mechanism), chosen, check_kinematics=check_kinematics,
                          fit_filter=fit_filter)


def read_described(description: Description, chosen: str = "", *, check_kinematics: bool = True,
                   fit_filter: dict | None = None) -> tuple[MeasuredData, Mechanism]:
    """The runs of a checked description (``chosen``: some of them by name, comma-separated);
    ``fit_filter``: the low-pass of the data a model was fitted to ({"cutoff", "order"}), which
    a validation recording is filtered with (else each run's own)."""
    path = description.path
    runs = list(enumerate(description.data["runs"]))
    if chosen:
        names = [run.get("name") for _, run in runs]
        wanted = [name.strip() for name in chosen.split(",")]
        unknown = [name for name in wanted if name not in names]
        if unknown:
            raise InputError(f"no run named {', '.join(map(repr, unknown))} (runs: "
                             f"{', '.join(str(n) for n in names if n) or 'none named'})", file=path, key="runs")
        runs = [(i, run) for i, run in runs if run.get("name") in wanted]
    parts = [_read_run(description, i, run, fit_filter) for i, run in runs]
    data = concatenate(parts, path=description.path)
    data.path = description.path + (f"#{chosen}" if chosen else "")
    if check_kinematics:
        try:
            data.sample = kinematics(description.mechanism, data)
        except InputError as exc:        # rows of the filtered data are not the log's rows
            raise InputError(exc.reason, file=description.path) from None
    return data, description.mechanism


def read_data(paths: list[str], mechanism: Mechanism, *, check_kinematics: bool = True,
              fit_filter: dict | None = None) -> tuple[MeasuredData, Mechanism]:
    """Measured data from CSV files in the project's layout and recording descriptions
    (``.toml``), one run each or more, stacked with every run kept apart; and the mechanism
    with the descriptions' motors (which must agree)."""
    from baseparams.recordings.data import read_measured
    parts, model = [], None
    for path in paths:
        if is_description(path):
            part, with_motors = read_recording(path, mechanism, check_kinematics=check_kinematics,
                                               fit_filter=fit_filter)
            if model is not None and with_motors.motors != model.motors:
                raise InputError("declares other motors than the descriptions before it", file=path,
                                 key="motors")
            if model is not None and with_motors.gravity != model.gravity:
                raise InputError("states another gravity than the descriptions before it: fit recordings of "
                                 "one mounting together", file=path, key="recording.gravity")
            if model is not None and with_motors.coordinates != model.coordinates:
                raise InputError("holds other coordinates than the descriptions before it", file=path, key="held")
            model = with_motors
        else:
            # the project's layout, every field checked; through the recording pipeline (one pipeline) when its
            # stamps are irregular, or when it is filtered as a fit's data were (a --validate recording)
            why = "to be filtered with the fit's low-pass" if fit_filter is not None else ""
            try:
                part = read_measured(path, mechanism, check_kinematics=check_kinematics and not why)
            except NonUniform:
                why = "irregular time stamps"
            if why:
                part = _read_layout(path, mechanism, why, check_kinematics=check_kinematics, fit_filter=fit_filter)
        parts.append(part)
    if model is not None and model.gravity != mechanism.gravity and any(not is_description(p) for p in paths):
        raise InputError("a CSV log cannot be fitted beside a recording with its own gravity ([recording] "
                         "gravity): describe it with a recording description stating the same",
                         file=next(p for p in paths if not is_description(p)))
    if model is not None and model.coordinates != mechanism.coordinates and any(not is_description(p) for p in paths):
        raise InputError("a CSV log cannot be fitted beside a recording that holds joints ([held]): describe it "
                         "with a recording description holding the same ones", file=next(
                             p for p in paths if not is_description(p)))
    # each part's kinematics were checked with its own rows named; several parts are
    # evaluated again, stacked, when a fit needs them
    data = concatenate(parts)
    data.notes = data.notes + tuple(constant_torques(data))
    return data, model or mechanism


def _read_layout(path: str, mechanism: Mechanism, why: str, *, check_kinematics: bool = True,
                 fit_filter: dict | None = None) -> MeasuredData:
    """A CSV in the project's layout (already checked field by field) through the recording
    pipeline with the description its columns imply (:mod:`.implied`), with a note saying so
    and ``why``. One pipeline: the same samples read through a written description cannot
    give other estimates."""
    implied = implied_description(path, mechanism)
    measured, _ = read_described(describe(implied, path, mechanism), check_kinematics=check_kinematics,
                                 fit_filter=fit_filter)
    measured.notes = (implied_note(implied, why),) + measured.notes
    measured.path = path
    return measured


def constant_torques(data: MeasuredData) -> list[str]:
    """A note for each coordinate whose force is one value in every row while it moves: a
    channel that was not recorded (a dead sensor, a column of zeros). Why: it is fitted as
    measured, and the noise weighting then trusts that coordinate without limit, so a fit
    and a diagnosis bend every coupled coordinate to it (a zero torque on a PUMA's fifth
    joint named a spring and rotor inertia elsewhere)."""
    out = []
    scaled = np.any(data.gain_columns != 0, axis=(0, 2)) if data.gain_columns is not None and data.gain_columns.size \
        else np.zeros(len(data.coordinates), dtype=bool)
    for j, name in enumerate(data.coordinates):
        if scaled[j]:            # its force is a current times a gain the fit finds: not in tau (issue 44)
            continue
        tau = data.tau[:, j]
        if len(tau) > 1 and np.ptp(tau) == 0 and np.ptp(data.motion.q[:, j]) > 0:
            out.append(f"tau_{name} is {tau[0]:g} in every row while {name} moves: a force that was not "
                       "recorded? It is fitted as measured, and the coordinates it couples to follow it")
    return out


def _read_run(description: Description, index: int, run: dict, fit_filter: dict | None = None) -> MeasuredData:
    """One run of a description: its logs on one clock, the channels mapped to the independent
    coordinates, samples without a value left out, each uniform piece filtered; the run's
    known payload and the channels it leaves out kept with it."""
    path, key = description.path, f"runs[{index}]"
    mechanism = description.mechanism
    coordinates = independent_names(mechanism)
    skipped = _skipped(description, run, key)
    clock = _run_clock(description, run, key)
    channels = _RunChannels(description, clock, skipped, key)
    q = channels.mapped("position")
    assert q is not None                  # the description requires positions
    for coordinate, value in description.data.get("zero", {}).items():
        q[:, coordinates.index(coordinate)] += _number(value, path, f"zero.{coordinate}")
    qd, qdd = channels.mapped("velocity"), channels.mapped("acceleration")
    forces = channels.mapped("torque", transpose=True)
    assert forces is not None             # ... and torques
    gain_names = tuple(f"gain_{c.coordinate}" for c in description.channels["torque"] if c.unknown_gain)
    motor_side = any(c.coordinate in mechanism.motor_names for chans in description.channels.values() for c in chans)
    notes = clock.notes + channels.wrap_notes + channels.quantised_notes + ([_drive_note(description)] if motor_side
                                                                             else [])
    t, rows, (q, qd, qdd, forces), present_notes = _present(clock.t, clock.rows, (q, qd, qdd, forces))
    assert q is not None and forces is not None
    notes += present_notes
    pieces, split_notes = _uniform_pieces(t, clock.t_file, rows, path)
    notes += split_notes
    name = clock.name
    (raw_torques, torque_map), = channels.torque_channels      # channels without signal: refused, or left out
    chans = description.channels["torque"]
    notes += _dead_channels(raw_torques, chans, skipped, description, name, key)
    out = [k for k, c in enumerate(chans) if c.absent or c.coordinate in skipped]
    unmeasured = np.any(torque_map[out] != 0, axis=0) if out else np.zeros(len(coordinates), dtype=bool)
    if unmeasured.all():
        raise InputError(f"no torque is measured in run {name!r}: every channel is left out "
                         f"({', '.join(c.coordinate for c in chans)})", file=path, key=key)
    if unmeasured.any():
        forces[:, unmeasured, :] = 0.0
    still, still_note = _still(q, mechanism, coordinates, name)
    notes += still_note
    settings = _filter_settings(description, fit_filter, pieces, t, q, still)
    parts = _filtered_pieces(pieces, t, q, qd, qdd, forces, settings, path, coordinates, still, notes)
    if not parts:
        raise InputError(f"every piece of run {name!r} between gaps is too short for its filter", file=path,
                         key=key)
    payloads = _payload(run.get("payload"), mechanism, path, f"{key}.payload")
    if unmeasured.any():
        left = [c for c, u in zip(coordinates, unmeasured) if u]
        notes.append(f"no measured force on {', '.join(left)} in run {name!r} (a channel left out): those rows are "
                     "not fitted, and the motion still drives the other coordinates")
        parts = [replace(p, segments=tuple(replace(s, skip=tuple(int(j) for j in np.flatnonzero(unmeasured)))
                                           for s in p.segments)) for p in parts]
    data = _joined(parts, coordinates, f"{path}: {name}", notes, payloads, gain_names)
    data.runs = (name,)
    data.quanta = channels.quanta if channels.quanta.any() else None
    return data


@dataclass
class _RunClock:
    """A run's tables on one clock: the times ``t`` (and the file they came from), each
    sample's row in the log, the tables by file alias, the files' paths and how the
    files group into clocks, the run's name and what reading said."""
    name: str
    t: np.ndarray
    t_file: str
    rows: list
    tables: dict
    files: dict
    groups: dict
    folder: Path
    notes: list[str]


def _run_clock(description: Description, run: dict, key: str) -> _RunClock:
    """The run's logs read as tables, merged and put on one clock, cut to its window or rows."""
    path = description.path
    folder = Path(path).parent
    head = description.data.get("recording", {})
    logs = log_files(run, path, key)
    tables, files, groups = read_run_tables(description, logs, folder)
    tables, merged_notes = _merged_rows(head, tables, files, description, groups)
    tables, clock_notes = _on_one_clock(head, tables, files, description, folder, groups)
    clock_notes = merged_notes + clock_notes
    lengths = {alias: len(rows) for alias, (_, _, rows) in tables.items()}
    if len(set(lengths.values())) > 1:
        shown = ", ".join(f"{files[a]}: {n} rows" for a, n in lengths.items())
        raise InputError(f"the files of one run must have the same rows ({shown}), or each its own time "
                         "column (time = \"COLUMN\" found in every file: read on the first torque channel's clock)",
                         file=path, key=key)
    name = run.get("name", str(logs[next(iter(logs))].path))
    t, t_file = _times(head, tables, files, path, groups)
    rows = next(iter(tables.values()))[2]
    t, rows, tables = _selected(run, t, rows, tables, head, path, key)
    return _RunClock(name, t, t_file, rows, tables, files, groups, folder, clock_notes)


class _RunChannels:
    """A run's channels as the model's quantities: each channel scaled and shifted, angles
    logged modulo a turn unwrapped, positions (velocities, accelerations) mapped to the
    independent coordinates through the drive chain and torques by its transpose; what
    mapping found (unwrapped angles, quantised torques) kept as notes."""

    def __init__(self, description: Description, clock: _RunClock, skipped: set[str], key: str) -> None:
        self.description, self.clock, self.skipped, self.key = description, clock, skipped, key
        self.coordinates = independent_names(description.mechanism)
        self.wrap_notes: list[str] = []
        self.quantised_notes: list[str] = []
        self.torque_channels: list = []       # (raw, map) of the torque channels, for the dead-channel check
        self.quanta = np.zeros(len(self.coordinates))

    def values(self, channel: Channel) -> np.ndarray:
        """One channel's column, scaled and shifted (zeros for a torque left out)."""
        clock, path = self.clock, self.description.path
        tables, files, t = clock.tables, clock.files, clock.t
        if channel.absent or (channel.quantity == "torque" and channel.coordinate in self.skipped):
            return np.zeros(len(t))                    # a torque left out: zero, its coordinates masked
        alias = None if channel.file is None and None in tables else _owner(tables, clock.groups, channel, path,
                                                                            self.key)
        header, table, _ = tables[alias]
        if channel.column not in header:
            raise InputError(f"no column {channel.column!r} (columns: {', '.join(header)})",
                             file=str(clock.folder / files[alias]), key="header")
        with np.errstate(all="ignore"):
            out = channel.scale * table[channel.column] + channel.offset
        if not np.all(np.abs(out[~np.isnan(out)]) <= MAX_MAGNITUDE):
            raise InputError(f"scaled by {channel.scale:g} (and shifted by {channel.offset:g}) the column leaves "
                             f"the range |value| <= {MAX_MAGNITUDE:g}", file=path, key=channel.key)
        return out

    def mapped(self, quantity: str, transpose: bool = False) -> np.ndarray | None:
        """The ``quantity``'s channels on the independent coordinates (N, f); torques
        (``transpose``) as (N, f, 1 + unknown gains): the known forces, then each channel
        with an unknown gain as the force it makes per unit gain. None without channels."""
        mechanism, coordinates, rows = self.description.mechanism, self.coordinates, self.clock.rows
        chans = self.description.channels[quantity]
        if not chans:
            return None
        names = [c.coordinate for c in chans]
        matrix = _independent_rows(mechanism, names, coordinates, self.description.path, quantity)
        raw = np.stack([self.values(c) for c in chans], axis=1)
        if quantity == "position":                      # an angle logged modulo a turn
            for k, channel in enumerate(chans):
                if mechanism.is_angle(channel.coordinate):
                    raw[:, k], jumps = _unwrapped(raw[:, k])
                    if jumps.size:
                        self.wrap_notes.append(f"{channel.coordinate}: {jumps.size} jump(s) of a turn unwrapped (an "
                                               f"angle logged modulo 2 pi; first at row {rows[int(jumps[0])]})")
        if transpose:                                    # tau = N^T tau_channels; with unknown gains
            self.torque_channels.append((raw, matrix))
            known = np.array([not c.unknown_gain for c in chans])   # each such channel's own column
            steps = np.array([quantum(raw[:, k]) if known[k] else 0.0 for k in range(len(chans))])
            size = np.array([np.sqrt(np.mean(c[np.isfinite(c)] ** 2)) if np.isfinite(c).any() else 0.0
                             for c in raw.T])
            steps[steps < QUANTUM_RELEVANT * size] = 0.0     # a value printed to many digits: not rounding
            self.quanta[:] = np.abs(matrix).T @ steps
            if steps.any():
                self.quantised_notes.append("quantised torque channels, their values on a grid of (in the model's "
                                            "units): " + ", ".join(f"{chans[k].coordinate} {steps[k]:.4g}"
                                                                   for k in np.flatnonzero(steps)))
            forces = [(raw * known) @ matrix] + [raw[:, k:k + 1] * matrix[k] for k in np.nonzero(~known)[0]]
            return np.stack(forces, axis=2)              # (N, f, 1 + unknown gains)
        return np.linalg.solve(matrix, raw.T).T


def _present(t: np.ndarray, rows: list, arrays: tuple) -> tuple[np.ndarray, list, tuple, list[str]]:
    """(t, rows, arrays, notes) without the samples that cannot be used: a missing value (an
    empty or NaN field) in a channel used, or a stamp equal to the sample before's (a logger
    that wrote it twice, a clock coarser than its rate: a step of zero cannot be
    differentiated). ``arrays``: q, qd, qdd, forces (None where not given). The steps around
    the samples left out are resampled, or the run split where GAP_STEPS or more are missing."""
    notes = []
    present = np.all([np.all(np.isfinite(a.reshape(len(t), -1)), axis=1) for a in arrays if a is not None], axis=0)
    if not present.all():
        lost = np.nonzero(~present)[0]
        notes.append(f"{lost.size} sample(s) with a missing value (an empty or NaN field) in a channel used "
                     f"left out (first at row {rows[int(lost[0])]})")
    kept = np.flatnonzero(present)
    repeated = kept[1:][np.diff(t[kept]) == 0]
    if repeated.size:
        present[repeated] = False
        notes.append(f"{repeated.size} sample(s) stamped with the time of the sample before left out "
                     f"(first at row {rows[int(repeated[0])]})")
    if not present.all():
        t, rows = t[present], [line for line, keep in zip(rows, present) if keep]
        arrays = tuple(None if a is None else a[present] for a in arrays)
    return t, rows, arrays, notes


def _filter_settings(description: Description, fit_filter: dict | None, pieces: list, t: np.ndarray,
                     q: np.ndarray, still: np.ndarray) -> dict:
    """The run's filter: the description's ``[filter]``; a validation run's the fit's
    (``fit_filter``, never decimated); a run split at gaps one cut-off for all its pieces,
    the longest piece's."""
    settings = dict(description.data.get("filter", {}))
    if fit_filter:                         # a validation run: filtered as the fit's data were
        settings.update(cutoff=fit_filter["cutoff"], order=fit_filter["order"], fit=True,
                        how=f"the fit's filter ({fit_filter['cutoff']:.4g} Hz, order {fit_filter['order']})")
        settings.pop("decimate", None)
    if "cutoff" not in settings and len(pieces) > 1:     # one filter for the run: the longest piece's
        a, b = max(pieces, key=lambda piece: piece[1] - piece[0])
        signal = q[a:b][:, ~still if not still.all() else slice(None)]     # never a measured velocity's noise
        settings["cutoff"], how = auto_cutoff(signal, float(np.median(np.diff(t[a:b]))), "positions")
        settings["how"] = how + " on the run's longest piece"
    return settings


def _filtered_pieces(pieces: list, t: np.ndarray, q: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None,
                     forces: np.ndarray, settings: dict, path: str, coordinates: tuple[str, ...],
                     still: np.ndarray, notes: list[str]) -> list[MeasuredData]:
    """Each uniform piece filtered (:func:`.filtering._filtered`); a piece too short for the
    filter dropped with a note when the run has others; the first piece's notes said once."""
    parts: list[MeasuredData] = []
    for a, b in pieces:
        try:
            part, part_notes = _filtered(t[a:b], q[a:b], None if qd is None else qd[a:b],
                                         None if qdd is None else qdd[a:b], forces[a:b], settings, path,
                                         coordinates, still)
        except InputError as exc:
            if len(pieces) == 1 or "too short" not in exc.reason:
                raise
            notes.append(f"the piece from {t[a]:.6g} to {t[b - 1]:.6g} s dropped: {exc.reason}")
            continue
        if not parts:
            notes += part_notes
        parts.append(part)
    return parts


def _skipped(description: Description, run: dict, key: str) -> set[str]:
    """The torque channels (their [torque] keys) ``skip`` leaves out of this run."""
    names = [c.coordinate for c in description.channels["torque"]]
    out = set()
    for k, name in enumerate(run.get("skip", [])):
        if name not in names:
            raise InputError(f"{name!r} is not a torque channel of this description ({', '.join(names)})",
                             file=description.path, key=f"{key}.skip[{k}]")
        out.add(name)
    return out


def _dead_channels(raw: np.ndarray, chans: list[Channel], skipped: set[str], description: Description,
                   name: str, key: str) -> list[str]:
    """Torque channels of this run without signal: exactly 0 in at least DEAD_SHARE of the
    rows, or one value in all of them. Refused (InputError naming the run, every such channel,
    its column and the share), or with ``[recording] dead = "skip"`` left out of the run
    (added to ``skipped``) with a note. A channel already left out is not looked at."""
    policy = description.data.get("recording", {}).get("dead", "refuse")
    dead = []
    for k, channel in enumerate(chans):
        if channel.absent or channel.coordinate in skipped:
            continue
        column = raw[:, k][np.isfinite(raw[:, k])]
        if len(column) < 2:
            continue
        zeros = float(np.mean(column == 0))
        if zeros >= DEAD_SHARE:
            dead.append((channel, f"0 in {100 * zeros:.3g} % of its {len(column)} rows"))
        elif np.ptp(column) == 0:
            dead.append((channel, f"{column[0]:g} in all of its {len(column)} rows"))
    if not dead:
        return []
    shown = "; ".join(f"{c.coordinate} (column {c.column!r}) is {what}" for c, what in dead)
    if policy == "skip":
        skipped.update(c.coordinate for c, _ in dead)
        return [f"torque channels without signal left out of run {name!r} (dead = \"skip\"): {shown}; the run's "
                "other channels are fitted"]
    names = [c.coordinate for c, _ in dead]
    raise InputError(f"run {name!r}: {shown}: a channel without signal (a dead sensor, a channel not logged) is "
                     f"never fitted; leave it out of this run with skip = {_toml_list(names)} in its [[runs]] ({key}), "
                     f"of every run with {names[0]} = \"none\" in [torque], or every dead channel with dead = "
                     "\"skip\" in [recording]", file=description.path, key=dead[0][0].key)


def _toml_list(names: list[str]) -> str:
    return "[" + ", ".join(f'"{n}"' for n in names) + "]"


def quantum(values: np.ndarray) -> float:
    """The step of the grid ``values`` lie on (a current logged in counts, a torque rounded to
    0.001: every difference between distinct values a whole number of steps, to GRID_TOLERANCE
    of a step), or 0 when they lie on none. Why: a step comparable to a channel's noise makes
    its residual structured (the rounding error follows the signal where it changes slowly):
    exact data rounded to the TIAGo's 0.001 on its wrist was called "unexplained"."""
    levels = np.unique(values[np.isfinite(values)])
    if len(levels) < 2:
        return 0.0
    gaps = np.diff(levels)
    smallest = float(gaps.min())
    for divisor in range(1, GRID_DIVISORS + 1):      # the step need not be a gap itself (1e-6 when
        step = smallest / divisor                    # no two values lie closer than 3e-6)
        ratio = gaps / step
        if np.abs(ratio - np.round(ratio)).max() <= GRID_TOLERANCE:
            return step
    return 0.0


def _unwrapped(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the angle unwrapped, the samples where it jumped): a step larger than half a turn
    between two samples is a wrap (an encoder or a topic that logs an angle modulo 2 pi: a
    joint would need 300 rad/s at 100 Hz to turn that far), undone by numpy's unwrap over the
    finite samples. Why: the jump differentiated was a spike the filter spread over seconds."""
    finite = np.flatnonzero(np.isfinite(angle))
    steps = np.diff(angle[finite])
    jumps = finite[1:][np.abs(steps) > np.pi]
    if not jumps.size:
        return angle, jumps
    out = angle.copy()
    out[finite] = np.unwrap(angle[finite])
    return out, jumps


def _independent_rows(mechanism: Mechanism, names: list[str], coordinates: tuple, path: str,
                      quantity: str) -> np.ndarray:
    """The channels' map from the independent coordinates: square and nonsingular."""
    rows = drive_rows(mechanism, names)
    index = [mechanism.coordinates.index(c) for c in coordinates]
    outside = [n for n, row in zip(names, rows) if np.any(np.delete(row, index) != 0)]
    if outside:
        raise InputError(f"{', '.join(outside)} move dependent coordinates: a {quantity} channel must be "
                         f"a combination of the independent ones ({', '.join(coordinates)})",
                         file=path, key=quantity)
    matrix = rows[:, index]
    if len(names) != len(coordinates):
        missing = [c for c in coordinates if c not in names]
        hint = (f"; a joint that does not move in the recording ({', '.join(missing)}?) is held at its value in "
                "[held] (COORD = value, or a pattern: \"*\" = 0 holds every joint without a channel)") if missing and len(names) < len(coordinates) else ""
        raise InputError(f"{len(names)} {quantity} channels for {len(coordinates)} independent coordinates "
                         f"({', '.join(coordinates)}): give one channel per coordinate{hint}", file=path,
                         key=quantity)
    singular = np.linalg.svd(matrix, compute_uv=False)
    if singular[-1] <= 1e-12 * singular[0]:
        raise InputError(f"the {quantity} channels {', '.join(names)} do not determine "
                         f"{', '.join(coordinates)}: their transmission is singular", file=path, key=quantity)
    return matrix


def _drive_note(description: Description) -> str:
    motors = ", ".join(f"{m.name} = " + " + ".join(f"{_ratio(r)} {c}" for c, r in m.ratios)
                       for m in description.mechanism.motors)
    return f"motor-side channels mapped through the drive chain ({motors}); torques to the joints by N^T"


def _ratio(value: Fraction) -> str:
    return str(value.numerator) if value.denominator == 1 else f"{float(value):g}"


def _joined(parts: list[MeasuredData], coordinates: tuple, path: str, notes: list[str], payloads: list,
            gain_names: tuple[str, ...]) -> MeasuredData:
    """The pieces of one run as one MeasuredData; ``tau`` of each piece holds the known
    forces and, behind them, one column per unknown gain (split here)."""
    filters = parts[0].filters                     # one filter for the run's pieces
    parts = [MeasuredData(p.motion, p.tau[:, :, 0], coordinates, path, (), p.estimated, segments=p.segments,
                          runs=("run",), gain_names=gain_names, gain_columns=p.tau[:, :, 1:],
                          unfiltered=None if p.unfiltered is None else p.unfiltered[:, :, 0],
                          unfiltered_gains=None if p.unfiltered is None else p.unfiltered[:, :, 1:]) for p in parts]
    joined = concatenate(parts, path=path)
    segments = tuple(replace(s, run=0) for s in joined.segments)
    return MeasuredData(joined.motion, joined.tau, coordinates, path, tuple(notes), joined.estimated,
                        segments=segments, runs=("run",),
                        payloads=tuple((0, label, phi) for label, phi in payloads),
                        gain_names=gain_names, gain_columns=joined.gain_columns,
                        unfiltered=joined.unfiltered, unfiltered_gains=joined.unfiltered_gains, filters=filters)
