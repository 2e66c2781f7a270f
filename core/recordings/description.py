"""Recording descriptions: the TOML that maps a robot's raw logs onto the model, read and checked.

The tables (:data:`SCHEMA`; docs/identification.md, "Recording descriptions"): where time
comes from, the runs and their logs, the drive chain's motors, the channels of each quantity
with their units, scales and gains, joint zeros, held joints, the filter and known payloads.
:func:`describe` checks them against the mechanism (motors added, held joints made rigid,
the mounting's gravity) and gives a :class:`Description`, which :mod:`.recording` reads the
logs of. Every error names the description, the key and the reason.
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

from baseparams.dynamics.forces import independent_names
from baseparams.errors import InputError
from baseparams.io.schema import INTEGER, STRING, VALUE, Array, ArrayOfTables, Map, Table, _Validator
from baseparams.model.builder import MechanismBuilder
from baseparams.model.held import hold
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.bags import STAMP, is_bag
from baseparams.recordings.clocks import TIME_UNITS
from baseparams.recordings.delimited import _read_text
from baseparams.recordings.tables import LOG, as_table
from baseparams.recordings.values import _exact, _number

UNITS = {"position": {"rad": 1.0, "deg": math.pi / 180, "rev": 2 * math.pi, "m": 1.0, "mm": 1e-3},
         "velocity": {"rad/s": 1.0, "deg/s": math.pi / 180, "rpm": 2 * math.pi / 60, "m/s": 1.0, "mm/s": 1e-3},
         "acceleration": {"rad/s2": 1.0, "deg/s2": math.pi / 180, "m/s2": 1.0, "mm/s2": 1e-3},
         "torque": {"N m": 1.0, "Nm": 1.0, "N": 1.0, "kN": 1e3, "mN m": 1e-3, "mNm": 1e-3, "N mm": 1e-3,
                    "A": 1.0, "mA": 1e-3}}
QUANTITIES = ("position", "velocity", "acceleration", "torque")
DESCRIPTION = "a recording description (TOML)"
NO_CHANNEL = ("none", "")          # [torque] COORD = "none": the coordinate has no torque channel
DEAD_POLICIES = ("refuse", "skip")
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
