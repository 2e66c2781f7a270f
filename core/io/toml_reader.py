"""The TOML mechanism format (docs/mechanism-format.md): parse, walk the tables, call the builder.

Everything that is not TOML (names, references, exact values, spanning tree, coordinates)
is :class:`baseparams.model.builder.MechanismBuilder`'s; this module only knows the
tables and the key paths that name them in errors (``joints[2].type``). TOML floats are
parsed as :class:`decimal.Decimal`, so no geometry passes through a binary float.
"""

import tomllib
from decimal import Decimal
from pathlib import Path

from baseparams.errors import InputError
from baseparams.model.builder import MechanismBuilder
from baseparams.model.mechanism import Mechanism

TOP_LEVEL = ("mechanism", "geometry", "bodies", "joints", "coordinates", "trajectory", "effects")
HEADER_KEYS = ("name", "title", "description", "source", "gravity")
BODY_KEYS = ("label", "name", "inertia", "mass", "com", "inertia_com")
JOINT_KEYS = ("name", "type", "parent", "child", "coordinates", "loop", "limits",
              "parent_frame", "child_frame")
TRAJECTORY_KEYS = ("t_start", "t_end", "samples", "q")
EFFECT_KEYS = ("kind", "coordinate", "values")


class TomlReader:
    """The built-in reader of ``.toml`` mechanism files (registered by baseparams.plugins.readers)."""

    name = "toml"
    suffixes = (".toml",)
    description = "baseparams mechanism files (docs/mechanism-format.md)"

    def read(self, path: str | Path) -> Mechanism:
        """The mechanism in the file at ``path`` (without the mobility check)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise InputError("no such file", file=path) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read: {exc}", file=path) from None
        return parse_toml(text, path)


def parse_toml(text: str, path: str | Path = "<string>") -> Mechanism:
    """The mechanism described by TOML ``text`` (``path`` names it in errors)."""
    try:
        data = tomllib.loads(text, parse_float=Decimal)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML: {exc}", file=path) from None
    return _Walker(data, str(path)).build()


class _Walker:
    """Walks the TOML tables in file order, handing each value and its key path to the builder."""

    def __init__(self, data: dict, path: str):
        self.data = data
        self.path = path

    def error(self, key, reason):
        return InputError(reason, file=self.path, key=key)

    def table(self, obj, key, required=False):
        value = obj.get(key.split(".")[-1])
        if value is None:
            if required:
                raise self.error(key, "missing (required)")
            return {}
        if not isinstance(value, dict):
            raise self.error(key, f"must be a table, not {type(value).__name__}")
        return value

    def array_of_tables(self, key):
        raw = self.data.get(key)
        if not isinstance(raw, list) or not raw:
            raise self.error(key, f"at least one [[{key}]] table is required")
        for i, item in enumerate(raw):
            if not isinstance(item, dict):
                raise self.error(f"{key}[{i}]", "must be a table")
        return raw

    def check_keys(self, table, key, known):
        unknown = set(table) - set(known)
        if unknown:
            raise self.error(key, f"unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(known)})")

    def build(self) -> Mechanism:
        data = self.data
        for key in data:
            if key not in TOP_LEVEL:
                raise self.error(key, f"unknown section (known: {', '.join(sorted(TOP_LEVEL))})")
        head = self.table(data, "mechanism", required=True)
        self.check_keys(head, "mechanism", HEADER_KEYS)
        b = MechanismBuilder(head.get("name"), self.path, title=head.get("title", ""),
                             description=head.get("description", ""), source=head.get("source", ""))
        for name, value in self.table(data, "geometry").items():
            b.geometry(name, value, key=f"geometry.{name}")
        if "gravity" in head:
            b.gravity(head["gravity"], key="mechanism.gravity")
        for i, body in enumerate(self.array_of_tables("bodies")):
            key = f"bodies[{i}]"
            self.check_keys(body, key, BODY_KEYS)
            b.body(body.get("label"), body.get("name", ""), mass=body.get("mass"), com=body.get("com"),
                   inertia_com=body.get("inertia_com"), inertia=body.get("inertia"), key=key)
        for i, joint in enumerate(self.array_of_tables("joints")):
            key = f"joints[{i}]"
            self.check_keys(joint, key, JOINT_KEYS)
            b.joint(joint.get("type"), joint.get("parent"), joint.get("child"), name=joint.get("name"),
                    parent_frame=joint.get("parent_frame"), child_frame=joint.get("child_frame"),
                    coordinates=joint.get("coordinates"), limits=joint.get("limits"),
                    loop=joint.get("loop", False), key=key)
        coordinates = self.table(data, "coordinates")
        self.check_keys(coordinates, "coordinates", ("independent",))
        if "independent" in coordinates:
            b.independent(coordinates["independent"], key="coordinates.independent")
        trajectory = self.table(data, "trajectory")
        if trajectory:
            self.check_keys(trajectory, "trajectory", TRAJECTORY_KEYS)
            b.trajectory(self.table(trajectory, "trajectory.q", required=True),
                         t_start=trajectory.get("t_start", 0), t_end=trajectory.get("t_end", 10),
                         samples=trajectory.get("samples", 200), key="trajectory")
        effects = self.data.get("effects", [])
        if not isinstance(effects, list):
            raise self.error("effects", "must be an array of tables: [[effects]]")
        for i, effect in enumerate(effects):
            key = f"effects[{i}]"
            if not isinstance(effect, dict):
                raise self.error(key, "must be a table")
            self.check_keys(effect, key, EFFECT_KEYS)
            b.effect(effect.get("kind"), effect.get("coordinate"), effect.get("values"), key=key)
        return b.build()
