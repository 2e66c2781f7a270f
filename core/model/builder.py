"""Build a :class:`~baseparams.model.mechanism.Mechanism` from Python calls, for any reader.

Every reader (TOML, URDF, a third party's SDF or DH table) and every user script builds
mechanisms through :class:`MechanismBuilder`, so the rules live in one place: names and
references are checked, the spanning tree, coordinate names, independent set and default
trajectory are derived, and values stay exact. A reader only walks its own format and
passes each value together with the key path that names it in that format
(``key="joints[2]"``); every error is an :class:`~baseparams.errors.InputError` naming the
file, that key (plus the field, ``joints[2].type``) and the reason.

Values are exact: ``int``, :class:`~fractions.Fraction`, :class:`~decimal.Decimal`, decimal
strings or expression strings in the geometry names (``"L/2"``), or sympy expressions in the
geometry symbols. Binary floats are refused: ``0.1`` is not one tenth.

Names: geometry and coordinate names are identifiers that are not reserved (``t``, ``pi``,
the trajectory functions, Python keywords, names sympy reads as something else such as
``E``, ``I`` or ``gamma``) and not inertial parameter names (``m2``, ``Izz1``), which would
make the symbolic solver's expressions ambiguous. Inertia is checked for physical
consistency (:mod:`baseparams.model.consistency`): a negative mass or an inertia that
is not a mass distribution is refused, a zero-mass body with inertia gets a warning
(``Mechanism.warnings``, printed by the command line).

The mobility check (degrees of freedom, which coordinates may be independent) needs the
kinematics; :func:`baseparams.io.loader.check_mobility` runs it, and every file loaded
through :func:`baseparams.io.loader.load_mechanism` gets it.
"""

import builtins
import keyword
import math
import re
from collections.abc import Mapping, Sequence
from decimal import Decimal
from fractions import Fraction
from pathlib import Path
from typing import TypeAlias

import sympy

from baseparams import registry
from baseparams.errors import InputError
from baseparams.model.expressions import ExpressionError, parse_decimal, parse_expression, to_fraction
from baseparams.model.expressions import NON_FINITE
from baseparams.model.consistency import check_body
from baseparams.model.joints import JointType
from baseparams.model.mechanism import (MAX_SAMPLES, Body, Coupling, EffectSpec, Frame, Joint, Mechanism, Motor,
                                        TrajectorySpec, TreeEdge)
from baseparams.model.params import PARAMETER_KINDS, from_mass_properties

NAME_RE = re.compile(r"^[a-z0-9_]+$")
IDENT_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
RESERVED = frozenset({"t", "pi", "sin", "cos", "exp", "sqrt"})
PARAMETER_NAME_RE = re.compile(rf"^(?:{'|'.join(sorted(PARAMETER_KINDS, key=len, reverse=True))})[0-9]+$")
DEFAULT_GRAVITY = ("0", "0", "-9.81")
FRAME_KEYS = ("point", "axis", "ref")
INERTIA_COM_KEYS = ("Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")
TIME = sympy.Symbol("t")

Value: TypeAlias = str | int | Fraction | Decimal | sympy.Expr
"""An exact value: a number or an expression in the geometry names (never a float)."""


