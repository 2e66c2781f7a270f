"""Read mechanism files (TOML) into :class:`baseparams.model.mechanism.Mechanism`.

The format is documented in docs/mechanism-format.md. Every problem is reported as an
:class:`baseparams.errors.InputError` naming the file, the key path and the reason.
TOML floats are parsed as :class:`decimal.Decimal`, so no geometry passes through a
binary float.
"""

import re
import tomllib
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import sympy

from baseparams import registry
from baseparams.errors import InputError, KinematicsError
from baseparams.model.expressions import ExpressionError, parse_decimal, parse_expression, to_fraction
from baseparams.model.mechanism import Body, Frame, Joint, Mechanism, TrajectorySpec, TreeEdge
from baseparams.model.params import PARAMETER_KINDS, from_mass_properties

NAME_RE = re.compile(r"^[a-z0-9_]+$")
IDENT_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
RESERVED = {"t", "pi", "sin", "cos", "exp", "sqrt"}


def resolve(mech):
    """A registered mechanism name or a path to a mechanism file -> Mechanism."""
    path = Path(mech)
    known = registry.mechanisms()
    if mech in known:
        return load_mechanism(known[mech].item.path)
    if path.suffix == ".toml" or path.exists():
        return load_mechanism(path)
    raise InputError(f"unknown mechanism {mech!r}: not a registered name "
                     f"({', '.join(known) or 'none registered'}) and not a file")


def load_mechanism(path):
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", file=path) from None
    return parse_mechanism(text, path)


def parse_mechanism(text, path="<string>"):
    try:
        data = tomllib.loads(text, parse_float=Decimal)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML: {exc}", file=path) from None
    return _Builder(data, path).build()


