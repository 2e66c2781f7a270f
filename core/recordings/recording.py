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

Logs are read as tables of named columns by :mod:`.tables` (text: a header row, or
``names``, or ``stacked``), :mod:`.arrays` (``.npz``, ``.mat``) and :mod:`.bags` (ROS bags,
a table per topic on its own clock).

Nothing here rewrites a raw file; every error names the description or the log, the key
or the row and column, and the reason.
"""

import math
import os
import tomllib
from dataclasses import dataclass, replace
from decimal import Decimal
from fnmatch import fnmatchcase
from fractions import Fraction
from pathlib import Path

import numpy as np
import sympy
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from baseparams.errors import InputError
from baseparams.recordings.bags import STAMP, is_bag
from baseparams.recordings.clocks import (TIME_UNITS, _merged_rows, _on_one_clock, _owner, _selected, _times,
                                          _uniform_pieces)
from baseparams.recordings.implied import implied_description, implied_note
from baseparams.recordings.values import _exact, _number
from baseparams.recordings.tables import LOG, as_table, log_files, read_run_tables
from baseparams.recordings.data import (MAX_MAGNITUDE, MIN_SAMPLES, STILL_RANGE, UNIFORM_TOLERANCE, MeasuredData, NonUniform, Segment,
                                      _read_text, bandwidth, concatenate, kinematics)
from baseparams.dynamics.forces import Motion, drive_rows, independent_names
from baseparams.io.schema import INTEGER, STRING, VALUE, Array, ArrayOfTables, Map, Table, _Validator
from baseparams.model.builder import MechanismBuilder
from baseparams.model.held import hold
from baseparams.model.mechanism import Mechanism

# Default filter: the positions' cut-off is this multiple of their bandwidth (Gautier's rule
# of thumb: 5 to 10 times the dynamics' band keeps the derivatives' phase and amplitude).
CUTOFF_PER_BANDWIDTH = 10.0
BUTTERWORTH_ORDER = 4
# The parallel filter's cut-off sits at this fraction of the decimated Nyquist frequency.
DECIMATION_BAND = 0.8
# Rows dropped at each end of a segment: this many periods of the cut-off (filter transients).
EDGE_PERIODS = 3.0
UNITS = {"position": {"rad": 1.0, "deg": math.pi / 180, "rev": 2 * math.pi, "m": 1.0, "mm": 1e-3},
         "velocity": {"rad/s": 1.0, "deg/s": math.pi / 180, "rpm": 2 * math.pi / 60, "m/s": 1.0, "mm/s": 1e-3},
         "acceleration": {"rad/s2": 1.0, "deg/s2": math.pi / 180, "m/s2": 1.0, "mm/s2": 1e-3},
         "torque": {"N m": 1.0, "Nm": 1.0, "N": 1.0, "kN": 1e3, "mN m": 1e-3, "mNm": 1e-3, "N mm": 1e-3,
                    "A": 1.0, "mA": 1e-3}}
QUANTITIES = ("position", "velocity", "acceleration", "torque")
DESCRIPTION = "a recording description (TOML)"
GRID_TOLERANCE = 1e-3              # of a step: values on a grid (quantum)
GRID_DIVISORS = 10                 # the step tried: the smallest gap over 1 .. this
VELOCITY_MISMATCH = 0.05          # measured velocity vs the positions' derivative: a note above this
QUANTUM_RELEVANT = 1e-6            # a grid finer than this times a channel's RMS is not quantisation
# A torque channel exactly 0 in at least this share of a run's rows, or one value in all of
# them, carries no signal (a dead sensor, a channel the logger did not fill): refused, or left
# out of the run (skip, dead = "skip"). Why: a column of zeros was fitted as measured: "noise
# SD 1e-100", NRMS 0, and a TIAGo's three wrists at 0 in 85-87 % of rows named "gains" of -0.99.
DEAD_SHARE = 0.8
NO_CHANNEL = ("none", "")          # [torque] COORD = "none": the coordinate has no torque channel
DEAD_POLICIES = ("refuse", "skip")
SLOW_BAND = 0.1                    # Hz: a motion slower than this over a whole log: a time unit wrong?
PATTERN_CHARACTERS = "*?["

CHANNEL = Table({"column": (STRING, True), "scale": (VALUE, False), "offset": (VALUE, False),
                 "unit": (STRING, False), "gain": (VALUE, False)})
SCHEMA = Table({
    "recording": (Table({"name": (STRING, False), "time": (STRING, False), "time_unit": (STRING, False),
                         "rate": (VALUE, False), "step": (VALUE, False), "delimiter": (STRING, False),
                         "comment": (STRING, False), "dead": (STRING, False),
                         "gravity": (Array(VALUE, 3, what="[gx, gy, gz] in the base's axes, m/s^2"), False)}),
                  False),
    "runs": (ArrayOfTables(Table({
        "name": (STRING, False), "file": (LOG, False), "files": (Map(LOG), False),
        "window": (Array(VALUE, 2, what="[start, end] in seconds"), False),
        "rows": (Array(INTEGER, 2, what="[first, last] rows of the log, the header being row 1"), False),
        "skip": (Array(STRING, what="a list of torque channels ([torque] keys) left out of this run"), False),
        "payload": (Table({"body": (VALUE, True), "mass": (VALUE, True), "com": (Array(VALUE, 3), False),
                           "inertia": (Array(VALUE, 6, what="a list of 6 numbers (Ixx, Ixy, Ixz, Iyy, "
                                                              "Iyz, Izz) about the centre of mass"), False)}),
                    False),
    }), min_length=1), True),
    "motors": (ArrayOfTables(Table({"name": (STRING, True), "ratios": (Map(VALUE), True)})), False),
    "position": (Map(CHANNEL), True),
    "velocity": (Map(CHANNEL), False),
    "acceleration": (Map(CHANNEL), False),
    "torque": (Map(CHANNEL), True),
    "zero": (Map(VALUE), False),
    "held": (Map(VALUE), False),
    "filter": (Table({"cutoff": (VALUE, False), "order": (INTEGER, False), "decimate": (INTEGER, False)}),
               False),
})
"""The description's tables (docs/identification.md); a channel may also be a plain string,
the column."""


@dataclass(frozen=True)
class Channel:
    quantity: str
    coordinate: str              # a joint coordinate or a motor
    file: str | None             # the run's file alias (None: the run's only file)
    column: str
    scale: float
    offset: float
    key: str
    unknown_gain: bool = False   # a current whose gain the fit identifies (a payload run fixes it)
    absent: bool = False         # [torque] COORD = "none": no channel; the coordinate's force is not fitted


@dataclass(frozen=True)
class Description:
    path: str
    data: dict
    channels: dict               # quantity -> [Channel]
    mechanism: Mechanism         # with the description's motors added


# ----- the description ---------------------------------------------------------------------
def is_description(path: str | os.PathLike) -> bool:
    """A data argument names a recording description (TOML, ``FILE.toml#RUN,RUN`` for some of
    its runs), not a CSV log."""
    return Path(str(path).partition("#")[0]).suffix.lower() == ".toml"


def holds(path: str | os.PathLike) -> bool:
    """Whether the recording description at ``path`` has a ``[held]`` table with entries
    (False for a CSV log, or a description that cannot be read: reading it says why)."""
    if not is_description(path):
        return False
    try:
        data = tomllib.loads(_read_text(str(path).partition("#")[0], DESCRIPTION), parse_float=Decimal)
    except (InputError, tomllib.TOMLDecodeError):
        return False
    return isinstance(data.get("held"), dict) and bool(data["held"])


def read_description(path: str | os.PathLike, mechanism: Mechanism) -> Description:
    """The description at ``path``, checked against ``mechanism`` (its motors added)."""
    path = str(path)
    text = _read_text(path, DESCRIPTION)
    try:
        data = tomllib.loads(text, parse_float=Decimal)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML: {exc}", file=path) from None
    return describe(data, path, mechanism)


def describe(data: dict, path: str, mechanism: Mechanism) -> Description:
    """A description's parsed TOML ``data`` (numbers as Decimal), checked against
    ``mechanism``; ``path``: where it stands (logs are relative to its folder; messages name it).
    One home for a description written by a user and one implied by a log's layout
    (:mod:`.implied`)."""
    for quantity in QUANTITIES:                # a plain string is the column
        table = data.get(quantity)
        if isinstance(table, dict):
            data[quantity] = {k: {"column": v} if isinstance(v, str) else v for k, v in table.items()}
    _plain_paths_as_tables(data)
    _Validator(path).check(SCHEMA, data, "")
    _bag_clock(data, path)
    mechanism = _with_motors(mechanism, data.get("motors", []), path)
    held = _held_values(data, mechanism, path)
    mechanism = hold(mechanism, held, file=path)
    if "gravity" in data.get("recording", {}):          # the robot mounted otherwise than its model
        mechanism = replace(mechanism, gravity=tuple(
            sympy.Rational(g.numerator, g.denominator) for g in
            (_exact(v, path, f"recording.gravity[{k}]") for k, v in enumerate(data["recording"]["gravity"]))))
    if held and not independent_names(mechanism):
        raise InputError("every coordinate is held: nothing moves in this recording to fit", file=path,
                         key="held")
    channels = {q: [_channel(q, name, spec, mechanism, path) for name, spec in data.get(q, {}).items()]
                for q in QUANTITIES}
    for quantity in ("position", "torque"):
        if not channels[quantity]:
            raise InputError(f"no {quantity} channels: give one per independent coordinate "
                             f"({', '.join(independent_names(mechanism))}), or hold a joint that does not move "
                             "in [held]", file=path, key=quantity)
    if channels["acceleration"] and not channels["velocity"]:
        raise InputError("acceleration channels need velocity channels too", file=path, key="acceleration")
    for name in data.get("zero", {}):
        if name not in independent_names(mechanism):
            raise InputError(f"{name!r} is not an independent coordinate of {mechanism.name} "
                             f"({', '.join(independent_names(mechanism))})", file=path, key=f"zero.{name}")
    _check_time_source(data.get("recording", {}), path)
    return Description(path, data, channels, mechanism)


def _plain_paths_as_tables(data: dict) -> None:
    """Each run's ``file`` and ``files`` entries as tables (``{ path = ... }``), so that a
    path and a headerless or stacked log (``{ path, names, stacked }``) are checked alike."""
    runs = data.get("runs")
    if not isinstance(runs, list):
        return
    for run in runs:
        if not isinstance(run, dict):
            continue
        if "file" in run:
            run["file"] = as_table(run["file"])
        if isinstance(run.get("files"), dict):
            run["files"] = {alias: as_table(entry) for alias, entry in run["files"].items()}


def _bag_clock(data: dict, path: str) -> None:
    """A description whose every log is a ROS bag and that gives no clock reads the messages'
    stamps (``time = "header.stamp"``); a bag's clock is in seconds, so ``time_unit`` is refused."""
    entries = [entry["path"] for run in data["runs"] for entry in
               ([run["file"]] if "file" in run else list(run.get("files", {}).values()))]
    head = data.setdefault("recording", {})
    bags = [is_bag(Path(path).parent / p) for p in entries]
    if bags and all(bags) and not any(k in head for k in ("time", "rate", "step")):
        head["time"] = STAMP
    if any(bags) and "time_unit" in head:
        raise InputError("a ROS bag's clock is read in seconds (time = \"header.stamp\" or \"log_time\"): leave "
                         "time_unit out", file=path, key="recording.time_unit")