class MechanismBuilder:
    """Collects geometry, bodies, joints, coordinates and a trajectory; :meth:`build` checks
    the whole and returns the immutable Mechanism.

    Declare geometry names before the values that use them, and bodies before the joints
    that connect them. Each method checks what it can at once (so a script's traceback
    points at the bad call) and :meth:`build` checks what needs everything (the spanning
    tree, the independent coordinates, the trajectory's coordinates).

    ``path``: the file the mechanism comes from (named in errors; None for a script).
    ``joint_types``: name -> :class:`JointType`; default: the registered joint types.
    ``key``: the key path of the mechanism's header (its name is ``{key}.name``).
    ``lenient_inertia``: a body whose inertia is not physical is a warning, not an error,
    and is listed in ``Mechanism.nonphysical`` (for formats as users have them, URDF:
    base parameters do not depend on inertia values; verbs that use them call
    :func:`baseparams.model.consistency.require_physical`).
    """

    def __init__(self, name: str, path: str | Path | None = None, *, title: str = "",
                 description: str = "", source: str = "",
                 joint_types: Mapping[str, JointType] | None = None, key: str = "mechanism",
                 lenient_inertia: bool = False) -> None:
        self.path = None if path is None else str(path)
        self.lenient_inertia = lenient_inertia
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise self.error(f"{key}.name", "required: lower-case letters, digits and _ only")
        for field, text in (("title", title), ("description", description), ("source", source)):
            if not isinstance(text, str):
                raise self.error(f"{key}.{field}", "must be a string")
        self.name, self.title, self.description, self.source = name, title, description, source
        self._joint_types = joint_types
        self._geometry: dict[str, Fraction] = {}
        self._gravity = tuple(sympy.Rational(parse_decimal(v)) for v in DEFAULT_GRAVITY)
        self._bodies: list[Body] = []
        self._joints: list[Joint] = []
        self._coordinates: set[str] = set()
        self._independent: tuple[tuple[str, ...], str] | None = None
        self._trajectory: tuple[TrajectorySpec, str] | None = None
        self._effects: list[tuple[EffectSpec, str]] = []
        self._motors: list[tuple[Motor, str]] = []
        self._couplings: list[tuple[Coupling, str]] = []
        self._warnings: list[str] = []
        self._nonphysical: list[tuple[str, str]] = []
        self._nonphysical_labels: list[int] = []

    # ----- errors and values ---------------------------------------------------------
    def error(self, key: str | None, reason: str) -> InputError:
        """The error to raise for a bad value at ``key`` (readers use it for their own checks)."""
        return InputError(reason, file=self.path, key=key)

    def warn(self, key: str | None, text: str) -> None:
        """Record a remark that does not stop the build (``Mechanism.warnings``)."""
        self._warnings.append(InputError(text, file=self.path, key=key).message)

    @property
    def geometry_subs(self) -> dict:
        return {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator) for k, v in self._geometry.items()}

    def expression(self, value: Value, key: str, time: bool = False) -> sympy.Expr:
        """An exact sympy expression in the declared geometry names (and ``t``, ``pi``,
        sin, cos, exp, sqrt when ``time``)."""
        if isinstance(value, (float, sympy.Float)):
            raise self.error(key, f"{value!r} is a binary float, not exact: give a decimal string, "
                                  "an int, a Fraction or a Decimal")
        if isinstance(value, Fraction):
            return sympy.Rational(value.numerator, value.denominator)
        if isinstance(value, sympy.Basic):
            return self._sympy_expression(value, key, time)
        if not isinstance(value, (str, int, Decimal)) or isinstance(value, bool):
            raise self.error(key, f"{_type_word(value)} is not a number or expression")
        try:
            return parse_expression(value, tuple(self._geometry), time=time)
        except ExpressionError as exc:
            raise self.error(key, str(exc)) from None

    def _sympy_expression(self, value: object, key: str, time: bool) -> sympy.Expr:
        if not isinstance(value, sympy.Expr):
            raise self.error(key, f"{value!r} is not an expression")
        if value.atoms(sympy.Float):
            raise self.error(key, f"{value} holds a binary float, not exact: use sympy.Rational")
        if not time and (value.atoms(sympy.Function, sympy.NumberSymbol)
                         or any(not p.exp.is_Integer for p in value.atoms(sympy.Pow))):
            raise self.error(key, f"{value} is not a rational expression: geometry stays exact rationals")
        allowed = {sympy.Symbol(n) for n in self._geometry} | ({TIME} if time else set())
        unknown = sorted(str(s) for s in value.free_symbols - allowed)
        if unknown:
            known = ", ".join(sorted(self._geometry)) or "none"
            raise self.error(key, f"unknown name {unknown[0]!r} (geometry names: {known})")
        return value

    def vector(self, value: object, key: str) -> tuple[sympy.Expr, ...]:
        """Three exact expressions (``value``: a list or tuple of three values, checked)."""
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            got = f"{len(value)} items" if isinstance(value, (list, tuple)) else _type_word(value)
            raise self.error(key, f"must be a list of 3 numbers or expressions, got {got}")
        return tuple(self.expression(v, f"{key}[{i}]") for i, v in enumerate(value))

    def rational(self, value: Value, key: str) -> Fraction:
        """An exact rational number (an expression in the geometry is evaluated at it)."""
        expr = self.expression(value, key).xreplace(self.geometry_subs)
        try:
            return to_fraction(expr)
        except ExpressionError as exc:
            raise self.error(key, str(exc)) from None

    # ----- declarations --------------------------------------------------------------
    def geometry(self, name: str, value: Value, *, key: str | None = None) -> sympy.Symbol:
        """Declare a named geometric length or angle with an exact rational value; returns its
        symbol, usable in later expressions (as the text ``name`` or the symbol itself)."""
        key = key or f"geometry.{name}"
        problem = name_problem(name)
        if problem or name in PARAMETER_KINDS:
            raise self.error(key, problem or f"{name!r} is an inertial parameter kind: not a usable name")
        if name in self._geometry or name in self._coordinates:
            raise self.error(key, f"the name {name!r} is already used")
        if isinstance(value, (float, sympy.Float)):
            raise self.error(key, f"{value!r} is a binary float, not exact: give a decimal string, "
                                  "an int, a Fraction or a Decimal")
        if isinstance(value, sympy.Rational):
            value = Fraction(int(value.p), int(value.q))
        try:
            self._geometry[name] = parse_decimal(value)
        except ExpressionError as exc:
            raise self.error(key, str(exc)) from None
        return sympy.Symbol(name)

    def gravity(self, vector: Sequence[Value], *, key: str = "mechanism.gravity") -> None:
        """Gravity in ground axes (default 0, 0, -9.81)."""
        self._gravity = self.vector(vector, key)

    def body(self, label: int, name: str = "", *, mass: Value | None = None,
             com: Sequence[Value] | None = None, inertia_com: Sequence[Value] | None = None,
             inertia: Mapping[str, Value] | None = None, key: str | None = None) -> Body:
        """A moving body (ground is 0). Optional inertia, for simulation: either ``inertia``,
        the ten parameters about the body origin (``{"m": ..., "mx": ..., "Izz": ...}``), or
        ``mass``, ``com`` and ``inertia_com`` (Ixx Ixy Ixz Iyy Iyz Izz, tensor entries at the
        centre of mass), converted exactly."""
        key = key or f"bodies[{len(self._bodies)}]"
        if not isinstance(label, int) or isinstance(label, bool) or label < 1:
            raise self.error(f"{key}.label", "required: an integer >= 1 (ground is 0)")
        if any(b.label == label for b in self._bodies):
            raise self.error(f"{key}.label", f"duplicate body label {label}")
        if not isinstance(name, str):
            raise self.error(f"{key}.name", "must be a string")
        params = self._inertia(key, mass, com, inertia_com, inertia)
        if params is not None:
            verdict = check_body(params)
            where = f"{key}.inertia" if inertia is not None else (
                f"{key}.mass" if Fraction(params[0]) < 0 else f"{key}.inertia_com")
            who = f"body {label}" + (f" ({name})" if name else "")
            if verdict.error and self.lenient_inertia:
                self.warn(where, f"{who}: {verdict.error}: not a physical body (accepted: base parameters "
                                 "do not depend on inertia values; simulate and identification refuse it)")
                self._nonphysical.append((where, f"{who}: {verdict.error}"))
                self._nonphysical_labels.append(label)
            elif verdict.error:
                raise self.error(where, f"{who}: {verdict.error}: not a physical body")
            if verdict.warning:
                self.warn(where, f"{who}: {verdict.warning}")
        body = Body(label, name, params)
        self._bodies.append(body)
        return body

    def _inertia(self, key: str, mass: Value | None, com: Sequence[Value] | None,
                 inertia_com: Sequence[Value] | None,
                 inertia: Mapping[str, Value] | None) -> tuple[Fraction, ...] | None:
        given = mass is not None or com is not None or inertia_com is not None
        if inertia is not None and given:
            raise self.error(key, "give either inertia (about the origin) or mass/com/inertia_com, not both")
        if inertia is not None:
            if not isinstance(inertia, Mapping) or set(inertia) != set(PARAMETER_KINDS):
                raise self.error(f"{key}.inertia", f"needs exactly the keys {', '.join(PARAMETER_KINDS)}")
            return tuple(self.rational(inertia[k], f"{key}.inertia.{k}") for k in PARAMETER_KINDS)
        if not given:
            return None
        if mass is None:
            raise self.error(f"{key}.mass", "required with com and inertia_com")
        m = self.rational(mass, f"{key}.mass")
        c = [to_fraction(v.xreplace(self.geometry_subs)) for v in self.vector(com, f"{key}.com")]
        if not isinstance(inertia_com, (list, tuple)) or len(inertia_com) != 6:
            raise self.error(f"{key}.inertia_com", f"needs 6 entries: {' '.join(INERTIA_COM_KEYS)}")
        tensor = [self.rational(v, f"{key}.inertia_com[{i}]") for i, v in enumerate(inertia_com)]
        return tuple(from_mass_properties(m, c, tensor))

    def frame(self, frame: Frame | Mapping[str, object] | None, key: str) -> Frame:
        """A joint frame with exact components, checked: ``point``; ``axis`` (z, default
        0 0 1, not zero); ``ref`` (x, optional, perpendicular to the axis)."""
        if isinstance(frame, Frame):
            raw: dict[str, object] = {"point": frame.point, "axis": frame.axis, "ref": frame.ref}
        elif isinstance(frame, Mapping):
            raw = dict(frame)
            unknown = set(raw) - set(FRAME_KEYS)
            if unknown:
                raise self.error(key, f"unknown key(s) {', '.join(sorted(unknown))} (known: point, axis, ref)")
        else:
            raise self.error(key, "required: a table with point (and axis, ref)")
        point = self.vector(raw.get("point"), f"{key}.point")
        axis = self.vector(raw["axis"] if raw.get("axis") is not None else ("0", "0", "1"), f"{key}.axis")
        subs = self.geometry_subs
        axis_values = [c.xreplace(subs) for c in axis]
        if all(v == 0 for v in axis_values):
            raise self.error(f"{key}.axis", "zero-length axis")
        ref = None
        if raw.get("ref") is not None:
            ref = self.vector(raw["ref"], f"{key}.ref")
            ref_values = [c.xreplace(subs) for c in ref]
            if all(v == 0 for v in ref_values):
                raise self.error(f"{key}.ref", "zero-length ref axis")
            if sum(a * r for a, r in zip(axis_values, ref_values)) != 0:
                raise self.error(f"{key}.ref", "must be perpendicular to axis")
        return Frame(point, axis, ref)

    def joint(self, type: str | JointType, parent: int, child: int, *, name: str | None = None,
              parent_frame: Frame | Mapping[str, object] | None = None,
              child_frame: Frame | Mapping[str, object] | None = None,
              coordinates: Sequence[str] | None = None,
              limits: Mapping[str, Sequence[Value]] | None = None, loop: bool = False,
              drive_limits: Mapping[str, Mapping[str, Value]] | None = None,
              key: str | None = None) -> Joint:
        """A joint of a registered type (or a :class:`JointType`) from ``parent`` to ``child``.

        ``name``: default ``J{parent}_{child}``. ``coordinates``: one name per motion;
        default the joint name (one coordinate) or ``{name}_{suffix}``. ``limits``:
        coordinate -> (low, high). ``loop=True`` makes it a loop-closing joint.
        ``drive_limits``: coordinate -> {"velocity": v, "effort": e} (either or both; positive
        numbers: a URDF's ``<limit velocity effort>``, kept so that writing it back loses nothing)."""
        key = key or f"joints[{len(self._joints)}]"
        jtype = self._joint_type(type, f"{key}.type")
        ends = []
        for end, label in (("parent", parent), ("child", child)):
            if not isinstance(label, int) or isinstance(label, bool):
                raise self.error(f"{key}.{end}", "required: a body label (integer; ground is 0)")
            labels = sorted(b.label for b in self._bodies)
            if label != 0 and label not in labels:
                raise self.error(f"{key}.{end}", f"unknown body {label} (bodies: {labels}, ground 0)")
            ends.append(label)
        if ends[0] == ends[1]:
            raise self.error(key, "a joint must connect two different bodies")
        name = f"J{ends[0]}_{ends[1]}" if name is None else name
        if (not isinstance(name, str) or not IDENT_RE.match(name)
                or any(j.name == name for j in self._joints)):
            raise self.error(f"{key}.name", f"{name!r} is not a unique identifier")
        cnames = self._coordinate_names(coordinates, f"{key}.coordinates", name, jtype)
        frames = [self.frame(f, f"{key}.{end}_frame")
                  for end, f in (("parent", parent_frame), ("child", child_frame))]
        bounds = self._limits({} if limits is None else limits, f"{key}.limits", cnames)
        if not isinstance(loop, bool):
            raise self.error(f"{key}.loop", "must be true or false")
        drives = self._drive_limits({} if drive_limits is None else drive_limits, f"{key}.drive_limits", cnames)
        joint = Joint(name, jtype, ends[0], ends[1], frames[0], frames[1], cnames, bounds, loop, drives)
        self._joints.append(joint)
        self._coordinates.update(cnames)
        return joint

    def _joint_type(self, value: object, key: str) -> JointType:
        if isinstance(value, JointType):
            return value
        if self._joint_types is None:
            self._joint_types = {n: r.item for n, r in registry.joint_types().items()}
        if not isinstance(value, str) or value not in self._joint_types:
            raise self.error(key, f"unknown joint type {value!r}; known: {', '.join(self._joint_types)}")
        return self._joint_types[value]

    def _coordinate_names(self, coordinates: object, key: str, name: str,
                          jtype: JointType) -> tuple[str, ...]:
        if coordinates is None:
            cnames = (name,) if jtype.dof == 1 else tuple(f"{name}_{s}" for s in jtype.suffixes)
        elif (not isinstance(coordinates, (list, tuple)) or len(coordinates) != jtype.dof
                or not all(isinstance(c, str) and IDENT_RE.match(c) for c in coordinates)):
            raise self.error(key, f"a {jtype.name} joint needs {jtype.dof} coordinate name(s) (identifiers)")
        else:
            cnames = tuple(coordinates)
        for c in cnames:
            problem = name_problem(c)
            if problem:
                raise self.error(key, f"coordinate {problem}" + (" (the joint's name is its coordinate's "
                                                                 "by default)" if coordinates is None else ""))
            if c in self._coordinates or c in self._geometry or cnames.count(c) > 1:
                raise self.error(key, f"coordinate name {c!r} is already used")
        return cnames

    def _limits(self, raw: object, key: str, cnames: tuple[str, ...]) -> dict[str, tuple[float, float]]:
        if not isinstance(raw, Mapping):
            raise self.error(key, "must be a table: coordinate = [low, high]")
        out = {}
        for c, pair in raw.items():
            if c not in cnames:
                raise self.error(f"{key}.{c}", f"not a coordinate of this joint ({', '.join(cnames)})")
            if not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise self.error(f"{key}.{c}", "must be [low, high]")
            values = [self.expression(v, f"{key}.{c}", time=True).xreplace(self.geometry_subs) for v in pair]
            if any(v.free_symbols for v in values):
                raise self.error(f"{key}.{c}", "must be numbers (t is not allowed here)")
            lo, hi = (_nearest_float(v) for v in values)
            if not lo < hi:
                raise self.error(f"{key}.{c}", "low must be below high")
            out[c] = (lo, hi)
        return out

    def _drive_limits(self, raw: object, key: str, cnames: tuple[str, ...]) -> dict[str, dict[str, float]]:
        """coordinate -> {"velocity": v, "effort": e}: positive finite numbers, either or both."""
        if not isinstance(raw, Mapping):
            raise self.error(key, "must be a table: coordinate = { velocity = v, effort = e }")
        out: dict[str, dict[str, float]] = {}
        for c, table in raw.items():
            if c not in cnames:
                raise self.error(f"{key}.{c}", f"not a coordinate of this joint ({', '.join(cnames)})")
            if not isinstance(table, Mapping) or not table or set(table) - {"velocity", "effort"}:
                raise self.error(f"{key}.{c}", "must be a table with velocity and/or effort")
            out[c] = {}
            for kind, value in table.items():
                number = self.expression(value, f"{key}.{c}.{kind}").xreplace(self.geometry_subs)
                if number.free_symbols:
                    raise self.error(f"{key}.{c}.{kind}", "must be a number")
                out[c][kind] = _nearest_float(number)
                if not (math.isfinite(out[c][kind]) and out[c][kind] > 0):
                    raise self.error(f"{key}.{c}.{kind}", "must be a positive number")
        return out

    def independent(self, names: Sequence[str], *, key: str = "coordinates.independent") -> None:
        """The independent coordinates (required with loops; default without: all). Checked
        against the tree coordinates by :meth:`build`."""
        if not isinstance(names, (list, tuple)) or not all(isinstance(c, str) for c in names):
            raise self.error(key, "must be a list of coordinate names")
        self._independent = (tuple(names), key)

    def trajectory(self, q: Mapping[str, Value], *, t_start: Value = 0, t_end: Value = 10,
                   samples: int = 200, key: str = "trajectory") -> None:
        """The default exciting trajectory: an expression of ``t`` per independent coordinate
        (``"0.5*sin(3*t)"``), sampled ``samples`` times from ``t_start`` to ``t_end``."""
        t0 = self.rational(t_start, f"{key}.t_start")
        t1 = self.rational(t_end, f"{key}.t_end")
        if not t1 > t0:
            raise self.error(f"{key}.t_end", "must be after t_start")
        if not isinstance(samples, int) or isinstance(samples, bool) or not 2 <= samples <= MAX_SAMPLES:
            shown = samples if isinstance(samples, int) and abs(samples) < 10 ** 12 else "out of range"
            raise self.error(f"{key}.samples", f"must be an integer from 2 to {MAX_SAMPLES:,} ({shown})")
        if not isinstance(q, Mapping):
            raise self.error(f"{key}.q", f"must be a table, not {type(q).__name__}")
        subs = self.geometry_subs
        exprs = {name: self.expression(text, f"{key}.q.{name}", time=True).subs(subs)
                 for name, text in q.items()}
        self._trajectory = (TrajectorySpec(exprs, t0, t1, samples), key)

    def effect(self, kind: str, coordinate: str, values: Mapping[str, Value] | None = None, *,
               key: str | None = None) -> EffectSpec:
        """A model effect (friction, spring, offset ...: a registered effect kind) acting on a
        joint coordinate, with optionally known coefficients (``{"fv": "0.8"}``). The
        coordinate is checked against the tree coordinates by :meth:`build`."""
        key = key or f"effects[{len(self._effects)}]"
        effects = registry.effects()
        if not isinstance(kind, str) or kind not in effects:
            raise self.error(f"{key}.kind", f"unknown effect {kind!r}; known: {', '.join(sorted(effects))}")
        if not isinstance(coordinate, str):
            raise self.error(f"{key}.coordinate", "required: a joint coordinate name")
        if any(spec.kind == kind and spec.coordinate == coordinate for spec, _ in self._effects):
            raise self.error(key, f"{kind} on {coordinate} is already included")
        raw = {} if values is None else values
        if not isinstance(raw, Mapping):
            raise self.error(f"{key}.values", "must be a table: coefficient = value")
        coefficients = effects[kind].item.coefficients + effects[kind].item.shape_names
        exact = {}
        for name, value in raw.items():
            if name not in coefficients:
                raise self.error(f"{key}.values.{name}", f"not a coefficient or shape parameter of {kind} "
                                 f"({', '.join(coefficients)})")
            exact[name] = self.rational(value, f"{key}.values.{name}")
        spec = EffectSpec(kind, coordinate, exact)
        self._effects.append((spec, key))
        return spec

    def motor(self, name: str, ratios: Mapping[str, Value], *, key: str | None = None) -> Motor:
        """A motor-side coordinate of the drive chain: ``position = sum(ratio * q)`` over the
        joint coordinates named in ``ratios`` (gear ratios of any sign, nonzero; several for a
        coupled wrist or a differential). Coordinates are checked by :meth:`build`."""
        key = key or f"motors[{len(self._motors)}]"
        problem = name_problem(name)
        if problem:
            raise self.error(f"{key}.name", problem)
        if any(m.name == name for m, _ in self._motors):
            raise self.error(f"{key}.name", f"motor {name!r} is declared twice")
        if not isinstance(ratios, Mapping) or not ratios:
            raise self.error(f"{key}.ratios", "required: a table joint coordinate = gear ratio (at least one)")
        exact = []
        for coordinate, value in ratios.items():
            ratio = self.rational(value, f"{key}.ratios.{coordinate}")
            if ratio == 0:
                raise self.error(f"{key}.ratios.{coordinate}", "a gear ratio of 0: the motor would not "
                                 "move with the joint (leave the coordinate out instead)")
            exact.append((coordinate, ratio))
        motor = Motor(name, tuple(exact))
        self._motors.append((motor, key))
        return motor

    def coupling(self, coordinate: str, leader: str, ratio: Value = 1, offset: Value = 0, *,
                 key: str | None = None) -> Coupling:
        """``coordinate = ratio * leader + offset``: a joint coordinate that follows another
        (a gear train between joints, URDF ``<mimic>``, a cable-driven counterweight); it is
        then not independent. On a mechanism with closed loops it is one more closure
        equation, solved with the loops'. Coordinates are checked by :meth:`build`."""
        key = key or f"couplings[{len(self._couplings)}]"
        for field, name in (("coordinate", coordinate), ("leader", leader)):
            if not isinstance(name, str):
                raise self.error(f"{key}.{field}", "required: a joint coordinate name")
        if coordinate == leader:
            raise self.error(f"{key}.leader", "a coordinate cannot follow itself")
        if any(c.coordinate == coordinate for c, _ in self._couplings):
            raise self.error(f"{key}.coordinate", f"{coordinate!r} already follows another coordinate")
        value = self.rational(ratio, f"{key}.ratio")
        if value == 0:
            raise self.error(f"{key}.ratio", "a ratio of 0 would hold the coordinate fixed: make the joint "
                             "fixed instead")
        coupling = Coupling(coordinate, leader, value, self.rational(offset, f"{key}.offset"))
        self._couplings.append((coupling, key))
        return coupling

    # ----- the whole -----------------------------------------------------------------
    def build(self) -> Mechanism:
        """Check the whole and return the Mechanism (the builder may be built again)."""
        if not self._bodies:
            raise self.error("bodies", "at least one body is required")
        if not self._joints:
            raise self.error("joints", "at least one joint is required")
        bodies = sorted(self._bodies, key=lambda body: body.label)
        tree, loops = self._spanning_tree(bodies)
        coordinates = tuple(c for edge in tree for c in edge.joint.coordinates)
        couplings = self._checked_couplings(coordinates, loops)
        independent = self._checked_independent(coordinates, loops, couplings)
        trajectory = self._checked_trajectory(independent or coordinates)
        gruebler = 6 * len(bodies) - sum(6 - j.type.dof for j in self._joints)
        for motor, key in self._motors:
            if motor.name in coordinates:
                raise self.error(f"{key}.name", f"{motor.name!r} is a joint coordinate: a motor needs its own name")
            for coordinate, _ in motor.ratios:
                if coordinate not in coordinates:
                    raise self.error(f"{key}.ratios.{coordinate}", f"{coordinate!r} is not a tree coordinate "
                                     f"(tree coordinates: {', '.join(coordinates)})")
        motor_names = tuple(m.name for m, _ in self._motors)
        for spec, key in self._effects:
            if spec.coordinate not in coordinates and spec.coordinate not in motor_names:
                raise self.error(f"{key}.coordinate", f"{spec.coordinate!r} is not a tree coordinate "
                                 f"or a motor (tree coordinates: {', '.join(coordinates)}"
                                 + (f"; motors: {', '.join(motor_names)})" if motor_names else ")"))
        return Mechanism(
            name=self.name, bodies=tuple(bodies), joints=tuple(self._joints), tree=tuple(tree),
            loops=tuple(loops), coordinates=coordinates, independent=independent,
            geometry=dict(self._geometry), gravity=self._gravity, trajectory=trajectory,
            title=self.title, description=self.description, source=self.source, path=self.path,
            gruebler=gruebler, effects=tuple(spec for spec, _ in self._effects),
            warnings=tuple(self._warnings), motors=tuple(m for m, _ in self._motors),
            couplings=couplings, nonphysical=tuple(self._nonphysical),
            nonphysical_labels=tuple(self._nonphysical_labels))

    def _spanning_tree(self, bodies: Sequence[Body]) -> tuple[list[TreeEdge], list[Joint]]:
        """Joints in declaration order; one joining two placed bodies closes a loop."""
        placed = {0}
        tree: list[TreeEdge] = []
        loops: list[Joint] = []
        remaining = [j for j in self._joints if not j.loop]
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
        missing = sorted({b.label for b in bodies} - placed)
        if missing:
            raise self.error("joints", f"body {missing[0]} is not connected to ground (body 0)"
                             + (f"; nor are {missing[1:]}" if len(missing) > 1 else ""))
        loops.extend(j for j in self._joints if j.loop)
        return tree, loops

    def _checked_couplings(self, coordinates: Sequence[str], loops: Sequence[Joint]) -> tuple[Coupling, ...]:
        followers = {c.coordinate for c, _ in self._couplings}
        for coupling, key in self._couplings:
            for field in ("coordinate", "leader"):
                name = getattr(coupling, field)
                if name not in coordinates:
                    raise self.error(f"{key}.{field}", f"{name!r} is not a tree coordinate (tree coordinates: "
                                     f"{', '.join(coordinates)})")
            if coupling.leader in followers:
                raise self.error(f"{key}.leader", f"{coupling.leader!r} follows another coordinate itself: "
                                 "name the coordinate it follows (chains of couplings are not read)")
        return tuple(c for c, _ in self._couplings)

    def _checked_independent(self, coordinates: Sequence[str], loops: Sequence[Joint],
                             couplings: Sequence[Coupling] = ()) -> tuple[str, ...]:
        followers = {c.coordinate for c in couplings}
        if self._independent is None:
            return () if loops else tuple(c for c in coordinates if c not in followers)
        names, key = self._independent
        for c in names:
            if c not in coordinates:
                raise self.error(key, f"{c!r} is not a tree coordinate (tree coordinates: {', '.join(coordinates)})")
        if len(set(names)) != len(names):
            raise self.error(key, "repeated coordinate")
        if loops:
            for coupling in couplings:
                if coupling.coordinate in names:
                    raise self.error(key, f"{coupling.coordinate!r} follows {coupling.leader!r} (a coupling): it is "
                                     f"not independent; list another coordinate (or make {coupling.coordinate!r} "
                                     f"the leader and {coupling.leader!r} its follower)")
            return names
        if couplings and set(names) != {c for c in coordinates if c not in followers}:
            raise self.error(key, f"with couplings the independent coordinates are the tree coordinates "
                             f"that follow no other: {', '.join(c for c in coordinates if c not in followers)}")
        return names

    def _checked_trajectory(self, independent: Sequence[str]) -> TrajectorySpec | None:
        if self._trajectory is None:
            return None
        spec, key = self._trajectory
        for name in spec.expressions:
            if independent and name not in independent:
                raise self.error(f"{key}.q.{name}", f"not an independent coordinate ({', '.join(independent)})")
        return spec


