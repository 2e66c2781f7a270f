"""URDF XML -> checked, exact link and joint records (no mechanism yet).

The standard library's ``xml.etree.ElementTree`` reads the file: URDF is a small,
flat XML vocabulary, and a parser dependency (urdfdom's Python bindings, yourdfpy,
urdf_parser_py) would add nothing this module needs while parsing numbers through
floats. Every number is read from the attribute text as a :class:`~decimal.Decimal`,
so no value passes through a binary float; rotations become exact rationals
(:mod:`.rotations`). Every problem is an :class:`~baseparams.errors.InputError` naming
the file, the element (``joint[name=elbow].origin.rpy``) and the reason.
"""

import xml.etree.ElementTree as ET
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from pathlib import Path

from baseparams.errors import InputError
from baseparams.model.params import from_mass_properties

from .rotations import IDENTITY, ROUNDED, Rotation, is_long, matmul, matvec, rounded, rpy_matrix, transpose

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
ZERO3 = (Fraction(0), Fraction(0), Fraction(0))


@dataclass
class Link:
    name: str
    key: str
    inertia: tuple[Fraction, ...] | None   # ten parameters about the link origin, link axes (Fractions)
    has_inertial: bool = False


@dataclass
class UrdfJoint:
    name: str
    type: str
    parent: str
    child: str
    key: str
    rotation: Rotation = IDENTITY     # joint frame (= child link frame) in the parent link frame
    origin: tuple[Fraction, ...] = ZERO3
    axis: tuple[Fraction, ...] = (Fraction(0), Fraction(0), Fraction(1))
    limits: tuple[Decimal, Decimal] | None = None       # (lower, upper)
    drive: dict[str, Decimal] | None = None   # {"velocity": v, "effort": e} positive Decimals of <limit>
    damping: Decimal | None = None
    friction: Decimal | None = None
    mimic: tuple[str, Decimal, Decimal] | None = None   # (leader joint name, multiplier, offset)


@dataclass
class UrdfTransmission:
    """A ``<transmission>`` (ROS 1 or ros2_control form): its type's last word and the
    reductions of its joints and actuators, in file order."""
    name: str
    type: str
    joints: list[tuple[str, Decimal]]      # [(joint name, reduction)]
    actuators: list[tuple[str, Decimal]]   # [(actuator name, reduction)]
    key: str


@dataclass
class Urdf:
    """A parsed, checked URDF: links in file order, joints in file order, the root link."""
    path: str
    robot: str
    links: dict[str, Link]            # file order
    joints: list[UrdfJoint]           # file order
    root: str
    notes: list[str] = field(default_factory=list)
    transmissions: list[UrdfTransmission] = field(default_factory=list)
    warnings: list[tuple[str, str]] = field(default_factory=list)     # (key, text): printed by every verb


