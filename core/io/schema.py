"""The schema of TOML mechanism files, in one place: every table, key and value type.

:data:`SCHEMA` declares the document (docs/mechanism-format.md is its prose);
:func:`validate` checks a parsed document against it *before* anything is built, so
that the builder only ever sees values of the right shape. Every refusal is an
:class:`~baseparams.errors.InputError` naming the file, the key path (``joints[2].type``)
and the reason: an unknown key says which known key it is closest to ("did you mean
'type'?", by :mod:`difflib`), a wrong type says what was expected and what was found.
What the schema cannot say (names, references, exact values, physical consistency) is
:class:`baseparams.model.builder.MechanismBuilder`'s, which every reader shares.

:func:`json_schema` renders the same declaration as a JSON Schema (draft 2020-12) for
editors and other tools; tests/test_builder.py checks that the two agree on every
built-in file.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from baseparams.errors import InputError


# ----- the declaration --------------------------------------------------------------

@dataclass(frozen=True)
class Scalar:
    """One TOML value of the given kinds: "string", "integer", "number" (a TOML float,
    read as a Decimal) or "boolean"."""
    kinds: tuple[str, ...]
    what: str                      # in messages: "a string", "a number or an expression"


@dataclass(frozen=True)
class Array:
    item: Spec
    length: int | None = None      # exact length, or None: any (at least ``min_length``)
    min_length: int = 0
    what: str = ""


@dataclass(frozen=True)
class Table:
    """A table with known keys (``fields``: name -> (spec, required))."""
    fields: dict[str, tuple[Spec, bool]]
    what: str = "a table"


@dataclass(frozen=True)
class Map:
    """A table whose keys are names the file chooses (geometry names, coordinates)."""
    value: Spec
    what: str = "a table"


@dataclass(frozen=True)
class ArrayOfTables:
    table: Table
    min_length: int = 0


Spec = Scalar | Array | Table | Map | ArrayOfTables


STRING = Scalar(("string",), "a string")
INTEGER = Scalar(("integer",), "an integer")
BOOLEAN = Scalar(("boolean",), "true or false")
VALUE = Scalar(("string", "integer", "number"), "a number or an expression string")
VECTOR = Array(VALUE, 3, what="a list of 3 numbers or expressions")
NAMES = Array(STRING, what="a list of names")

FRAME = Table({"point": (VECTOR, True), "axis": (VECTOR, False), "ref": (VECTOR, False)})
PARAMETERS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")

SCHEMA = Table({
    "mechanism": (Table({
        "name": (STRING, True), "title": (STRING, False), "description": (STRING, False),
        "source": (STRING, False), "gravity": (VECTOR, False),
    }), True),
    "geometry": (Map(VALUE), False),
    "bodies": (ArrayOfTables(Table({
        "label": (INTEGER, True), "name": (STRING, False),
        "inertia": (Table({k: (VALUE, True) for k in PARAMETERS}), False),
        "mass": (VALUE, False), "com": (VECTOR, False),
        "inertia_com": (Array(VALUE, 6, what="a list of 6 numbers or expressions "
                                             "(Ixx, Ixy, Ixz, Iyy, Iyz, Izz)"), False),
    }), min_length=1), True),
    "joints": (ArrayOfTables(Table({
        "name": (STRING, False), "type": (STRING, True), "parent": (INTEGER, True),
        "child": (INTEGER, True), "coordinates": (NAMES, False), "loop": (BOOLEAN, False),
        "limits": (Map(Array(VALUE, 2, what="[low, high]")), False),
        "drive_limits": (Map(Table({"velocity": (VALUE, False), "effort": (VALUE, False)})), False),
        "parent_frame": (FRAME, True), "child_frame": (FRAME, True),
    }), min_length=1), True),
    "coordinates": (Table({"independent": (NAMES, False)}), False),
    "trajectory": (Table({
        "t_start": (VALUE, False), "t_end": (VALUE, False), "samples": (INTEGER, False),
        "q": (Map(VALUE), True),
    }), False),
    "couplings": (ArrayOfTables(Table({
        "coordinate": (STRING, True), "leader": (STRING, True), "ratio": (VALUE, False), "offset": (VALUE, False),
    })), False),
    "motors": (ArrayOfTables(Table({
        "name": (STRING, True), "ratios": (Map(VALUE), True),
    })), False),
    "effects": (ArrayOfTables(Table({
        "kind": (STRING, True), "coordinate": (STRING, True), "values": (Map(VALUE), False),
    })), False),
})
"""The whole document. Key order is the documented order (docs/mechanism-format.md)."""


# ----- validation -------------------------------------------------------------------

def validate(data: dict, path: str | None = None) -> None:
    """Raise an InputError at the first value of ``data`` (a parsed TOML document) that the
    schema refuses; tables are checked in file order, unknown keys before missing ones."""
    _Validator(path).check(SCHEMA, data, "")


def type_word(value: object) -> str:
    """The TOML name of a parsed value's type, for messages ("an array", "a boolean")."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, (Decimal, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return "a date/time" if type(value).__module__ == "datetime" else f"a {type(value).__name__}"