def _held_values(data: dict, mechanism: Mechanism, path: str) -> dict[str, Fraction]:
    """``[held]``'s coordinates and values: ``COORD = value``, or a pattern (``"hand_*" = 0``,
    ``"*" = 0``: fnmatch's ``*``, ``?``, ``[...]``) for every independent coordinate it matches
    that has no channel of its own or through a motor. A coordinate named by itself takes its
    own value; two patterns giving one coordinate different values are an error. Why: a robot's
    model can have dozens of joints its log does not have (a TIAGo's hand, head and wheels: 40
    joints beside the 8 logged), each of which had to be listed by name."""
    given = data.get("held", {})
    channelled: set[str] = set()
    for quantity in QUANTITIES:
        for name in data.get(quantity, {}):
            channelled.add(name)
            channelled.update(c for m in mechanism.motors if m.name == name for c, _ in m.ratios)
    held = {name: _exact(value, path, f"held.{name}") for name, value in given.items()
            if not any(ch in name for ch in PATTERN_CHARACTERS)}
    for quantity in QUANTITIES:
        for name in data.get(quantity, {}):
            if name in held:
                raise InputError(f"{name!r} is held ([held]): it has no {quantity} channel", file=path,
                                 key=f"{quantity}.{name}")
    by_pattern: dict[str, tuple[str, Fraction]] = {}
    for pattern, value in given.items():
        if not any(ch in pattern for ch in PATTERN_CHARACTERS):
            continue
        exact = _exact(value, path, f"held.{pattern}")
        matched = [c for c in independent_names(mechanism) if fnmatchcase(c, pattern) and c not in channelled]
        if not matched and pattern.strip("*") == "":
            continue        # "*": every coordinate without a channel, which may be none (a run that logs them all)
        if not matched:
            raise InputError(f"the pattern {pattern!r} matches no coordinate without a channel "
                             f"(coordinates: {', '.join(independent_names(mechanism))})", file=path,
                             key=f"held.{pattern}")
        for coordinate in matched:
            if coordinate in held and coordinate not in by_pattern:
                continue                                    # named by itself: its own value
            if coordinate in by_pattern and by_pattern[coordinate][1] != exact:
                raise InputError(f"{coordinate!r} is matched by {by_pattern[coordinate][0]!r} and {pattern!r} "
                                 "with different values: hold it by name", file=path, key=f"held.{pattern}")
            by_pattern[coordinate] = (pattern, exact)
            held[coordinate] = exact
    return held


