"""The URDF writer: a tree mechanism (R, P, Fixed, Free joints) as a URDF file.

Two modes:

- *patch*: the mechanism was read from a URDF file whose links (fixed ones lumped into
  their parents, or not) are still its bodies: that file is copied and only its links'
  ``<inertial>`` elements are replaced by the bodies' parameters (a link lumped into a moving
  body loses its own: the body's link carries its mass), so meshes, visuals, collisions,
  transmissions and vendor tags survive (``convert robot.urdf --inertia identified.json -o out.urdf``);
- *generate*: any other tree mechanism is written from scratch. URDF puts a link's origin
  on its parent joint's axis, so a body whose revolute axis does not pass through its
  origin gets a link frame shifted (never turned) onto the axis, and its inertia is
  shifted exactly with it; URDF has no gravity (users assume 9.81 m/s^2 along -z of the
  root link), so another gravity direction of that magnitude turns the ground's children
  instead. Rotations are written as rpy angles: signed permutations as exact multiples of
  pi/2 (read back exactly), other rotations to 20 digits (read back within 1e-17).

Numbers are exact decimals when the value has one, else 25 significant digits.
"""

import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import mpmath
import sympy

from baseparams.errors import InputError
from baseparams.model.expressions import exact_text
from baseparams.model.mechanism import Frame, Joint, Mechanism
from baseparams.numeric.backends import Symbolic

from .parse import transform_parameters
from .reader import read_urdf
from .rotations import IDENTITY, matrix_rpy

URDF_TYPE = {"R": "revolute", "P": "prismatic", "Fixed": "fixed", "Free": "floating"}
STANDARD_GRAVITY = Fraction(981, 100)
DIGITS = 25


class UrdfWriter:
    """Writes ``.urdf`` files (registered by baseparams.plugins.urdf)."""

    name = "urdf"
    suffixes: tuple[str, ...] = (".urdf",)
    description = "URDF robot descriptions (docs/urdf.md)"

    def write(self, mechanism: Mechanism, path: str | Path) -> list[str]:
        source = _source_links(mechanism)
        if source is not None:
            text, notes = patch_inertials(mechanism, *source)
        else:
            text, notes = mechanism_urdf(mechanism)
        Path(path).write_text(text, encoding="utf-8")
        return notes


# ----- numbers ------------------------------------------------------------------------------
def number(value: object) -> str:
    """Exact decimal text when the value has one, else 25 significant digits."""
    expr = sympy.sympify(value)
    if expr.is_Rational:
        exact = exact_text(Fraction(int(expr.p), int(expr.q)))
        if "/" not in exact:
            return exact
    return _digits(sympy.N(expr, DIGITS + 5))


def _digits(x: object) -> str:
    with mpmath.workdps(DIGITS + 5):
        return mpmath.nstr(mpmath.mpf(str(x)), DIGITS, strip_zeros=True)


def _triple(values: Iterable[object]) -> str:
    return " ".join(number(v) for v in values)


# ----- patch mode -----------------------------------------------------------------------------
def _source_links(mech: Mechanism) -> tuple[dict[int, str], list[str]] | None:
    """({label: link name}, [links lumped into a moving body]) when ``mech`` came from a URDF
    file whose links (fixed ones lumped or kept) are its bodies."""
    if not mech.path or Path(mech.path).suffix.lower() != ".urdf" or not Path(mech.path).exists():
        return None
    for merge in (True, False):
        try:
            original = read_urdf(mech.path, merge_fixed=merge)
        except InputError:
            return None
        same = (len(original.mechanism.bodies) == len(mech.bodies)
                and all(original.links.get(b.label) == b.name for b in mech.bodies)
                and [j.name for j in original.mechanism.joints] == [j.name for j in mech.joints])
        if same:
            bodies = set(original.links.values())
            return original.links, [link for link, into in original.merged_into.items() if into in bodies]
    return None


