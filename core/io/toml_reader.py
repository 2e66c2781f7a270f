"""The TOML mechanism format (docs/mechanism-format.md): parse, validate, walk the tables, call the builder.

The document is first checked against :data:`baseparams.io.schema.SCHEMA` (unknown keys
with a "did you mean", value types); everything that is not TOML (names, references,
exact values, physics, spanning tree, coordinates) is
:class:`baseparams.model.builder.MechanismBuilder`'s. This module only knows the tables
and the key paths that name them in errors (``joints[2].type``). TOML floats are parsed
as :class:`decimal.Decimal`, so no geometry passes through a binary float. A UTF-8 byte
order mark (which some Windows editors write) is skipped.
"""

import re
import tomllib
from decimal import Decimal
from pathlib import Path
from typing import Any

from baseparams.errors import InputError
from baseparams.io.schema import SCHEMA, ArrayOfTables, Table, validate
from baseparams.model.builder import MechanismBuilder
from baseparams.model.mechanism import Mechanism


def _keys(section: str) -> tuple[str, ...]:
    """The keys of a top-level table (or of each table of an array of tables)."""
    spec = SCHEMA.fields[section][0]
    table = spec.table if isinstance(spec, ArrayOfTables) else spec
    assert isinstance(table, Table)
    return tuple(table.fields)


TOP_LEVEL = tuple(SCHEMA.fields)
HEADER_KEYS = _keys("mechanism")
BODY_KEYS = _keys("bodies")
JOINT_KEYS = _keys("joints")
TRAJECTORY_KEYS = _keys("trajectory")
EFFECT_KEYS = _keys("effects")
BOM = "\ufeff"
LONG_INTEGER = re.compile(r"[0-9_]{4301,}")


class TomlReader:
    """The built-in reader of ``.toml`` mechanism files (registered by baseparams.plugins.readers)."""

    name = "toml"
    suffixes: tuple[str, ...] = (".toml",)
    description = "baseparams mechanism files (docs/mechanism-format.md)"
    options: tuple[str, ...] = ()

    def read_notes(self, path: str | Path, **options: Any) -> tuple[Mechanism, list[str]]:
        """The mechanism and no notes: the format holds everything the model does."""
        return self.read(path), []

    def read(self, path: str | Path, **options: Any) -> Mechanism:
        """The mechanism in the file at ``path`` (without the mobility check). The format
        has no options (``options`` is empty), so callers pass none."""
        path = Path(path)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise InputError("no such file", file=path) from None
        except OSError as exc:
            raise InputError(f"cannot read: {exc.strerror or exc}", file=path) from None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = data[:exc.start].count(b"\n") + 1
            raise InputError(f"not UTF-8 text: byte 0x{data[exc.start]:02x} at line {line} "
                             f"(byte {exc.start}); mechanism files are UTF-8", file=path) from None
        return parse_toml(text, path)


def parse_toml(text: str, path: str | Path = "<string>") -> Mechanism:
    """The mechanism described by TOML ``text`` (``path`` names it in errors)."""
    text = text.removeprefix(BOM)
    try:
        data = tomllib.loads(text, parse_float=Decimal)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML: {exc}", file=path) from None
    except ValueError:
        # int() refuses literals of more than 4300 digits (CPython's guard against slow
        # conversions); tomllib lets that ValueError through
        match = LONG_INTEGER.search(text)
        where = f" at line {text.count(chr(10), 0, match.start()) + 1}" if match else ""
        raise InputError(f"an integer with more than 4300 digits{where}: out of range", file=path) from None
    validate(data, str(path))
    return _Walker(data, str(path)).build()


class _Walker:
    """Walks the tables of a document the schema accepted, in file order, handing each value
    and its key path to the builder (which checks names, references and values)."""

    def __init__(self, data: dict[str, Any], path: str) -> None:
        self.data = data
        self.path = path

    def build(self) -> Mechanism:
        data = self.data
        head = data["mechanism"]
        b = MechanismBuilder(head["name"], self.path, title=head.get("title", ""),
                             description=head.get("description", ""), source=head.get("source", ""))
        for name, value in data.get("geometry", {}).items():
            b.geometry(name, value, key=f"geometry.{name}")
        if "gravity" in head:
            b.gravity(head["gravity"], key="mechanism.gravity")
        for i, body in enumerate(data["bodies"]):
            b.body(body["label"], body.get("name", ""), mass=body.get("mass"), com=body.get("com"),
                   inertia_com=body.get("inertia_com"), inertia=body.get("inertia"), key=f"bodies[{i}]")
        for i, joint in enumerate(data["joints"]):
            b.joint(joint["type"], joint["parent"], joint["child"], name=joint.get("name"),
                    parent_frame=joint["parent_frame"], child_frame=joint["child_frame"],
                    coordinates=joint.get("coordinates"), limits=joint.get("limits"),
                    loop=joint.get("loop", False), drive_limits=joint.get("drive_limits"), key=f"joints[{i}]")
        coordinates = data.get("coordinates", {})
        if "independent" in coordinates:
            b.independent(coordinates["independent"], key="coordinates.independent")
        if "trajectory" in data:
            trajectory = data["trajectory"]
            b.trajectory(trajectory["q"], t_start=trajectory.get("t_start", 0),
                         t_end=trajectory.get("t_end", 10), samples=trajectory.get("samples", 200),
                         key="trajectory")
        for i, coupling in enumerate(data.get("couplings", [])):
            b.coupling(coupling["coordinate"], coupling["leader"], coupling.get("ratio", 1),
                       coupling.get("offset", 0), key=f"couplings[{i}]")
        for i, motor in enumerate(data.get("motors", [])):
            b.motor(motor["name"], motor["ratios"], key=f"motors[{i}]")
        for i, effect in enumerate(data.get("effects", [])):
            b.effect(effect["kind"], effect["coordinate"], effect.get("values"), key=f"effects[{i}]")
        return b.build()
