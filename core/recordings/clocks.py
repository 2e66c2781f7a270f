"""One run's tables on one clock: time stamps, the samples of a run, gaps.

A run's logs are tables of named columns (:mod:`.tables`, :mod:`.arrays`, :mod:`.bags`);
here they are brought onto one clock: a table whose columns are filled on different rows
(topics merged into one file) is read on its torque channels' rows, files (or a bag's
topics) on their own clocks are interpolated onto the clock of the first torque channel's,
the time is read from a column (any unit, a sample index with the rate) or made from a rate
or a step, a run's ``rows`` and ``window`` are selected (an empty window gives the log's span),
and a run is split at gaps. Split out of :mod:`.recording` (issue 44), whose reader of a
run (:func:`.recording._read_run`) calls these in that order.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from baseparams.errors import InputError
from baseparams.recordings.bags import STAMP
from baseparams.recordings.smoothing import MIN_SAMPLES
from baseparams.recordings.values import _number

if TYPE_CHECKING:
    from baseparams.recordings.description import Channel, Description

# A time step longer than this many median steps splits a run (a gap in the log).
GAP_STEPS = 10.0
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "iso": 1.0,   # iso: dates and times, in s from the first
              "samples": 1.0}                              # a sample index, times rate's step (rate or step given)
MERGED_SHARE = 0.5                 # a column missing on more of the reference rows: topics merged
# A time column of whole numbers in steps of 1 read as seconds is a sample index (a Kinova's
# Time: 0, 1, 2, ...): refused unless time_unit says so. Why: read as seconds, viscous friction
# came out 1000 times too large, exit 0.
SAMPLE_INDEX_SHARE = 0.99


def _owner(tables: dict, groups: dict, channel: Channel, path: str, key: str) -> object:
    """The table (its alias) that holds the channel's column: among the files of its alias
    (``FILE:COLUMN``; a bag's topics) or of the run, the one whose header has it."""
    candidates = [a for a in tables if channel.file is None or groups[a] == channel.file]
    if not candidates:
        aliases = ", ".join(sorted({str(g) for g in groups.values()}))
        raise InputError(f"no file aliased {channel.file!r} in {key}.files ({aliases})", file=path,
                         key=f"{channel.key}.column")
    owners = [a for a in candidates if channel.column in tables[a][0]]
    if len(owners) == 1:
        return owners[0]
    if not owners and len(candidates) == 1:
        return candidates[0]                 # its header says what it has
    if not owners:
        shown = "; ".join(f"{a[1] if isinstance(a, tuple) else a}: {', '.join(tables[a][0][:8])}" for a in candidates)
        raise InputError(f"no column {channel.column!r} in the run's files ({shown})", file=path,
                         key=f"{channel.key}.column")
    raise InputError(f"column {channel.column!r} is in {len(owners)} of the run's files: write "
                     "FILE:COLUMN with the file's alias", file=path, key=f"{channel.key}.column")


def _selected(run: dict, t: np.ndarray, rows: list[int], tables: dict, head: dict, path: str, key: str
              ) -> tuple[np.ndarray, list[int], dict]:
    """(t, rows, tables) of the run's part of the log: its ``rows = [first, last]`` (the log's
    rows; FIGAROH's protocols give rows, a clock reset splits a log) and its ``window`` (s,
    in the clock ``window`` reads); too few samples there is an error giving the log's span."""
    def keep(inside: np.ndarray) -> tuple[np.ndarray, list[int], dict]:
        kept = [line for line, k in zip(rows, inside) if k]
        return t[inside], kept, {alias: (header, {c: v[inside] for c, v in table.items()}, kept)
                                 for alias, (header, table, _) in tables.items()}

    if "rows" in run:
        first, last = run["rows"]
        inside = np.array([first <= line <= last for line in rows], dtype=bool)
        if inside.sum() < MIN_SAMPLES:
            raise InputError(f"{int(inside.sum())} samples in rows {first} to {last} (the log's samples are on rows "
                             f"{rows[0]} to {rows[-1]})", file=path, key=f"{key}.rows")
        t, rows, tables = keep(inside)
    if "window" in run:
        start, end = (_number(v, path, f"{key}.window") for v in run["window"])
        inside = (t >= start) & (t <= end)
        if inside.sum() < MIN_SAMPLES:
            raise InputError(f"{int(inside.sum())} samples between {start:g} and {end:g} s: {_span(t, head)}",
                             file=path, key=f"{key}.window")
        t, rows, tables = keep(inside)
    return t, rows, tables


def _span(t: np.ndarray, head: dict) -> str:
    """The log's time span, as ``window`` reads it. Why: "0 samples between 0 and 200 s" did
    not say that the log's own clock ran from 838 to 888 s."""
    clock = ("counted from the run's first stamp" if head.get("time_unit") == "iso" or head.get("time") in (STAMP, "log_time")
             else "in the log's own clock" if "time" in head else "from its first sample")
    return (f"the log's time runs from {t[0]:.6g} to {t[-1]:.6g} s ({clock}); window = [start, end] is read in that "
            "clock") if len(t) else "the log has no samples"


def _merged_rows(head: dict, tables: dict, files: dict, description: Description, groups: dict
                 ) -> tuple[dict, list[str]]:
    """(tables, notes): a file holding the time column whose used columns are present on
    different rows (a logger that merges topics into one table, each row filled by one topic)
    is read on the rows of its torque channels (else its position channels): a used column
    missing on more than MERGED_SHARE of those rows is interpolated from its own rows onto
    their times (cubic for positions and velocities, linear otherwise; NaN outside its span,
    left out later as missing values are), and the file is cut to those rows. Why: every row
    missed some channel, and all were left out ("0 samples"). A column missing on fewer rows
    (a dropped packet) is not touched: those samples are left out as before."""
    column = str(head.get("time", "")).rpartition(":")[2]
    if not column:
        return tables, []
    smooth = {(c.file, c.column) for q in ("position", "velocity", "acceleration") for c in description.channels[q]}
    torques = {(c.file, c.column) for c in description.channels["torque"]}
    out, notes = dict(tables), []
    for alias, (header, table, rows) in tables.items():
        if column not in table:
            continue
        group = groups[alias]
        used = [name for name in table if name != column]
        mine = [name for name in used if (group, name) in torques or (None, name) in torques] or \
            [name for name in used if (group, name) in smooth or (None, name) in smooth]
        if not mine:
            continue
        keep = np.all([np.isfinite(table[name]) for name in mine], axis=0)
        others = [name for name in used if name not in mine and keep.any()
                  and np.mean(~np.isfinite(table[name][keep])) > MERGED_SHARE]
        if not others:
            continue
        clock = table[column]
        moved = {name: values[keep] for name, values in table.items()}
        for name in others:
            own = np.isfinite(table[name]) & np.isfinite(clock)
            moved[name] = _onto(clock[own], table[name][own], clock[keep],
                                (group, name) in smooth or (None, name) in smooth) if own.sum() >= 4 else \
                np.full(int(keep.sum()), np.nan)
        out[alias] = (header, moved, [line for line, k in zip(rows, keep) if k])
        notes.append(f"{files[alias]}: its columns are filled on different rows (topics merged into one table): "
                     f"read on the {int(keep.sum())} rows of {', '.join(mine)}, with "
                     f"{', '.join(others)} interpolated onto their times from their own rows")
    return out, notes


def _onto(x: np.ndarray, y: np.ndarray, at: np.ndarray, cubic: bool) -> np.ndarray:
    """``y`` sampled at ``x`` (increasing; NaN where missing) at the times ``at``: a cubic
    spline through the finite samples (positions and velocities, ``cubic``) or linear, NaN
    outside ``x``'s span and next to a missing value (left out later as missing values are).
    One home for reading a column on another clock (:func:`_merged_rows`, :func:`_on_one_clock`)."""
    from scipy.interpolate import CubicSpline      # here: most runs share one clock
    out = np.interp(at, x, y)                                  # NaN next to a missing value
    finite = np.isfinite(y)
    if cubic and finite.sum() >= 4 and np.all(np.diff(x[finite]) > 0):
        out = np.where(np.isfinite(out), CubicSpline(x[finite], y[finite])(at), np.nan)
    return np.where((at >= x[0]) & (at <= x[-1]), out, np.nan)


def _on_one_clock(head: dict, tables: dict, files: dict, description: Description, folder: Path,
                  groups: dict) -> tuple[dict, list[str]]:
    """(tables, notes): when the time column is in every file of a run and the files' clocks
    differ (a logger that writes one file per topic, each stamped on arrival), every other
    file's columns interpolated onto the clock of the file with the first torque channel
    (cubic for positions and velocities, linear otherwise), NaN where that clock leaves their
    span or next to a missing value (left out later as missing values are); else the tables
    as read. Why: such files have different row counts, and were refused ("the files of one
    run must have the same rows"); the torques' clock, since the fourteenth session, because a
    torque interpolated across a Coulomb friction's jump takes a value the model does not."""
    column = str(head.get("time", ""))
    if not column or ":" in column or len(tables) < 2 or not all(column in h for h, _, _ in tables.values()):
        return tables, []
    first_channel = next((c for c in description.channels["torque"] if not c.absent),
                         description.channels["torque"][0])
    first = _owner(tables, groups, first_channel, description.path, "runs")
    reference = tables[first][1][column]
    if all(np.array_equal(table[column], reference) for _, table, _ in tables.values()):
        return tables, []
    out, notes = {}, []
    for alias, (header, table, rows) in tables.items():
        clock = table[column]
        bad = np.nonzero(~np.isfinite(clock))[0]
        if bad.size == 0:
            back = np.nonzero(np.diff(clock) < 0)[0]
            bad = back + 1
        if bad.size:
            raise InputError("time is not finite or goes back", file=str(folder / files[alias]),
                             key=f"row {rows[int(bad[0])]}, column {column}")
        if alias == first:
            out[alias] = (header, table, rows)
            continue
        once = np.r_[True, np.diff(clock) > 0]            # a repeated stamp: its first sample
        clock, table = clock[once], {name: values[once] for name, values in table.items()}
        inside = (reference >= clock[0]) & (reference <= clock[-1])
        smooth = {c.column for q in ("position", "velocity", "acceleration") for c in description.channels[q]
                  if c.file in (None, groups[alias])}
        moved = {name: _onto(clock, values, reference, name in smooth) for name, values in table.items()}
        moved[column] = reference
        out[alias] = (header, moved, tables[first][2])
        notes.append(f"{files[alias]}: its columns interpolated onto the clock of {files[first]} (cubic for "
                     f"positions and velocities, linear otherwise, in their own column {column}; {len(clock)} rows "
                     f"onto {len(reference)}"
                     + (f"; {int((~inside).sum())} sample(s) outside its span left out)" if not inside.all() else ")"))
    return out, notes


def _times(head: dict, tables: dict, files: dict, path: str, groups: dict) -> tuple[np.ndarray, str]:
    count = len(next(iter(tables.values()))[2])
    if "time" not in head:
        step = 1 / _number(head["rate"], path, "recording.rate") if "rate" in head else \
            _number(head["step"], path, "recording.step")
        return np.arange(count) * step, str(files[next(iter(files))])
    alias, _, column = head["time"].rpartition(":")
    alias = alias or None
    owners = [a for a, (header, _, _) in tables.items() if column in header and (alias is None or groups[a] == alias)]
    if len(owners) > 1 and all(np.array_equal(tables[a][1][column], tables[owners[0]][1][column]) for a in owners):
        owners = owners[:1]                  # one clock in every file (as written, or made so: _on_one_clock)
    if len(owners) != 1:
        raise InputError(f"time column {head['time']!r} found in {len(owners)} files of the run",
                         file=path, key="recording.time")
    header, table, rows = tables[owners[0]]
    t = table[column]
    if np.isnan(t).any():                    # a missing time stamp: no sample can be placed
        raise InputError("time is not finite (an empty or NaN field)", file=str(files[owners[0]]),
                         key=f"row {rows[int(np.nonzero(np.isnan(t))[0][0])]}, column {column}")
    unit = head.get("time_unit")
    if unit == "samples":
        step = 1 / _number(head["rate"], path, "recording.rate") if "rate" in head else \
            _number(head["step"], path, "recording.step")
        return t * step, str(files[owners[0]])
    counted = _counts_samples(t) if unit is None else 0.0
    if counted:
        raise InputError(f"the time column {column!r} counts samples ({t[0]:.0f}, {t[1]:.0f}, {t[2]:.0f}, ... in steps "
                         f"of {counted:.0f}), not seconds: read as seconds the rate would be {1 / counted:.3g} Hz, "
                         "and every time constant (viscous friction, inertia) 1000 times off at 1 kHz; give the "
                         "rate: time_unit = \"samples\" and rate = HZ in [recording] (or rate = HZ without time), "
                         "or time_unit = \"s\" if it is in seconds", file=path, key="recording.time")
    return t * TIME_UNITS[unit or "s"], str(files[owners[0]])


def _counts_samples(t: np.ndarray) -> float:
    """The step of a time column of whole numbers that steps by one whole number (1, or 2 in
    a log keeping every second sample) in almost every row (at least SAMPLE_INDEX_SHARE; a
    gap is a dropped sample): a sample index, not seconds; else 0."""
    if len(t) < 3 or not np.all(t == np.round(t)):
        return 0.0
    steps = np.diff(t)
    step = float(np.median(steps))
    return step if step >= 1 and np.mean(steps == step) >= SAMPLE_INDEX_SHARE else 0.0


def _uniform_pieces(t: np.ndarray, t_file: str, rows: list[int], path: str
                    ) -> tuple[list[tuple[int, int]], list[str]]:
    """Row ranges of the run between gaps; times (finite: :func:`_times`) must increase."""
    steps = np.diff(t)
    bad = np.nonzero(steps <= 0)[0]
    if bad.size:
        k = int(bad[0]) + 1
        raise InputError(f"time {t[k]:.17g} s does not increase (previous row: {t[k - 1]:.17g} s; a clock reset "
                         "or logs joined end to end: give each part its own run, rows = [first, last])",
                         file=t_file, key=f"row {rows[k]}")
    if len(t) < MIN_SAMPLES:
        raise InputError(f"{len(t)} samples; at least {MIN_SAMPLES} are needed", file=t_file)
    median = float(np.median(steps))
    gaps = np.nonzero(steps > GAP_STEPS * median)[0]
    cuts = [0] + [int(g) + 1 for g in gaps] + [len(t)]
    pieces = [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b - a >= MIN_SAMPLES]
    notes = []
    if gaps.size:
        notes.append(f"split at {gaps.size} gap(s) longer than {GAP_STEPS:g} median steps (first at row "
                     f"{rows[int(gaps[0]) + 1]}): {len(pieces)} pieces filtered apart"
                     + ("" if len(pieces) == len(cuts) - 1 else "; pieces too short to use dropped"))
    return pieces, notes
