"""The simulation a user already has, as standard parameters: ``diagnose --params SOURCE``.

SOURCE is a mechanism file (TOML or URDF: its own inertias, e.g. the CAD model's) with the
same bodies as the mechanism diagnosed, or the JSON of an earlier ``identify``: its base
parameters (any standard parameters that reproduce them give the same torques: those
nearest the mechanism's own inertias when it has them, so that each body's mass means
something, else the least-norm ones), its identified effects (known effects now), and the
base parameters' covariance, within which a change is the fit's own error, not a change.

Held values no robot has are held as they are, with a note (``Given.notes``, the report's
first notes): an identify result's estimates more than 3 std below zero where they must be
positive (:mod:`.impossible`: a negative friction or rotor inertia, a negative mass), and a
file's bodies whose inertia is not physical (a CAD URDF's that breaks the triangle
inequality). Why not refuse: the user's simulation is what it is, the forces it predicts are
defined all the same, and it is that simulation the user wants diagnosed (issue 48: the
Kinova Gen3's and the TIAGo's own URDFs were refused); but a correction named on such a
value may only undo it, which the note says.
"""

import json
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from baseparams.errors import InputError
from baseparams.dynamics.forces import standard_parameters
from baseparams.model.mechanism import EffectSpec, Mechanism


@dataclass(frozen=True)
class Given:
    """A simulation held as given: standard ``parameters`` (P,), the ``effects`` it brings;
    for an identify result the map ``base_map`` E (r, P) from standard to base parameters and
    their ``covariance`` (r, r; None when the JSON does not carry it); ``masses``: whether
    each body's mass in ``parameters`` is the body's (a file's, or completed from the
    mechanism's own inertias), not an arbitrary member of a group; ``gains``: the current
    gains an identify result estimated (``gain_COORD``: N m per unit of the channel)."""
    parameters: np.ndarray
    effects: list[EffectSpec] = field(default_factory=list)
    base_map: np.ndarray | None = None
    covariance: np.ndarray | None = None
    masses: bool = True
    gains: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)      # held values no robot has (before the run)
    fit_nrms: dict[str, float] = field(default_factory=dict)  # its residual NRMS on its own run, per coordinate
    fit_rms: dict[str, float] = field(default_factory=dict)   # and its residual RMS there (force units)
    recordings: tuple[str, ...] = ()  # what it was identified on (its JSON's ``data``: files, ``FILE#run``)


def _own_name(mechanism: Mechanism, name: str) -> str:
    """A standard parameter's name in either form (``m3``, or ``m_forearm`` for a URDF's
    link: issue 45) as ``mechanism`` writes it; any other name as it is."""
    try:
        return mechanism.parameter(name)
    except ValueError:
        return name


def given_parameters(mechanism: Mechanism, source: str) -> Given:
    """What ``source`` holds as given for ``mechanism``."""
    path = Path(source)
    if path.suffix.lower() == ".json":
        return _from_identify(mechanism, path)
    from baseparams.io.loader import resolve
    from baseparams.diagnose.derived import welded
    other = resolve(source)
    if list(other.parameters) != list(mechanism.parameters):
        raise InputError(f"its bodies do not match {mechanism.name}'s ({len(other.parameters)} standard "
                         f"parameters against {len(mechanism.parameters)}): give the same robot's file",
                         file=source, key="--params")
    # a body welded to the ground moves never: no force depends on its values
    still = {b for b, root in welded(other).items() if root == 0}
    bad = [reason for reason, label in zip((r for _, r in other.nonphysical), other.nonphysical_labels
                                           or (None,) * len(other.nonphysical)) if label not in still]
    notes = []
    if bad:
        notes.append(f"--params {source}: {len(bad)} bod{'y is' if len(bad) == 1 else 'ies are'} not physical, "
                     f"held as given all the same (the forces the file predicts are defined; a change named "
                     f"on such a body may only correct it): {'; '.join(bad)}")
    return Given(standard_parameters(other), notes=notes)