def _with_motors(mechanism: Mechanism, motors: list, path: str) -> Mechanism:
    """``mechanism`` with the description's ``[[motors]]`` (the drive chain, when the
    mechanism file has none: a URDF without transmissions), checked by the builder's rules."""
    if not motors:
        return mechanism
    builder = MechanismBuilder(mechanism.name, path)
    added = []
    for i, spec in enumerate(motors):
        key = f"motors[{i}]"
        if spec["name"] in mechanism.coordinates:
            raise InputError(f"{spec['name']!r} is a joint coordinate: a motor needs its own name",
                             file=path, key=f"{key}.name")
        motor = builder.motor(spec["name"], spec["ratios"], key=key)
        if spec["name"] in mechanism.motor_names:
            if mechanism.motor(spec["name"]) != motor:
                raise InputError(f"motor {spec['name']!r} is in the mechanism with other ratios", file=path,
                                 key=f"{key}.ratios")
            continue
        for coordinate, _ in motor.ratios:
            if coordinate not in mechanism.coordinates:
                raise InputError(f"{coordinate!r} is not a joint coordinate of {mechanism.name} "
                                 f"({', '.join(mechanism.coordinates)})", file=path,
                                 key=f"{key}.ratios.{coordinate}")
        added.append(motor)
    return replace(mechanism, motors=tuple(mechanism.motors) + tuple(added))