class _Parser:
    def __init__(self, path: str) -> None:
        self.path = path
        self.notes: list[str] = []
        self.warnings: list[tuple[str, str]] = []

    def error(self, key: str, reason: str) -> InputError:
        return InputError(reason, file=self.path, key=key)

    def once(self, elem: ET.Element, key: str, tags: tuple[str, ...]) -> None:
        """The URDF spec allows each of ``tags`` at most once inside ``elem``: a second one
        is an error (which of the two would count is a guess)."""
        for tag in tags:
            found = elem.findall(tag)
            if len(found) > 1:
                raise self.error(f"{key}.{tag}", f"{len(found)} <{tag}> elements: URDF allows one")

    # ----- numbers -------------------------------------------------------------------------
    def decimals(self, text: str | None, key: str, count: int) -> list[Decimal]:
        parts = (text or "").split()
        if len(parts) != count:
            raise self.error(key, f"needs {count} number(s), got {text!r}")
        out: list[Decimal] = []
        for part in parts:
            try:
                value = Decimal(part)
            except InvalidOperation:
                raise self.error(key, f"{part!r} is not a number") from None
            if not value.is_finite():
                raise self.error(key, f"{part!r} is not a finite number")
            out.append(value)
        return out

    def number(self, elem: ET.Element, attr: str, key: str, default: Decimal | None = None) -> Decimal:
        text = elem.get(attr)
        if text is None:
            if default is None:
                raise self.error(f"{key}.{attr}", "missing (required)")
            return default
        return self.decimals(text, f"{key}.{attr}", 1)[0]

    def origin(self, parent: ET.Element, key: str) -> tuple[Rotation, tuple[Fraction, ...]]:
        """(R, p) of an ``<origin>`` child (identity when absent)."""
        elem = parent.find("origin")
        if elem is None:
            return IDENTITY, ZERO3
        okey = f"{key}.origin"
        xyz = [Fraction(v) for v in self.decimals(elem.get("xyz", "0 0 0"), f"{okey}.xyz", 3)]
        rpy = self.decimals(elem.get("rpy", "0 0 0"), f"{okey}.rpy", 3)
        rot, how = rpy_matrix(*rpy)
        for name, value, h in zip(("roll", "pitch", "yaw"), rpy, how):
            if h == "snapped":
                self.notes.append(f"{okey}.rpy: {name} {value} taken as exactly "
                                  f"{_quarter_text(value)} (within 1e-9)")
            elif h == "rational":
                self.notes.append(f"{okey}.rpy: {name} {value} is not a multiple of pi/2: taken as the "
                                  f"rational rotation within 2e-17 rad of it (approximate)")
        return rot, tuple(xyz)

    # ----- elements ------------------------------------------------------------------------
    def transmission(self, elem: ET.Element, key: str) -> UrdfTransmission:
        """A ``<transmission>``: ``<type>`` (ROS 1) or ``<plugin>`` (ros2_control), and each
        ``<joint>``/``<actuator>`` with its ``<mechanicalReduction>`` or
        ``<mechanical_reduction>`` (default 1), on the element or inside it."""
        kind = (elem.findtext("type") or elem.findtext("plugin") or "").strip()
        parts: dict[str, list[tuple[str, Decimal]]] = {"joint": [], "actuator": []}
        for tag in parts:
            for i, child in enumerate(elem.findall(tag)):
                name = child.get("name")
                ckey = f"{key}.{tag}[{i}]"
                if not name:
                    raise self.error(f"{ckey}.name", "missing (required)")
                text = child.findtext("mechanicalReduction") or child.findtext("mechanical_reduction")
                reduction = self.decimals(text, f"{ckey}.mechanicalReduction", 1)[0] if text else Decimal(1)
                if reduction == 0:
                    raise self.error(f"{ckey}.mechanicalReduction", "a reduction of 0: the actuator "
                                     "would not move with the joint")
                parts[tag].append((name, reduction))
        return UrdfTransmission(elem.get("name") or "", kind.rsplit("/", 1)[-1].rsplit(":", 1)[-1],
                                parts["joint"], parts["actuator"], key)

    def link(self, elem: ET.Element, key: str) -> Link:
        name = elem.get("name") or ""       # parse_urdf checked it
        self.once(elem, key, ("inertial",))
        inertial = elem.find("inertial")
        if inertial is None:
            return Link(name, key, None)
        ikey = f"{key}.inertial"
        self.once(inertial, ikey, ("origin", "mass", "inertia"))
        rot, com = self.origin(inertial, ikey)
        mass_elem = inertial.find("mass")
        if mass_elem is None:
            raise self.error(f"{ikey}.mass", "missing (required in <inertial>)")
        mass = Fraction(self.number(mass_elem, "value", f"{ikey}.mass"))
        tensor_elem = inertial.find("inertia")
        if tensor_elem is None:
            raise self.error(f"{ikey}.inertia", "missing (required in <inertial>)")
        e = {a: Fraction(self.number(tensor_elem, a, f"{ikey}.inertia"))
             for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        tensor = ((e["ixx"], e["ixy"], e["ixz"]), (e["ixy"], e["iyy"], e["iyz"]), (e["ixz"], e["iyz"], e["izz"]))
        # physical consistency is the builder's check (a warning for URDF: see reader.build)
        if mass == 0 and any(v for row in tensor for v in row):
            self.notes.append(f"{ikey}: zero mass with a nonzero inertia (kept as written)")
        # the tensor at the COM in the inertial frame's axes, turned into link axes: R I R^T
        turned = matmul(matmul(rot, tensor), transpose(rot))
        entries = [turned[i][j] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))]
        phi = tuple(from_mass_properties(mass, com, entries))
        if any(is_long(v) for v in phi):
            self.notes.append(f"{ikey}: parameters rounded to {ROUNDED} significant digits (the inertial "
                              "frame's rotation is approximate)")
        return Link(name, key, tuple(rounded(v) for v in phi), True)

    def joint(self, elem: ET.Element, key: str, links: Collection[str]) -> UrdfJoint:
        name = elem.get("name") or ""       # parse_urdf checked it
        jtype = elem.get("type")
        self.once(elem, key, ("parent", "child", "origin", "axis", "limit", "dynamics", "mimic", "calibration",
                              "safety_controller"))
        if jtype is None or jtype not in JOINT_TYPES:
            raise self.error(f"{key}.type", f"unknown joint type {jtype!r} (URDF types: {', '.join(JOINT_TYPES)})")
        if jtype == "planar":
            raise self.error(f"{key}.type", "planar joints are not supported (docs/urdf.md): model the "
                             "plane motion as two prismatic joints and a revolute one through massless links")
        ends = []
        for end in ("parent", "child"):
            sub = elem.find(end)
            link = None if sub is None else sub.get("link")
            if link is None:
                raise self.error(f"{key}.{end}", "missing <" + end + " link=...> (required)")
            if link not in links:
                raise self.error(f"{key}.{end}", f"link {link!r} is not defined")
            ends.append(link)
        if ends[0] == ends[1]:
            raise self.error(key, "parent and child are the same link")
        rot, origin = self.origin(elem, key)
        joint = UrdfJoint(name, jtype, ends[0], ends[1], key, rot, origin)
        if jtype in ("revolute", "continuous", "prismatic"):
            axis_elem = elem.find("axis")
            if axis_elem is not None:
                axis = tuple(Fraction(v) for v in self.decimals(axis_elem.get("xyz", "1 0 0"), f"{key}.axis.xyz", 3))
                if not any(axis):
                    raise self.error(f"{key}.axis.xyz", "zero-length axis")
                joint.axis = axis
            else:
                joint.axis = (Fraction(1), Fraction(0), Fraction(0))      # the URDF default
        mimic = elem.find("mimic")
        if mimic is not None and jtype == "fixed":
            self.notes.append(f"{key}.mimic: a fixed joint does not move: its <mimic> is ignored (as "
                              "urdfdom and Pinocchio do)")
        elif mimic is not None:
            if jtype not in ("revolute", "continuous", "prismatic"):
                raise self.error(f"{key}.mimic", f"a {jtype} joint cannot mimic another")
            leader = mimic.get("joint")
            if not leader:
                raise self.error(f"{key}.mimic.joint", "missing (required)")
            joint.mimic = (leader, self.number(mimic, "multiplier", f"{key}.mimic", Decimal(1)),
                           self.number(mimic, "offset", f"{key}.mimic", Decimal(0)))
        limit = elem.find("limit")
        if jtype in ("revolute", "prismatic") and limit is not None:
            lo = self.number(limit, "lower", f"{key}.limit", Decimal(0))
            hi = self.number(limit, "upper", f"{key}.limit", Decimal(0))
            if lo < hi:
                joint.limits = (lo, hi)
            else:
                self.notes.append(f"{key}.limit: lower {lo} is not below upper {hi}: no limits taken")
        if jtype in ("revolute", "continuous", "prismatic") and limit is not None:
            drive = {attr: self.number(limit, attr, f"{key}.limit") for attr in ("velocity", "effort")
                     if limit.get(attr) is not None}
            joint.drive = {attr: value for attr, value in drive.items() if value > 0} or None
        dynamics = elem.find("dynamics")
        if dynamics is not None and jtype in ("revolute", "continuous", "prismatic"):
            for attr in ("damping", "friction"):
                if dynamics.get(attr) is not None:
                    value = self.number(dynamics, attr, f"{key}.dynamics")
                    if value < 0:
                        raise self.error(f"{key}.dynamics.{attr}", f"negative {attr} {value}")
                    setattr(joint, attr, value)
        return joint