def _from_identify(mechanism: Mechanism, path: Path) -> Given:
    report = _read_report(path)
    file = str(path)
    base = report.get("base")
    if not isinstance(base, list) or not base:
        raise InputError("not the JSON of `baseparams identify` (no 'base' list)", file=file, key="base")
    _check_identity(mechanism, report, file)
    names = list(mechanism.parameters)
    E = np.zeros((len(base), len(names)))
    beta = np.zeros(len(base))
    for k, entry in enumerate(base):
        where = f"base[{k}]"
        if not isinstance(entry, dict):
            raise InputError(f"a base parameter is an object with a value and an expression, not "
                             f"{_kind(entry)}", file=file, key=where)
        beta[k] = _finite(entry.get("value"), file, f"{where}.value")
        expression = entry.get("expression")
        if not isinstance(expression, dict) or not expression:
            raise InputError(f"an expression is an object {{parameter: coefficient}} over {mechanism.name}'s "
                             f"standard parameters, not {_kind(expression)}", file=file, key=f"{where}.expression")
        for written, coefficient in expression.items():
            key = f"{where}.expression.{written}"
            name = _own_name(mechanism, written)
            if name not in names:
                raise InputError(f"{name!r} is not a standard parameter of {mechanism.name}", file=file, key=key)
            E[k, names.index(name)] = _coefficient(coefficient, file, key)
    own = all(b.inertia is not None for b in mechanism.bodies)
    prior = standard_parameters(mechanism) if own else np.zeros(len(names))
    phi = prior + np.linalg.lstsq(E, beta - E @ prior, rcond=None)[0]
    effects = []
    raw_effects = _list(report, "effects", file)
    for k, entry in enumerate(raw_effects):
        where = f"effects[{k}]"
        try:
            coordinate = entry["coordinate"]
            if not isinstance(entry["kind"], str) or not isinstance(coordinate, str):
                raise TypeError("kind and coordinate are names")
            values: dict[str, Any] = {}               # the JSON's numbers, as held before (floats)
            for j, c in enumerate(entry["coefficients"]):
                if c.get("value") is None:
                    continue
                values[str(c["name"]).rsplit("_" + coordinate, 1)[0]] = _finite(
                    c["value"], file, f"{where}.coefficients[{j}].value")
            effects.append(EffectSpec(entry["kind"], coordinate, values))
        except (KeyError, TypeError, AttributeError) as exc:
            raise InputError(f"an effect needs kind, coordinate and coefficients ({exc})", file=file,
                             key=where) from None
    gains = {}
    for k, entry in enumerate(_list(report, "gains", file)):
        try:
            gains[str(entry["name"])] = _finite(entry["value"], file, f"gains[{k}].value")
        except (KeyError, TypeError) as exc:
            raise InputError(f"a gain needs a name and a value ({exc})", file=file, key=f"gains[{k}]") from None
    covariance = _base_covariance(report, base, path)
    return Given(phi, effects, E, covariance, masses=own, gains=gains,
                 notes=_impossible_notes(mechanism, path, E, base, raw_effects, covariance),
                 fit_nrms=_per_coordinate(report, "nrms", file), fit_rms=_per_coordinate(report, "rms", file),
                 recordings=_recordings(report))


def _recordings(report: dict) -> tuple[str, ...]:
    """The recordings an identify result was fitted on (``data``: paths joined by ", ", a
    description's run as ``FILE#run``); anything else is ignored, as the result's own figures
    do not depend on it."""
    data = report.get("data")
    return tuple(part for part in data.split(", ") if part) if isinstance(data, str) else ()


def held_recordings(given: Given, result_file: str) -> list[str]:
    """The recordings the held identify result was fitted on that exist here (a path as
    written, or beside the result file; a description's ``#run`` kept): ``--baseline`` with
    them compares the two runs directly, where what both lack cancels."""
    found = []
    for spec in given.recordings:
        file, hash_, run = spec.partition("#")
        for path in (Path(file), Path(result_file).parent / file):
            if path.is_file():
                found.append(str(path) + hash_ + run)
                break
    return found


def _per_coordinate(report: dict, key: str, file: str) -> dict[str, float]:
    """The identify result's residual ``nrms`` or ``rms`` on its own run, per coordinate
    (absent in older results, null where undefined: left out)."""
    value = report.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"a table of coordinates is needed, not {_kind(value)}", file=file, key=key)
    return {str(c): _finite(v, file, f"{key}.{c}") for c, v in value.items() if v is not None}