def _channel(quantity: str, name: str, spec: dict, mechanism: Mechanism, path: str) -> Channel:
    key = f"{quantity}.{name}"
    if name not in mechanism.coordinates and name not in mechanism.motor_names:
        motors = f"; motors: {', '.join(mechanism.motor_names)}" if mechanism.motors else \
            "; declare motors in [[motors]] for motor-side channels"
        raise InputError(f"{name!r} is not a joint coordinate or a motor of {mechanism.name} "
                         f"(coordinates: {', '.join(mechanism.coordinates)}{motors})", file=path, key=key)
    if spec["column"].strip().lower() in NO_CHANNEL:
        if quantity != "torque" or set(spec) != {"column"}:
            raise InputError(f"{spec['column']!r}: only a torque channel may be absent (its coordinate's force is "
                             "then left out of the fit while its motion drives the others)", file=path, key=key)
        return Channel(quantity, name, None, "", 1.0, 0.0, key, absent=True)
    scale = _number(spec.get("scale", 1), path, f"{key}.scale")
    if "unit" in spec:
        units = UNITS[quantity]
        if spec["unit"] not in units:
            raise InputError(f"unknown unit {spec['unit']!r}; known: {', '.join(units)}", file=path,
                             key=f"{key}.unit")
        scale *= units[spec["unit"]]
    unknown = spec.get("gain") == "unknown"
    if "gain" in spec:
        if quantity != "torque":
            raise InputError("a gain converts a current to a torque: torque channels only", file=path,
                             key=f"{key}.gain")
        if not unknown:
            scale *= _number(spec["gain"], path, f"{key}.gain")
    if scale == 0:
        raise InputError("a scale (or gain) of 0 would erase the channel", file=path, key=key)
    file, _, column = spec["column"].rpartition(":")
    if not column:
        raise InputError(f"{spec['column']!r}: expected COLUMN or FILE:COLUMN", file=path, key=f"{key}.column")
    return Channel(quantity, name, file or None, column, scale,
                   _number(spec.get("offset", 0), path, f"{key}.offset"), key, unknown)