def patch_inertials(mech: Mechanism, links: Mapping[int, str], lumped: Sequence[str] = ()) -> tuple[str, list[str]]:
    """The source URDF with each body's ``<inertial>`` replaced (comments kept); the links
    ``lumped`` into a body lose theirs (the body's link carries their mass)."""
    assert mech.path is not None                # read from that file (_source_links)
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(Path(mech.path).read_text(encoding="utf-8"), parser=parser)
    by_name = {elem.get("name"): elem for elem in root.findall("link")}
    for name in lumped:
        old = by_name[name].find("inertial")
        if old is not None:
            by_name[name].remove(old)
    for body in mech.bodies:
        link = by_name[links[body.label]]
        old = link.find("inertial")
        if old is not None:
            link.remove(old)
        if body.inertia is not None:
            new = _inertial(body.inertia, f"link[name={link.get('name')}]", mech.path)
            new.tail = link.text
            link.insert(0, new)
    ET.indent(root, space="  ")
    text = '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    return text, [f"kept {mech.path}; replaced the <inertial> of {len(mech.bodies)} link(s)"
                  + (f", removed those of the links lumped into them: {', '.join(lumped)}" if lumped else "")]


def _inertial(phi: Sequence[Fraction], key: str, path: str | None) -> ET.Element:
    """``<inertial>`` of ten parameters about the link origin (link axes): COM and the tensor at it."""
    m, hx, hy, hz = phi[:4]
    if m < 0:
        raise InputError(f"negative mass {float(m):g}: not physical, not writable to URDF", file=path, key=key)
    if m == 0:
        if hx or hy or hz:
            raise InputError("zero mass with a nonzero first moment: no centre of mass to write",
                             file=path, key=key)
        c = (Fraction(0),) * 3
    else:
        c = (hx / m, hy / m, hz / m)
    at_com = transform_parameters(phi, IDENTITY, tuple(-v for v in c))
    elem = ET.Element("inertial")
    ET.SubElement(elem, "origin", xyz=_triple(c), rpy="0 0 0")
    ET.SubElement(elem, "mass", value=number(m))
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    ET.SubElement(elem, "inertia", {n: number(v) for n, v in zip(names, at_com[4:])})
    return elem