def _quarter_text(value: Decimal) -> str:
    k = round(float(value) / 1.5707963267948966)
    return {0: "0", 1: "pi/2", -1: "-pi/2", 2: "pi", -2: "-pi"}.get(k, f"{k}*pi/2")


def parse_urdf(text: str, path: str | Path = "<string>") -> Urdf:
    """Parse and check URDF ``text``: elements, numbers, names, one root, a tree (no cycles)."""
    path = str(path)
    p = _Parser(path)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"malformed XML: {exc}", file=path) from None
    if root.tag != "robot":
        raise p.error(root.tag, "the top element must be <robot>")
    robot = root.get("name") or Path(path).stem
    links: dict[str, Link] = {}
    for i, elem in enumerate(root.findall("link")):
        name, key = _named(p, elem, "link", i, links)
        links[name] = p.link(elem, key)
    if not links:
        raise p.error("robot", "no <link> element")
    joints: list[UrdfJoint] = []
    names: set[str] = set()
    parent_of: dict[str, UrdfJoint] = {}
    for i, elem in enumerate(root.findall("joint")):
        name, key = _named(p, elem, "joint", i, names)
        names.add(name)
        joint = p.joint(elem, key, links)
        if joint.child in parent_of:
            raise p.error(f"{key}.child", f"link {joint.child!r} already has a parent joint "
                          f"({parent_of[joint.child].name}): URDF is a tree (closed loops are not URDF)")
        parent_of[joint.child] = joint
        joints.append(joint)
    moving = {j.name for j in joints if j.type in ("revolute", "continuous", "prismatic")}
    for j in joints:
        if j.mimic is not None and j.mimic[0] not in moving:
            what = "not a joint of this robot" if j.mimic[0] not in names else "not a moving joint"
            p.warnings.append((f"{j.key}.mimic.joint", f"joint {j.mimic[0]!r} is {what}: the <mimic> is "
                               f"ignored and {j.name!r} moves independently (as Pinocchio without mimic support "
                               "does); fix the file if it should follow a joint"))
            j.mimic = None
    roots = [name for name in links if name not in parent_of]
    if not roots:
        raise p.error("robot", f"the joints form a cycle: {_cycle(links, parent_of)}")
    if len(roots) > 1:
        raise p.error("robot", f"more than one root link ({', '.join(roots)}): every link but one needs a "
                      "parent joint")
    reached = {roots[0]}
    frontier = [roots[0]]
    while frontier:
        link = frontier.pop()
        for j in joints:
            if j.parent == link and j.child not in reached:
                reached.add(j.child)
                frontier.append(j.child)
    unreached = [name for name in links if name not in reached]
    if unreached:
        raise p.error("robot", f"the joints form a cycle: {_cycle({n: None for n in unreached}, parent_of)}")
    transmissions = [p.transmission(elem, f"transmission[name={elem.get('name')}]" if elem.get("name")
                                    else f"transmission[{i}]")
                     # ROS 1 puts them under <robot>, ros2_control inside <ros2_control> (TIAGo Pro)
                     for i, elem in enumerate(root.findall("transmission") + root.findall("ros2_control/transmission"))]
    return Urdf(path, robot, links, joints, roots[0], p.notes, transmissions, p.warnings)