def _check_time_source(head: dict, path: str) -> None:
    given = [k for k in ("time", "rate", "step") if k in head]
    if head.get("time_unit") == "samples":
        if "time" not in head or len(given) != 2:
            raise InputError("time_unit = \"samples\" (a time column counting samples) needs the time column and "
                             "one of rate (Hz) or step (s)" + (f"; found {', '.join(given)}" if given else ""),
                             file=path, key="recording.time_unit")
        given = ["time"]
    if len(given) != 1:
        raise InputError("give exactly one of time (a column), rate (Hz) or step (s)"
                         + (f"; found {', '.join(given)}" if given else "")
                         + ("; a time column that counts samples: time_unit = \"samples\" with the rate"
                            if "time" in given else ""), file=path, key="recording")
    if "time_unit" in head and head["time_unit"] not in TIME_UNITS:
        raise InputError(f"unknown time unit {head['time_unit']!r}; known: {', '.join(TIME_UNITS)}",
                         file=path, key="recording.time_unit")
    for k in ("rate", "step"):
        if k in head and not _number(head[k], path, f"recording.{k}") > 0:
            raise InputError("must be positive", file=path, key=f"recording.{k}")
    if head.get("dead", "refuse") not in DEAD_POLICIES:
        raise InputError(f"{head['dead']!r}: one of {', '.join(DEAD_POLICIES)} (a torque channel without signal "
                         "is refused, or left out of its run with a note)", file=path, key="recording.dead")


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
    path, key = description.path, f"runs[{index}]"
    mechanism = description.mechanism
    coordinates = independent_names(mechanism)
    folder = Path(path).parent
    head = description.data.get("recording", {})
    logs = log_files(run, path, key)
    skipped = _skipped(description, run, key)
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

    def values(channel: Channel) -> np.ndarray:
        if channel.absent or (channel.quantity == "torque" and channel.coordinate in skipped):
            return np.zeros(len(t))                    # a torque left out: zero, its coordinates masked
        alias = None if channel.file is None and None in tables else _owner(tables, groups, channel, path, key)
        header, table, _ = tables[alias]
        if channel.column not in header:
            raise InputError(f"no column {channel.column!r} (columns: {', '.join(header)})",
                             file=str(folder / files[alias]), key="header")
        with np.errstate(all="ignore"):
            out = channel.scale * table[channel.column] + channel.offset
        if not np.all(np.abs(out[~np.isnan(out)]) <= MAX_MAGNITUDE):
            raise InputError(f"scaled by {channel.scale:g} (and shifted by {channel.offset:g}) the column leaves "
                             f"the range |value| <= {MAX_MAGNITUDE:g}", file=path, key=channel.key)
        return out

    wrap_notes: list[str] = []
    quantised_notes: list[str] = []
    torque_channels: list = []            # (raw, map) of the torque channels, for the dead-channel check
    quanta = np.zeros(len(coordinates))

    def mapped(quantity: str, transpose: bool = False) -> np.ndarray | None:
        chans = description.channels[quantity]
        if not chans:
            return None
        names = [c.coordinate for c in chans]
        matrix = _independent_rows(mechanism, names, coordinates, path, quantity)
        raw = np.stack([values(c) for c in chans], axis=1)
        if quantity == "position":                      # an angle logged modulo a turn
            for k, channel in enumerate(chans):
                if mechanism.is_angle(channel.coordinate):
                    raw[:, k], jumps = _unwrapped(raw[:, k])
                    if jumps.size:
                        wrap_notes.append(f"{channel.coordinate}: {jumps.size} jump(s) of a turn unwrapped (an angle "
                                          f"logged modulo 2 pi; first at row {rows[int(jumps[0])]})")
        if transpose:                                    # tau = N^T tau_channels; with unknown gains
            torque_channels.append((raw, matrix))
            known = np.array([not c.unknown_gain for c in chans])   # each such channel's own column
            steps = np.array([quantum(raw[:, k]) if known[k] else 0.0 for k in range(len(chans))])
            size = np.array([np.sqrt(np.mean(c[np.isfinite(c)] ** 2)) if np.isfinite(c).any() else 0.0
                             for c in raw.T])
            steps[steps < QUANTUM_RELEVANT * size] = 0.0     # a value printed to many digits: not rounding
            quanta[:] = np.abs(matrix).T @ steps
            if steps.any():
                quantised_notes.append("quantised torque channels, their values on a grid of (in the model's "
                                       "units): " + ", ".join(f"{chans[k].coordinate} {steps[k]:.4g}"
                                                              for k in np.flatnonzero(steps)))
            forces = [(raw * known) @ matrix] + [raw[:, k:k + 1] * matrix[k] for k in np.nonzero(~known)[0]]
            return np.stack(forces, axis=2)              # (N, f, 1 + unknown gains)
        return np.linalg.solve(matrix, raw.T).T

    q = mapped("position")
    assert q is not None                  # the description requires positions
    for coordinate, value in description.data.get("zero", {}).items():
        q[:, coordinates.index(coordinate)] += _number(value, path, f"zero.{coordinate}")
    qd, qdd, forces = mapped("velocity"), mapped("acceleration"), mapped("torque", transpose=True)
    assert forces is not None             # ... and torques
    gain_names = tuple(f"gain_{c.coordinate}" for c in description.channels["torque"] if c.unknown_gain)
    notes = clock_notes + wrap_notes + quantised_notes + ([_drive_note(description)] if any(c.coordinate in mechanism.motor_names
                                                             for chans in description.channels.values()
                                                             for c in chans) else [])
    # samples with a missing value (an empty or NaN field) in a channel used are left out; the
    # steps around them are resampled, or the run split where GAP_STEPS or more are missing
    present = np.all([np.all(np.isfinite(a.reshape(len(t), -1)), axis=1)
                      for a in (q, qd, qdd, forces) if a is not None], axis=0)
    if not present.all():
        lost = np.nonzero(~present)[0]
        notes.append(f"{lost.size} sample(s) with a missing value (an empty or NaN field) in a channel used "
                     f"left out (first at row {rows[int(lost[0])]})")
    # a sample stamped with the time of the one before (a logger that wrote it twice, or a
    # clock coarser than its rate) is left out: a step of zero cannot be differentiated
    kept = np.flatnonzero(present)
    repeated = kept[1:][np.diff(t[kept]) == 0]
    if repeated.size:
        present[repeated] = False
        notes.append(f"{repeated.size} sample(s) stamped with the time of the sample before left out "
                     f"(first at row {rows[int(repeated[0])]})")
    if not present.all():
        t, rows = t[present], [line for line, keep in zip(rows, present) if keep]
        q, forces = q[present], forces[present]
        qd = None if qd is None else qd[present]
        qdd = None if qdd is None else qdd[present]
    pieces, split_notes = _uniform_pieces(t, t_file, rows, path)
    notes += split_notes
    (raw_torques, torque_map), = torque_channels       # channels without signal: refused, or left out
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
    data.quanta = quanta if quanta.any() else None
    return data


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