# ----- generate mode --------------------------------------------------------------------------
def mechanism_urdf(mech: Mechanism) -> tuple[str, list[str]]:
    """URDF text of a tree mechanism, and notes on what URDF could not hold."""
    notes: list[str] = []
    if mech.loops:
        raise InputError(f"URDF describes trees; {mech.name} has loop-closing joint(s) "
                         f"{', '.join(j.name for j in mech.loops)}", file=mech.path, key="joints")
    for k, joint in enumerate(mech.joints):
        if joint.type.name not in URDF_TYPE:
            raise InputError(f"a {joint.type.name} joint has no URDF joint type (URDF: revolute, "
                             "prismatic, fixed, floating)", file=mech.path, key=f"joints[{k}].type")
    backend = Symbolic()
    subs = mech.geometry_subs
    world = _gravity_turn(mech)
    names = _link_names(mech)
    shift = {0: (sympy.Integer(0),) * 3}
    robot = ET.Element("robot", name=mech.name)
    robot.append(ET.Comment(f" written by baseparams convert from {mech.path or mech.name} "))
    ET.SubElement(robot, "link", name=names[0])
    joints = []
    for edge in mech.tree:
        joint = edge.joint
        known, new = edge.known, edge.new
        f_known, f_new = ((joint.child_frame, joint.parent_frame) if edge.reversed
                          else (joint.parent_frame, joint.child_frame))
        rk, pk = _frame(mech, f_known, backend, subs)
        rn, pn = _frame(mech, f_new, backend, subs)
        raw = sympy.Matrix([sympy.sympify(v).subs(subs) for v in f_new.axis]) * (-1 if edge.reversed else 1)
        axis = rn[:, 2] * (-1 if edge.reversed else 1)
        if joint.type.name == "R":
            # the link origin must lie on the axis: the point of the axis line nearest the body origin
            shift[new] = tuple(pn - raw * (pn.dot(raw)) / raw.dot(raw))
        else:
            shift[new] = (sympy.Integer(0),) * 3
        if any(v != 0 for v in shift[new]):
            notes.append(f"link {names[new]}: origin shifted by ({', '.join(number(v) for v in shift[new])}) "
                         f"from body {new}'s frame onto the axis of {joint.name} (URDF puts it there); "
                         f"its inertia is shifted exactly")
        rot = rk * rn.T
        pos = pk - sympy.Matrix(shift[known]) - rot * (pn - sympy.Matrix(shift[new]))
        if known == 0:
            rot, pos = world * rot, world * pos
        joints.append((joint, new, known, rot, pos, _written_axis(axis, raw, notes, joint.name)))
    for body in mech.bodies:
        link = ET.SubElement(robot, "link", name=names[body.label])
        if body.inertia is not None:
            exact = [Fraction(int(v.p), int(v.q)) if v.is_Rational else None for v in map(sympy.nsimplify, shift[body.label])]
            s = tuple(v for v in exact if v is not None)
            if len(s) != len(exact):
                raise InputError(f"the axis of body {body.label}'s joint does not pass through a rational point "
                                 "near its origin: cannot shift its inertia exactly", file=mech.path)
            phi = transform_parameters(body.inertia, IDENTITY, tuple(-v for v in s))
            link.append(_inertial(phi, f"bodies[{body.label}]", mech.path))
        else:
            notes.append(f"body {body.label} has no inertia: link {names[body.label]} has no <inertial>")
    effects = {(e.kind, e.coordinate): e for e in getattr(mech, "effects", ())}
    unknown: list[str] = []
    for joint, new, known, rot, pos, axis in joints:
        jname = joint.coordinates[0] if len(joint.coordinates) == 1 else joint.name
        kind = URDF_TYPE[joint.type.name]
        if kind == "revolute" and not joint.limits:
            kind = "continuous"
        elem = ET.SubElement(robot, "joint", name=jname, type=kind)
        ET.SubElement(elem, "parent", link=names[known])
        ET.SubElement(elem, "child", link=names[new])
        ET.SubElement(elem, "origin", xyz=_triple(pos), rpy=_rpy(rot))
        if kind in ("revolute", "continuous", "prismatic"):
            ET.SubElement(elem, "axis", xyz=_triple(axis))
            limit = _limit(joint, kind)
            if kind == "continuous" and limit is not None and set(limit) != {"effort", "velocity"}:
                notes.append(f"joint {jname}: only {', '.join(limit)} known; URDF's <limit> needs effort and "
                             "velocity together: not written")
                limit = None
            if limit is not None:
                ET.SubElement(elem, "limit", limit)
            missing = {"lower", "upper", "effort", "velocity"} - set(limit or ()) if kind != "continuous" else set()
            if missing:
                unknown.append(f"{jname} ({', '.join(sorted(missing))})")
            dynamics: dict[str, str] = {}
            for effect_kind, attr, coefficient in (("viscous_friction", "damping", "fv"),
                                                   ("coulomb_friction", "friction", "fc")):
                spec = effects.pop((effect_kind, joint.coordinates[0]), None)
                if spec is not None and coefficient in spec.values:
                    dynamics[attr] = number(sympy.Rational(spec.values[coefficient]))
                elif spec is not None:
                    notes.append(f"{effect_kind} on {joint.coordinates[0]}: no known value, not written")
            if dynamics:
                ET.SubElement(elem, "dynamics", dynamics)
    for (kind, coordinate) in effects:
        notes.append(f"{kind} on {coordinate}: URDF has no such element, not written")
    if unknown:
        notes.append(f"<limit> attributes URDF requires but the mechanism does not know, not written (none is "
                     f"invented): {'; '.join(unknown)}. urdfdom, hence ROS and Pinocchio, refuse such a file until "
                     "they are added (in the mechanism file: `limits` and `drive_limits`, docs/mechanism-format.md)")
    if mech.geometry:
        notes.append(f"geometry names ({', '.join(mech.geometry)}) written as their values")
    if mech.trajectory is not None:
        notes.append("the trajectory is not part of URDF; the URDF reader makes a default one")
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n", notes


