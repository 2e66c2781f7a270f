"""Write a Mechanism as a TOML mechanism file (docs/mechanism-format.md): the inverse of the reader.

Every value is written exactly: geometry and inertial parameters as exact decimals (or
``p/q``), frames and the trajectory as the expressions the model holds, so reading the
file back gives the same mechanism (tests/test_urdf_convert.py checks it). Limits are
the floats the model keeps, written by their shortest round-trip text.
"""

import json
from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path

import sympy

from baseparams.model.expressions import exact_text
from baseparams.model.mechanism import Frame, Mechanism
from baseparams.model.params import PARAMETER_KINDS


class TomlWriter:
    """The built-in writer of ``.toml`` mechanism files (registered by baseparams.plugins.readers)."""

    name = "toml"
    suffixes: tuple[str, ...] = (".toml",)
    description = "baseparams mechanism files (docs/mechanism-format.md)"

    def write(self, mechanism: Mechanism, path: str | Path) -> list[str]:
        Path(path).write_text(mechanism_toml(mechanism), encoding="utf-8")
        return []


def _string(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(text, ensure_ascii=False)


def _expr(value: object) -> str:
    expr = sympy.sympify(value)
    if expr.is_Rational:
        return _string(exact_text(Fraction(int(expr.p), int(expr.q))))
    return _string(str(expr))


def _vector(values: Iterable[object]) -> str:
    return "[" + ", ".join(_expr(v) for v in values) + "]"


def _frame(frame: Frame) -> str:
    parts = [f"point = {_vector(frame.point)}", f"axis = {_vector(frame.axis)}"]
    if frame.ref is not None:
        parts.append(f"ref = {_vector(frame.ref)}")
    return "{ " + ", ".join(parts) + " }"


def mechanism_toml(mech: Mechanism) -> str:
    """The TOML text of ``mech``."""
    out = ["[mechanism]", f"name = {_string(mech.name)}"]
    for key in ("title", "description", "source"):
        if getattr(mech, key):
            out.append(f"{key} = {_string(getattr(mech, key))}")
    out.append(f"gravity = {_vector(mech.gravity)}")
    if mech.geometry:
        out += ["", "[geometry]"] + [f"{name} = {_string(exact_text(v))}" for name, v in mech.geometry.items()]
    for body in mech.bodies:
        out += ["", "[[bodies]]", f"label = {body.label}"]
        if body.name:
            out.append(f"name = {_string(body.name)}")
        if body.inertia is not None:
            values = ", ".join(f"{k} = {_string(exact_text(v))}" for k, v in zip(PARAMETER_KINDS, body.inertia))
            out.append(f"inertia = {{ {values} }}")
    for joint in mech.joints:
        out += ["", "[[joints]]", f"name = {_string(joint.name)}", f"type = {_string(joint.type.name)}",
                f"parent = {joint.parent}", f"child = {joint.child}"]
        if joint.coordinates:
            out.append("coordinates = [" + ", ".join(_string(c) for c in joint.coordinates) + "]")
        if joint.loop:
            out.append("loop = true")
        if joint.limits:
            limits = ", ".join(f"{c} = [{_string(repr(lo))}, {_string(repr(hi))}]" for c, (lo, hi) in joint.limits.items())
            out.append(f"limits = {{ {limits} }}")
        if joint.drive_limits:
            drives = ", ".join(f"{c} = {{ " + ", ".join(f"{k} = {_string(repr(v))}" for k, v in d.items()) + " }"
                               for c, d in joint.drive_limits.items())
            out.append(f"drive_limits = {{ {drives} }}")
        out.append(f"parent_frame = {_frame(joint.parent_frame)}")
        out.append(f"child_frame = {_frame(joint.child_frame)}")
    if mech.loops and mech.independent:
        out += ["", "[coordinates]", "independent = [" + ", ".join(_string(c) for c in mech.independent) + "]"]
    if mech.trajectory is not None:
        spec = mech.trajectory
        q = ", ".join(f"{name} = {_expr(e)}" for name, e in spec.expressions.items())
        out += ["", "[trajectory]", f"t_start = {_string(exact_text(spec.t_start))}",
                f"t_end = {_string(exact_text(spec.t_end))}", f"samples = {spec.samples}", f"q = {{ {q} }}"]
    for c in mech.couplings:
        out += ["", "[[couplings]]", f"coordinate = {_string(c.coordinate)}", f"leader = {_string(c.leader)}",
                f"ratio = {_string(exact_text(c.ratio))}", f"offset = {_string(exact_text(c.offset))}"]
    for motor in mech.motors:
        ratios = ", ".join(f"{c} = {_string(exact_text(r))}" for c, r in motor.ratios)
        out += ["", "[[motors]]", f"name = {_string(motor.name)}", f"ratios = {{ {ratios} }}"]
    for effect in mech.effects:
        out += ["", "[[effects]]", f"kind = {_string(effect.kind)}", f"coordinate = {_string(effect.coordinate)}"]
        if effect.values:
            values = ", ".join(f"{k} = {_string(exact_text(v))}" for k, v in effect.values.items())
            out.append(f"values = {{ {values} }}")
    return "\n".join(out) + "\n"