def auto_cutoff(signal: np.ndarray, step: float, what: str) -> tuple[float, str]:
    """The default cut-off (Hz) for ``signal`` sampled every ``step`` s, and how it was chosen:
    CUTOFF_PER_BANDWIDTH times its bandwidth (:func:`.data.bandwidth`: the spectrum above the
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


def _payload(spec: dict | None, mechanism: Mechanism, path: str, key: str) -> list[tuple[int, np.ndarray]]:
    """A known load fixed to a body: its ten parameters about the body's origin, in body axes
    (mass, centre of mass in the body frame, inertia about the centre of mass)."""
    if spec is None:
        return []
    body = spec["body"]
    labels = {b.name: b.label for b in mechanism.bodies if b.name}
    if isinstance(body, str) and body in labels:
        label = labels[body]
    elif isinstance(body, int) and not isinstance(body, bool) and body in mechanism.body_labels:
        label = body
    else:
        raise InputError(f"no body {body!r} in {mechanism.name} (bodies: "
                         f"{', '.join(b.name or str(b.label) for b in mechanism.bodies)})", file=path,
                         key=f"{key}.body")
    mass = _number(spec["mass"], path, f"{key}.mass")
    if mass <= 0:
        raise InputError("a payload's mass must be positive", file=path, key=f"{key}.mass")
    c = np.array([_number(v, path, f"{key}.com[{i}]") for i, v in enumerate(spec.get("com", [0, 0, 0]))])
    i6 = [_number(v, path, f"{key}.inertia[{i}]") for i, v in enumerate(spec.get("inertia", [0] * 6))]
    inertia = np.array([[i6[0], i6[1], i6[2]], [i6[1], i6[3], i6[4]], [i6[2], i6[4], i6[5]]])
    eigen = np.linalg.eigvalsh(inertia)
    if eigen[0] < -1e-12 * max(1.0, abs(eigen[-1])) or eigen[-1] > eigen[0] + eigen[1] + 1e-12 * max(1, eigen[-1]):
        raise InputError("the payload's inertia about its centre of mass is not a mass distribution's "
                         "(positive, triangle inequality)", file=path, key=f"{key}.inertia")
    at_origin = inertia + mass * (c @ c * np.eye(3) - np.outer(c, c))
    phi = np.array([mass, *(mass * c), at_origin[0, 0], at_origin[0, 1], at_origin[0, 2],
                    at_origin[1, 1], at_origin[1, 2], at_origin[2, 2]])
    return [(label, phi)]