def _limit(joint: Joint, kind: str) -> dict[str, str] | None:
    """The ``<limit>`` attributes the mechanism knows for a one-coordinate joint (None: none).

    Only what was read or declared is written: never a zero effort or velocity, which
    ROS, Gazebo and MoveIt take as "cannot move". A revolute joint without a position range
    is written ``continuous`` by the caller (URDF's unlimited hinge), whose ``<limit>`` is
    optional and carries only effort and velocity."""
    name = joint.coordinates[0]
    limit: dict[str, str] = {}
    if kind != "continuous" and name in joint.limits:
        lo, hi = joint.limits[name]
        limit.update(lower=repr(lo), upper=repr(hi))
    limit.update({k: repr(v) for k, v in sorted(joint.drive_limits.get(name, {}).items())})
    return limit or None


def _frame(mech: Mechanism, frame: Frame, backend: Symbolic, subs: Mapping[Any, Any]) -> tuple[Any, Any]:
    """(R, p) of ``frame`` as exact sympy matrices (geometry substituted)."""
    rot, p = mech.numeric_frame(frame, backend)
    rot = sympy.Matrix(rot).subs(subs)
    return rot, sympy.Matrix(p).subs(subs)


def _written_axis(unit: Any, raw: Any, notes: list[str], name: str) -> list[Any]:
    """The axis as written: the unit vector when its entries are exact decimals, else the
    direction as the shortest integer vector when it is rational (exact; readers normalise
    it, as Pinocchio and ours do), else the unit vector to 25 digits."""
    if all(v.is_Rational and "/" not in exact_text(Fraction(int(v.p), int(v.q))) for v in unit):
        return list(unit)
    if all(v.is_Rational for v in raw):
        den = sympy.ilcm(*[v.q for v in raw])
        ints = [int(v * den) for v in raw]
        g = sympy.igcd(*ints)
        notes.append(f"joint {name}: axis written as the integer direction {[i // g for i in ints]} (exact)")
        return [sympy.Integer(i // g) for i in ints]
    return list(unit)


def _rpy(rot: Any) -> str:
    """URDF's ``rpy`` text of a sympy rotation matrix."""
    entries: list[list[Any]] = [[rot[i, j] for j in range(3)] for i in range(3)]
    if all(sympy.sympify(v).is_Rational for row in entries for v in row):
        entries = [[Fraction(int(v.p), int(v.q)) for v in map(sympy.Rational, row)] for row in entries]
    else:
        entries = [[str(sympy.N(v, 40)) for v in row] for row in entries]
    return " ".join(_digits(a) if abs(a) > mpmath.mpf(10) ** -35 else "0" for a in matrix_rpy(entries))


def _gravity_turn(mech: Mechanism) -> Any:
    """The rotation that turns the ground's axes so gravity is along -z (URDF's convention)."""
    g = sympy.Matrix([sympy.sympify(v).subs(mech.geometry_subs) for v in mech.gravity])
    norm = sympy.sqrt(g.dot(g))
    if norm != sympy.Rational(981, 100):
        raise InputError(f"URDF has no gravity element (its users take 9.81 m/s^2 along -z of the root "
                         f"link); this mechanism's gravity has magnitude {sympy.N(norm, 6)}",
                         file=mech.path, key="mechanism.gravity")
    u = g / norm
    v = sympy.Matrix([0, 0, -1])
    if u == v:
        return sympy.eye(3)
    if u == -v:
        return sympy.diag(1, -1, -1)
    w = u.cross(v)
    wx = sympy.Matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    return sympy.eye(3) + wx + wx * wx / (1 + u.dot(v))


def _link_names(mech: Mechanism) -> dict[int, str]:
    """Link name per body label (0: the ground, ``world``): the body's name, else ``body<k>``."""
    names: dict[int, str] = {}
    used: set[str] = set()
    root = "world" if all(b.name != "world" for b in mech.bodies) else "ground"
    names[0] = root
    used.add(root)
    for body in mech.bodies:
        name = body.name if body.name and body.name not in used else f"body{body.label}"
        while name in used:
            name += "_"
        names[body.label] = name
        used.add(name)
    return names