class _Builder:
    def __init__(self, data, path):
        self.data = data
        self.path = str(path)

    def error(self, key, reason):
        return InputError(reason, file=self.path, key=key)

    # ----- small readers ----------------------------------------------------
    def table(self, obj, key, required=False):
        value = obj.get(key.split(".")[-1]) if isinstance(obj, dict) else None
        if value is None:
            if required:
                raise self.error(key, "missing (required)")
            return {}
        if not isinstance(value, dict):
            raise self.error(key, f"must be a table, not {type(value).__name__}")
        return value

    def expr(self, value, key, time=False):
        try:
            return parse_expression(value, self.geometry_names, time=time)
        except ExpressionError as exc:
            raise self.error(key, str(exc)) from None

    def vector(self, value, key):
        if not isinstance(value, list) or len(value) != 3:
            raise self.error(key, f"must be a list of 3 numbers or expressions, got {value!r}")
        return tuple(self.expr(v, f"{key}[{i}]") for i, v in enumerate(value))

    def exact(self, value, key):
        expr = self.expr(value, key)
        return to_fraction(expr.subs(self.geometry_subs))

    # ----- sections ---------------------------------------------------------
    def build(self):
        data = self.data
        known_top = {"mechanism", "geometry", "bodies", "joints", "coordinates", "trajectory"}
        for key in data:
            if key not in known_top:
                raise self.error(key, f"unknown section (known: {', '.join(sorted(known_top))})")
        head = self.table(data, "mechanism", required=True)
        name = head.get("name")
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise self.error("mechanism.name", "required: lower-case letters, digits and _ only")
        self.read_geometry()
        gravity = self.vector(head.get("gravity", ["0", "0", "-9.81"]), "mechanism.gravity")
        bodies = self.read_bodies()
        types = registry.joint_types()
        joints = self.read_joints({b.label for b in bodies}, types)
        tree, loops = self.spanning_tree(joints, [b.label for b in bodies])
        coordinates = tuple(c for edge in tree for c in edge.joint.coordinates)
        independent = self.read_independent(coordinates, loops)
        trajectory = self.read_trajectory(independent or coordinates)
        gruebler = 6 * len(bodies) - sum(6 - j.type.dof for j in joints)
        mech = Mechanism(
            name=name, bodies=tuple(bodies), joints=tuple(joints), tree=tuple(tree),
            loops=tuple(loops), coordinates=coordinates, independent=independent,
            geometry=dict(self.geometry), gravity=gravity, trajectory=trajectory,
            title=str(head.get("title", "")), description=str(head.get("description", "")),
            source=str(head.get("source", "")), path=self.path, gruebler=gruebler)
        self.check_mobility(mech)
        return mech

    def read_geometry(self):
        raw = self.table(self.data, "geometry")
        self.geometry = {}
        for key, value in raw.items():
            if not IDENT_RE.match(key) or key in RESERVED or key in PARAMETER_KINDS:
                raise self.error(f"geometry.{key}", "not a usable name (identifier, not t, pi or a function)")
            try:
                self.geometry[key] = parse_decimal(value)
            except ExpressionError as exc:
                raise self.error(f"geometry.{key}", str(exc)) from None
        self.geometry_names = tuple(self.geometry)
        self.geometry_subs = {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator)
                              for k, v in self.geometry.items()}

    def read_bodies(self):
        raw = self.data.get("bodies")
        if not isinstance(raw, list) or not raw:
            raise self.error("bodies", "at least one [[bodies]] table is required")
        bodies, seen = [], set()
        for i, b in enumerate(raw):
            key = f"bodies[{i}]"
            if not isinstance(b, dict):
                raise self.error(key, "must be a table")
            label = b.get("label")
            if not isinstance(label, int) or isinstance(label, bool) or label < 1:
                raise self.error(f"{key}.label", "required: an integer >= 1 (ground is 0)")
            if label in seen:
                raise self.error(f"{key}.label", f"duplicate body label {label}")
            seen.add(label)
            bodies.append(Body(label, str(b.get("name", "")), self.read_inertia(b, key)))
        return sorted(bodies, key=lambda body: body.label)

    def read_inertia(self, b, key):
        if "inertia" in b and "mass" in b:
            raise self.error(key, "give either inertia (about the origin) or mass/com/inertia_com, not both")
        if "inertia" in b:
            table = b["inertia"]
            if not isinstance(table, dict) or set(table) != set(PARAMETER_KINDS):
                raise self.error(f"{key}.inertia", f"needs exactly the keys {', '.join(PARAMETER_KINDS)}")
            return tuple(self.exact(table[k], f"{key}.inertia.{k}") for k in PARAMETER_KINDS)
        if "mass" in b:
            mass = self.exact(b["mass"], f"{key}.mass")
            com = [to_fraction(c.subs(self.geometry_subs)) for c in self.vector(b.get("com"), f"{key}.com")]
            raw = b.get("inertia_com")
            if not isinstance(raw, list) or len(raw) != 6:
                raise self.error(f"{key}.inertia_com", "needs 6 entries: Ixx Ixy Ixz Iyy Iyz Izz")
            tensor = [self.exact(v, f"{key}.inertia_com[{i}]") for i, v in enumerate(raw)]
            return tuple(from_mass_properties(mass, com, tensor))
        return None

    def read_frame(self, raw, key):
        if not isinstance(raw, dict):
            raise self.error(key, "required: a table with point (and axis, ref)")
        unknown = set(raw) - {"point", "axis", "ref"}
        if unknown:
            raise self.error(key, f"unknown key(s) {', '.join(sorted(unknown))} (known: point, axis, ref)")
        point = self.vector(raw.get("point"), f"{key}.point")
        axis = self.vector(raw.get("axis", ["0", "0", "1"]), f"{key}.axis")
        axis_values = [c.subs(self.geometry_subs) for c in axis]
        if all(v == 0 for v in axis_values):
            raise self.error(f"{key}.axis", "zero-length axis")
        ref = None
        if "ref" in raw:
            ref = self.vector(raw["ref"], f"{key}.ref")
            ref_values = [c.subs(self.geometry_subs) for c in ref]
            if all(v == 0 for v in ref_values):
                raise self.error(f"{key}.ref", "zero-length ref axis")
            if sum(a * r for a, r in zip(axis_values, ref_values)) != 0:
                raise self.error(f"{key}.ref", "must be perpendicular to axis")
        return Frame(point, axis, ref)

    def read_joints(self, labels, types):
        raw = self.data.get("joints")
        if not isinstance(raw, list) or not raw:
            raise self.error("joints", "at least one [[joints]] table is required")
        joints, names, coords = [], set(), set()
        allowed = {"name", "type", "parent", "child", "coordinates", "loop", "limits",
                   "parent_frame", "child_frame"}
        for i, j in enumerate(raw):
            key = f"joints[{i}]"
            if not isinstance(j, dict):
                raise self.error(key, "must be a table")
            unknown = set(j) - allowed
            if unknown:
                raise self.error(key, f"unknown key(s) {', '.join(sorted(unknown))}")
            tname = j.get("type")
            if tname not in types:
                raise self.error(f"{key}.type", f"unknown joint type {tname!r}; known: {', '.join(types)}")
            jtype = types[tname].item
            ends = []
            for end in ("parent", "child"):
                label = j.get(end)
                if not isinstance(label, int) or isinstance(label, bool):
                    raise self.error(f"{key}.{end}", "required: a body label (integer; ground is 0)")
                if label != 0 and label not in labels:
                    raise self.error(f"{key}.{end}", f"unknown body {label} (bodies: {sorted(labels)}, ground 0)")
                ends.append(label)
            if ends[0] == ends[1]:
                raise self.error(key, "a joint must connect two different bodies")
            name = j.get("name", f"J{ends[0]}_{ends[1]}")
            if not isinstance(name, str) or not IDENT_RE.match(name) or name in names:
                raise self.error(f"{key}.name", f"{name!r} is not a unique identifier")
            names.add(name)
            cnames = self.coordinate_names(j, key, name, jtype)
            for c in cnames:
                if c in coords or c in self.geometry or c in RESERVED:
                    raise self.error(f"{key}.coordinates", f"coordinate name {c!r} is already used")
                coords.add(c)
            frames = [self.read_frame(j.get(f"{end}_frame"), f"{key}.{end}_frame")
                      for end in ("parent", "child")]
            limits = self.read_limits(j.get("limits", {}), f"{key}.limits", cnames)
            loop = j.get("loop", False)
            if not isinstance(loop, bool):
                raise self.error(f"{key}.loop", "must be true or false")
            joints.append(Joint(name, jtype, ends[0], ends[1], frames[0], frames[1], cnames, limits, loop))
        return joints

    def coordinate_names(self, j, key, name, jtype):
        if "coordinates" in j:
            cnames = j["coordinates"]
            if (not isinstance(cnames, list) or len(cnames) != jtype.dof
                    or not all(isinstance(c, str) and IDENT_RE.match(c) for c in cnames)):
                raise self.error(f"{key}.coordinates",
                                 f"a {jtype.name} joint needs {jtype.dof} coordinate name(s) (identifiers)")
            return tuple(cnames)
        if jtype.dof == 1:
            return (name,)
        return tuple(f"{name}_{s}" for s in jtype.suffixes)

    def read_limits(self, raw, key, cnames):
        if not isinstance(raw, dict):
            raise self.error(key, "must be a table: coordinate = [low, high]")
        out = {}
        for c, pair in raw.items():
            if c not in cnames:
                raise self.error(f"{key}.{c}", f"not a coordinate of this joint ({', '.join(cnames)})")
            if not isinstance(pair, list) or len(pair) != 2:
                raise self.error(f"{key}.{c}", "must be [low, high]")
            lo, hi = (float(sympy.N(self.expr(v, f"{key}.{c}", time=True).subs(self.geometry_subs)))
                      for v in pair)
            if not lo < hi:
                raise self.error(f"{key}.{c}", "low must be below high")
            out[c] = (lo, hi)
        return out

    def spanning_tree(self, joints, labels):
        placed = {0}
        tree, loops = [], []
        remaining = [j for j in joints if not j.loop]
        progress = True
        while remaining and progress:
            progress = False
            for j in list(remaining):
                if j.parent in placed and j.child not in placed:
                    tree.append(TreeEdge(j, False))
                    placed.add(j.child)
                elif j.child in placed and j.parent not in placed:
                    tree.append(TreeEdge(j, True))
                    placed.add(j.parent)
                elif j.parent in placed and j.child in placed:
                    loops.append(j)
                else:
                    continue
                remaining.remove(j)
                progress = True
        missing = sorted(set(labels) - placed)
        if missing:
            raise self.error("joints", f"body {missing[0]} is not connected to ground (body 0)"
                             + (f"; nor are {missing[1:]}" if len(missing) > 1 else ""))
        loops.extend(j for j in joints if j.loop)
        return tree, loops

    def read_independent(self, coordinates, loops):
        table = self.table(self.data, "coordinates")
        unknown = set(table) - {"independent"}
        if unknown:
            raise self.error("coordinates", f"unknown key(s) {', '.join(sorted(unknown))}")
        indep = table.get("independent")
        if indep is None:
            return () if loops else tuple(coordinates)
        if not isinstance(indep, list) or not all(isinstance(c, str) for c in indep):
            raise self.error("coordinates.independent", "must be a list of coordinate names")
        for c in indep:
            if c not in coordinates:
                raise self.error("coordinates.independent",
                                 f"{c!r} is not a tree coordinate (tree coordinates: {', '.join(coordinates)})")
        if len(set(indep)) != len(indep):
            raise self.error("coordinates.independent", "repeated coordinate")
        return tuple(indep)

    def read_trajectory(self, independent):
        table = self.table(self.data, "trajectory")
        if not table:
            return None
        unknown = set(table) - {"t_start", "t_end", "samples", "q"}
        if unknown:
            raise self.error("trajectory", f"unknown key(s) {', '.join(sorted(unknown))}")
        t0 = self.exact(table.get("t_start", 0), "trajectory.t_start")
        t1 = self.exact(table.get("t_end", 10), "trajectory.t_end")
        if not t1 > t0:
            raise self.error("trajectory.t_end", "must be after t_start")
        samples = table.get("samples", 200)
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 2:
            raise self.error("trajectory.samples", "must be an integer >= 2")
        q = self.table(table, "trajectory.q", required=True)
        exprs = {}
        for name, text in q.items():
            if independent and name not in independent:
                raise self.error(f"trajectory.q.{name}", f"not an independent coordinate ({', '.join(independent)})")
            exprs[name] = self.expr(text, f"trajectory.q.{name}", time=True).subs(self.geometry_subs)
        return TrajectorySpec(exprs, Fraction(t0), Fraction(t1), samples)

    def check_mobility(self, mech):
        from baseparams.dynamics.evaluator import closure_structure
        try:
            structure = closure_structure(mech)
        except KinematicsError as exc:
            raise self.error("joints", f"cannot evaluate the kinematics: {exc}") from None
        if structure.dof == 0:
            raise self.error("joints", f"the mechanism has no degree of freedom "
                             f"(Gruebler count {mech.gruebler}; closure rank {structure.rank})")
        if mech.loops and not mech.independent:
            names = [mech.coordinates[i] for i in structure.independent]
            raise self.error("coordinates.independent",
                             f"required for a mechanism with loops; choose {structure.dof} of "
                             f"{', '.join(mech.coordinates)} (for example {names})")
        if mech.trajectory:
            missing = [c for c in mech.independent if c not in mech.trajectory.expressions]
            if missing:
                raise self.error("trajectory.q", f"no expression for {', '.join(missing)}")