# An identify result is a few kB to a few MB; a file far larger is not one (and is not read whole)
MAX_RESULT_BYTES = 200_000_000


def _read_report(path: Path) -> dict:
    """The JSON object of an identify result, or the InputError naming the file: unreadable,
    too large, not JSON, nested deeper than Python's parser goes (issue 46: 200 000 levels
    were a RecursionError), not an object."""
    file = str(path)
    try:
        if path.stat().st_size > MAX_RESULT_BYTES:
            raise InputError(f"{path.stat().st_size:,} bytes: larger than any identify result "
                             f"(at most {MAX_RESULT_BYTES:,} are read)", file=file, key="--params")
        report = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=file, key="--params") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start}): not JSON", file=file, key="--params") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"not JSON: {exc.msg} (line {exc.lineno})", file=file, key="--params") from None
    except RecursionError:
        raise InputError("not the JSON of `baseparams identify`: nested too deep to read", file=file,
                         key="--params") from None
    except ValueError as exc:               # a number of more than 4300 digits
        raise InputError(f"not the JSON of `baseparams identify`: {exc}", file=file, key="--params") from None
    if not isinstance(report, dict):
        raise InputError(f"not the JSON of `baseparams identify` (an object is needed, not {_kind(report)})",
                         file=file, key="--params")
    return report


def _check_identity(mechanism: Mechanism, report: dict, file: str) -> None:
    """The result is of this mechanism: the same name, and the same standard parameters where
    the result lists them. Why (issue 46): a pendulum's result was held for planar_2r (its
    parameters are among planar_2r's) and the diagnosis said UNEXPLAINED."""
    name = report.get("mechanism")
    if not isinstance(name, str):
        raise InputError("not the JSON of `baseparams identify` (no 'mechanism' name)", file=file, key="mechanism")
    if name != mechanism.name:
        raise InputError(f"the result of identify on {name!r}, not on {mechanism.name!r}: give a result of the "
                         f"same mechanism", file=file, key="mechanism")
    listed = report.get("parameters")
    if isinstance(listed, list):
        listed = [_own_name(mechanism, n) if isinstance(n, str) else n for n in listed]
    if listed is not None and listed != list(mechanism.parameters):
        count = len(listed) if isinstance(listed, list) else _kind(listed)
        raise InputError(f"its standard parameters ({count}) are not {mechanism.name}'s "
                         f"({len(mechanism.parameters)}): a result of another version of the mechanism file?",
                         file=file, key="parameters")


def _list(report: dict, key: str, file: str) -> list:
    """``report[key]``, a list (absent or null: empty)."""
    value = report.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise InputError(f"a list is needed, not {_kind(value)}", file=file, key=key)
    return value


def _finite(value: object, file: str, key: str) -> float:
    """A finite number (a JSON number or a decimal string), or the InputError naming ``key``."""
    try:
        number = float(value) if not isinstance(value, bool) else float("nan")  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        number = float("nan")
    if not np.isfinite(number):
        raise InputError(f"a finite number is needed, not {_shown(value)}", file=file, key=key)
    return number