def _named(p: _Parser, elem: ET.Element, tag: str, index: int, seen: Collection[str]) -> tuple[str, str]:
    """A ``<link>``'s or ``<joint>``'s name and its key path (``link[name=base]``, or
    ``link[3]`` without a name), checked: present, and not one of ``seen``."""
    name = elem.get("name")
    key = f"{tag}[name={name}]" if name else f"{tag}[{index}]"
    if not name:
        raise p.error(f"{key}.name", "missing (required)")
    if name in seen:
        raise p.error(key, f"{tag} {name!r} is defined twice")
    return name, key


def _cycle(links: Mapping[str, object], parent_of: Mapping[str, UrdfJoint]) -> str:
    start = next(iter(links))
    seen, name = [], start
    while name not in seen:
        seen.append(name)
        name = parent_of[name].parent
    loop = seen[seen.index(name):] + [name]
    return " <- ".join(loop)


# ----- rigid transforms of ten inertial parameters -----------------------------------------------
def transform_parameters(phi: Sequence[Fraction], rot: Rotation, p: Sequence[Fraction]) -> tuple[Fraction, ...]:
    """Ten parameters about a frame B (B axes) -> about frame A (A axes), where B's axes are
    ``rot``'s columns in A and B's origin is ``p`` in A. Exact for exact inputs (mass
    distribution: x_A = rot x_B + p, so h_A = rot h + m p and the second moments follow)."""
    m, hx, hy, hz, ixx, ixy, ixz, iyy, iyz, izz = phi
    inertia = ((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz))
    h = matvec(rot, (hx, hy, hz))
    turned = matmul(matmul(rot, inertia), transpose(rot))
    ph = sum(a * b for a, b in zip(p, h))
    pp = sum(a * a for a in p)
    out = [[turned[i][j] + (2 * ph + m * pp) * (1 if i == j else 0) - p[i] * h[j] - h[i] * p[j] - m * p[i] * p[j]
            for j in range(3)] for i in range(3)]
    return (m, h[0] + m * p[0], h[1] + m * p[1], h[2] + m * p[2],
            out[0][0], out[0][1], out[0][2], out[1][1], out[1][2], out[2][2])