def name_problem(name: object) -> str | None:
    """Why ``name`` cannot name a geometry value or a coordinate (None: it can): not an
    identifier, reserved (``t``, ``pi``, a function, a Python keyword, a name sympy reads as
    something else), or an inertial parameter's name (``m2``, ``Izz1``)."""
    if not isinstance(name, str) or not IDENT_RE.match(name):
        shown = repr(name) if isinstance(name, str) and len(name) < 40 else f"this {_type_word(name)}"
        return f"name {shown} is not an identifier (letters, digits, _; not starting with a digit)"
    if name in RESERVED or keyword.iskeyword(name) or name.lower() in NON_FINITE:
        return f"name {name!r} is reserved (t, pi, sin, cos, exp, sqrt, nan, inf and Python keywords)"
    if PARAMETER_NAME_RE.match(name):
        return f"name {name!r} is an inertial parameter's name: choose another"
    if _sympy_may_read(name) and sympy.parse_expr(name) != sympy.Symbol(name):
        return f"name {name!r} means something else to sympy (the symbolic results would be ambiguous)"
    return None


def _sympy_may_read(name: str) -> bool:
    """Might sympy's ``parse_expr`` read the identifier ``name`` as something other than
    ``Symbol(name)``? Only a name its namespace defines can be (``from sympy import *`` and
    the builtins; any other name it makes a Symbol): those are parsed, the rest are not (the
    parser costs 0.3 ms a name, 0.02 CPU s of reading TIAGo's 78 names)."""
    return name in _SYMPY_NAMES or name.startswith("__")


_SYMPY_NAMES = frozenset(vars(sympy)) | frozenset(vars(builtins))


def _type_word(value: object) -> str:
    """A value's kind in words, for messages (never a Python repr)."""
    if isinstance(value, bool):
        return "a boolean"
    return {str: "a string", int: "an integer", list: "a list", tuple: "a list", dict: "a table",
            type(None): "a missing value", Decimal: "a number", float: "a float"}.get(
        type(value), "a table" if isinstance(value, Mapping) else f"a {type(value).__name__}")


def _nearest_float(value: sympy.Expr) -> float:
    """The float nearest an exact number (``float(sympy.N(v))`` rounds twice: a file's
    "-2.96705972839" came back as -2.9670597283899998 and was written so)."""
    return float(value) if value.is_Rational else float(sympy.N(value, 30))