def _coefficient(value: object, file: str, key: str) -> float:
    """A coefficient: a number, a decimal or ``p/q`` string (exact), finite."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return _finite(value, file, key)
    if not isinstance(value, str) or len(value) > 1000:
        raise InputError(f"a coefficient is a number or a string such as \"0.25\" or \"1/3\", not {_shown(value)}",
                         file=file, key=key)
    try:
        exact = Fraction(value.strip())
    except ZeroDivisionError:
        raise InputError(f"{value!r} divides by zero", file=file, key=key) from None
    except ValueError:
        raise InputError(f"{_shown(value)} is not a number (a decimal or p/q)", file=file, key=key) from None
    try:
        return _finite(float(exact), file, key)
    except OverflowError:
        raise InputError(f"{_shown(value)} is beyond any float", file=file, key=key) from None


def _kind(value: object) -> str:
    """What a JSON value is, for messages."""
    names = {dict: "an object", list: "a list", str: "a string", bool: "true/false", type(None): "null",
             int: "a number", float: "a number"}
    return names.get(type(value), type(value).__name__)


def _shown(value: object) -> str:
    text = repr(value) if isinstance(value, (str, int, float)) and not isinstance(value, bool) else _kind(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _impossible_notes(mechanism: Mechanism, path: Path, E: np.ndarray, base: list, effects: list,
                      covariance: np.ndarray | None) -> list[str]:
    """Notes naming the identify result's estimates no robot has, judged from its values and
    std as identify judges them (:func:`.impossible.judge`; a result of an older version has
    no "impossible" key, and the values are what is held)."""
    from baseparams import registry
    from baseparams.identify.impossible import beyond, beyond_body_scale, judge, mechanism_scales, split
    names = [str(entry.get("name", f"base[{k}]")) for k, entry in enumerate(base)]
    values = [float(entry["value"]) for entry in base]
    stds = [_number(entry.get("std")) for entry in base]
    coefficients: dict[str, tuple[str, str]] = {}
    absorbed: dict[str, dict[str, float]] = {}
    known = registry.effects()
    for entry in effects:
        kind, coordinate = entry.get("kind"), entry.get("coordinate")
        if kind not in known or not isinstance(coordinate, str):
            continue
        for c in entry.get("coefficients") or []:
            name = str(c.get("name"))
            coefficient = name.rsplit("_" + coordinate, 1)[0]
            coefficients[name] = (kind, coefficient)
            if c.get("value") is None:
                into = c.get("absorbed_into")
                if isinstance(into, dict):
                    shares = {str(k): _number(v) for k, v in into.items()}
                    absorbed[name] = {k: v for k, v in shares.items() if np.isfinite(v)}
                continue
            names.append(name)
            values.append(float(c["value"]))
            stds.append(_number(c.get("std")))
    flags = judge(parameters=list(mechanism.parameters), base_map=E, names=names, values=np.array(values),
                  std=np.array(stds), covariance=covariance, effects=coefficients, absorbed=absorbed,
                  bodies={b.label: b.name for b in mechanism.bodies})
    flags += beyond_body_scale([str(entry.get("name", f"base[{k}]")) for k, entry in enumerate(base)], E, names,
                               np.array(values), np.array(stds), mechanism_scales(mechanism, mechanism.parameters))
    impossible, near_zero = split(flags)
    notes = []
    far = beyond(flags)
    if far:
        notes.append(f"--params {path}: {len(far)} held value{'s' if len(far) > 1 else ''} beyond any physical scale, "
                     "held as given all the same (the data of that identification did not determine them; the "
                     "body masses completed from them may be no body's, and a changed body's mass is not judged "
                     "where the held one is not positive): "
                     + "; ".join(f.text() for f in far))
    if impossible:
        notes.append(f"--params {path}: {len(impossible)} held value{'s' if len(impossible) > 1 else ''} no robot "
                     f"has, held as given all the same (a correction named there may only undo it): "
                     + "; ".join(f.text() for f in impossible))
    if near_zero:
        # not "--params ..." first: the short report ranks those notes first, and these are not urgent
        notes.append(f"held values negative but consistent with zero (within their noise; --params {path}): "
                     + "; ".join(f.text() for f in near_zero))
    return notes


def _number(value: object) -> float:
    """A JSON number, NaN when absent (an exact value then: judged without noise)."""
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return float("nan")


def _base_covariance(report: dict, base: list, path: Path) -> np.ndarray | None:
    """The base parameters' covariance (r, r) from the result's ``covariance`` (names and
    matrix over every estimate), None when it has none (a result of an older version)."""
    held = report.get("covariance")
    if held is None:
        return None
    try:
        names = list(held["names"])
        matrix = np.array([[np.nan if v is None else float(v) for v in row] for row in held["matrix"]])
        index = [names.index(entry["name"]) for entry in base]
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise InputError(f"expected {{\"names\": [...], \"matrix\": [[...]]}} naming every base parameter "
                         f"({exc})", file=str(path), key="covariance") from None
    if matrix.shape != (len(names), len(names)):
        raise InputError(f"a {len(names)} x {len(names)} matrix is needed, not {matrix.shape}", file=str(path),
                         key="covariance.matrix")
    block = matrix[np.ix_(index, index)]
    return block if np.all(np.isfinite(block)) else None