def shown_key(key: object, limit: int = 40) -> str:
    """A key quoted for a message: escapes control characters, cuts long keys."""
    text = repr(str(key))
    return text if len(text) <= limit else f"{text[:limit - 5]}...' ({len(str(key))} characters)"


def suggestion(word: str, known: Iterable[str]) -> str:
    """ " (did you mean 'type'?)" when ``word`` is close to one of ``known``, else ""."""
    close = difflib.get_close_matches(str(word)[:100], list(known), n=1, cutoff=0.6)
    if not close:
        lowered = {k.lower(): k for k in known}
        close = [lowered[str(word).lower()]] if str(word).lower() in lowered else []
    return f"; did you mean {close[0]!r}?" if close else ""


class _Validator:
    def __init__(self, path: str | None) -> None:
        self.path = path

    def error(self, key: str, reason: str) -> InputError:
        return InputError(reason, file=self.path, key=key or None)

    def check(self, spec: Spec, value: object, key: str) -> None:
        if isinstance(spec, Scalar):
            self.scalar(spec, value, key)
        elif isinstance(spec, Array):
            self.array(spec, value, key)
        elif isinstance(spec, Table):
            self.table(spec, value, key)
        elif isinstance(spec, Map):
            if not isinstance(value, dict):
                raise self.error(key, f"must be {spec.what}, not {type_word(value)}")
            for name, item in value.items():
                self.check(spec.value, item, _join(key, name))
        else:
            self.array_of_tables(spec, value, key)

    def scalar(self, spec: Scalar, value: object, key: str) -> None:
        kind = ("boolean" if isinstance(value, bool) else "integer" if isinstance(value, int)
                else "number" if isinstance(value, Decimal) else "string" if isinstance(value, str) else None)
        if kind not in spec.kinds:
            raise self.error(key, f"must be {spec.what}, not {type_word(value)}")

    def array(self, spec: Array, value: object, key: str) -> None:
        what = spec.what or "an array"
        if not isinstance(value, list):
            raise self.error(key, f"must be {what}, not {type_word(value)}")
        if spec.length is not None and len(value) != spec.length:
            raise self.error(key, f"must be {what}, got {len(value)} item{'s' * (len(value) != 1)}")
        if len(value) < spec.min_length:
            raise self.error(key, f"must be {what} with at least {spec.min_length}")
        for i, item in enumerate(value):
            self.check(spec.item, item, f"{key}[{i}]")

    def table(self, spec: Table, value: object, key: str) -> None:
        if not isinstance(value, dict):
            raise self.error(key, f"must be {spec.what}, not {type_word(value)}")
        known = tuple(spec.fields)
        for name, item in value.items():
            if name not in spec.fields:
                what = "section" if not key else "key"
                raise self.error(_join(key, name), f"unknown {what}{suggestion(name, known)} "
                                                    f"(known: {', '.join(known)})")
            self.check(spec.fields[name][0], item, _join(key, name))
        for name, (_, required) in spec.fields.items():
            if required and name not in value:
                raise self.error(_join(key, name), "missing (required)")

    def array_of_tables(self, spec: ArrayOfTables, value: object, key: str) -> None:
        if not isinstance(value, list):
            raise self.error(key, f"must be an array of tables ([[{key}]]), not {type_word(value)}")
        if len(value) < spec.min_length:
            raise self.error(key, f"at least {spec.min_length} [[{key}]] table is required")
        for i, item in enumerate(value):
            self.table(spec.table, item, f"{key}[{i}]")


def _join(key: str, name: object) -> str:
    name = str(name)
    text = name if name and all(c.isalnum() or c in "_-" for c in name) and name.isascii() else shown_key(name)
    return f"{key}.{text}" if key else text


# ----- the same as a JSON Schema --------------------------------------------------

_JSON_KINDS = {"string": {"type": "string"}, "integer": {"type": "integer"},
               "number": {"type": "number"}, "boolean": {"type": "boolean"}}


def json_schema() -> dict[str, Any]:
    """:data:`SCHEMA` as a JSON Schema (draft 2020-12), for tools that read one. TOML floats
    appear as JSON numbers; exact values and names are the builder's to check."""
    out = _json(SCHEMA)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": "baseparams mechanism file (docs/mechanism-format.md)", **out}


def _json(spec: Spec) -> dict[str, Any]:
    if isinstance(spec, Scalar):
        kinds = [_JSON_KINDS[k] for k in spec.kinds]
        return kinds[0] if len(kinds) == 1 else {"anyOf": kinds}
    if isinstance(spec, Array):
        out: dict[str, Any] = {"type": "array", "items": _json(spec.item)}
        if spec.length is not None:
            out["minItems"] = out["maxItems"] = spec.length
        elif spec.min_length:
            out["minItems"] = spec.min_length
        return out
    if isinstance(spec, Table):
        return {"type": "object", "properties": {k: _json(s) for k, (s, _) in spec.fields.items()},
                "required": [k for k, (_, r) in spec.fields.items() if r], "additionalProperties": False}
    if isinstance(spec, Map):
        return {"type": "object", "additionalProperties": _json(spec.value)}
    array: dict[str, Any] = {"type": "array", "items": _json(spec.table)}
    if spec.min_length:
        array["minItems"] = spec.min_length
    return array


