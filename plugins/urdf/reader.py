"""The URDF reader: a parsed URDF (:mod:`.parse`) built into a Mechanism through the builder.

Mapping (docs/urdf.md): the root link is the ground (body 0); every other link is a body,
labelled 1, 2, ... in file order, its body frame the link frame; a joint's frame in the
parent link is its ``<origin>`` turned so that z is the joint axis, and in the child link
the same axis through the link origin, so the child link frame moves exactly as URDF says.
revolute/continuous -> ``R``, prismatic -> ``P``, fixed: the child link lumped into its
parent exactly (the default since issue 47; ``merge_fixed=False`` keeps it as a body on a
``Fixed`` joint), floating -> ``Free``. Limits become coordinate limits;
``<dynamics damping friction>`` become viscous and Coulomb friction effects;
``<transmission>`` elements (simple, differential, four-bar linkage; under ``<robot>`` or,
ros2_control's, inside ``<ros2_control>``) become the motors of the drive chain (:func:`motor_ratios`); a default
exciting trajectory (a Fourier series inside the limits) is added so that every verb
works on a bare URDF.
"""

import random
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from decimal import Decimal
from fractions import Fraction
from pathlib import Path
from typing import Any

from baseparams.errors import InputError
from baseparams.model.builder import MechanismBuilder
from baseparams.model.expressions import exact_text
from baseparams.model.mechanism import Joint, Mechanism
from baseparams.model.params import PARAMETER_KINDS, parameter_name

from .parse import Urdf, UrdfJoint, UrdfTransmission, parse_urdf, transform_parameters
from .rotations import bounded_rotation, matmul, matvec

TYPE_OF = {"revolute": "R", "continuous": "R", "prismatic": "P", "fixed": "Fixed", "floating": "Free"}
RESERVED = frozenset({"t", "pi", "sin", "cos", "exp", "sqrt"})
ZERO10 = (Fraction(0),) * 10
GROUND = "<ground>"               # the ground's name when the root link floats (not a link name)
# default trajectory: amplitude about the middle of the range, when the joint has no limits
FREE_AMPLITUDE = {"R": Fraction(12, 10), "P": Fraction(2, 10)}
FLOATING_AMPLITUDE = (Fraction(2, 10),) * 3 + (Fraction(6, 10),) * 3   # Cardan b stays far from pi/2
RANGE_SHARE = Fraction(8, 10)      # of the half range, within the limits
T_END, SAMPLES = 10, 200
Bounds = tuple[Decimal, Decimal]   # a joint's (lower, upper) limits as the file writes them


@dataclass
class UrdfResult:
    """What reading a URDF gives: the mechanism, the notes (snapped or approximate angles,
    renamed joints, merged links ...), which link each body label is, and which links were
    lumped into which (``merged_into``: link -> the body's link, or the ground's name)."""
    mechanism: Mechanism
    notes: list[str]
    links: dict[int, str]          # body label -> link name
    merged: bool
    merged_into: dict[str, str] = field(default_factory=dict)


class UrdfReader:
    """The reader of ``.urdf`` files (registered by baseparams.plugins.urdf)."""

    name = "urdf"
    suffixes: tuple[str, ...] = (".urdf",)
    description = "URDF robot descriptions (docs/urdf.md)"
    options: tuple[str, ...] = ("merge_fixed", "keep_fixed", "floating_base")

    def read(self, path: str | Path, **options: bool) -> Mechanism:
        return read_urdf(path, **_flags(options)).mechanism

    def read_notes(self, path: str | Path, **options: bool) -> tuple[Mechanism, list[str]]:
        """The mechanism and the reader's notes (for ``convert``, which prints them)."""
        result = read_urdf(path, **_flags(options))
        return result.mechanism, result.notes


def _flags(options: dict[str, bool]) -> dict[str, bool]:
    """Reader options are flags (``convert --keep-fixed``): ``keep_fixed`` is ``merge_fixed=False``;
    ``merge_fixed``, the default since issue 47, is accepted as before."""
    keep = options.pop("keep_fixed", False)
    if keep and options.get("merge_fixed"):
        raise InputError("--merge-fixed and --keep-fixed contradict each other: give one")
    return {**options, "merge_fixed": not keep}


def read_urdf(path: str | Path, *, merge_fixed: bool = True, floating_base: bool = False) -> UrdfResult:
    """Read the URDF file at ``path``. ``merge_fixed`` (default): fixed joints' links lumped
    into their parents exactly, before any solver runs (issue 47: fewer parameters, the same
    dynamics); False keeps each as a body on a ``Fixed`` joint. ``floating_base``: the root
    link is a body on a Free joint (else it is the ground)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", file=path) from None
    return build(parse_urdf(text, path), merge_fixed=merge_fixed, floating_base=floating_base)


def build(urdf: Urdf, *, merge_fixed: bool = True, floating_base: bool = False) -> UrdfResult:
    """The mechanism of a parsed URDF (see :func:`read_urdf` for the options)."""
    notes = list(urdf.notes)
    inertia = {name: link.inertia if link.inertia is not None else ZERO10 for name, link in urdf.links.items()}
    joints = [_copy(j) for j in urdf.joints]
    contradictions = _contradicting_limits(joints)
    if floating_base:
        ground = GROUND
        joints.insert(0, UrdfJoint("floating_base", "floating", GROUND, urdf.root, "robot"))
        links = list(urdf.links)
    else:
        ground = urdf.root
        links = [name for name in urdf.links if name != urdf.root]
        if urdf.links[urdf.root].has_inertial:
            notes.append(f"{urdf.links[urdf.root].key}.inertial: the root link is the ground (fixed); its "
                         "inertia does not act and is not kept")
    if not any(urdf.links[name].has_inertial for name in links):
        raise InputError("no moving link has an <inertial> element: a visual or collision (mesh-only) "
                         "description has no dynamic model; add <inertial> elements" + (
                             "" if floating_base or not urdf.links[urdf.root].has_inertial else
                             f" (only the root link {urdf.root!r} has one: --floating-base for a free-flying robot)"),
                         file=urdf.path, key="robot")
    massless = [name for name in links if urdf.links[name].inertia is None]
    if massless:
        notes.append(f"links without <inertial> (mass 0): {', '.join(massless)}")
    merged_into: dict[str, str] = {}
    if merge_fixed:
        joints, links = _merge_fixed(ground, joints, links, inertia, merged_into)
        notes += _merge_notes(merged_into, ground, inertia)
    if not links:           # every joint fixed: everything lumped into the ground
        raise InputError("no moving link: every joint is fixed, so the mechanism has no degree of freedom",
                         file=urdf.path, key="robot")
    label = {name: k + 1 for k, name in enumerate(links)}
    label[ground] = 0
    b = MechanismBuilder(_mechanism_name(urdf.robot), urdf.path, title=f"{urdf.robot} (URDF)",
                         description=f"Read from the URDF file {Path(urdf.path).name}: body k is the k-th "
                                     f"link (file order) after the ground {ground!r} (docs/urdf.md).",
                         source=f"URDF {urdf.path}", lenient_inertia=True)
    for key, text in urdf.warnings + contradictions:
        b.warn(key, text)
    for name in links:
        phi = inertia[name]
        b.body(label[name], name, inertia=dict(zip(PARAMETER_KINDS, phi)), key=urdf.links[name].key)
    used: set[str] = set()
    motions, names = [], {}
    for j in joints:
        jtype = TYPE_OF[j.type]
        cname = _identifier(j.name, used)
        if cname != j.name:
            notes.append(f"{j.key}: coordinate named {cname!r} (joint names must be identifiers here)")
        parent_frame, child_frame = _frames(j, jtype)
        limits = {cname: list(j.limits)} if j.limits is not None and jtype in ("R", "P") else None
        drives = {cname: j.drive} if j.drive and jtype in ("R", "P") else None
        joint = b.joint(jtype, label[j.parent], label[j.child], name=cname, parent_frame=parent_frame,
                        child_frame=child_frame, limits=limits, drive_limits=drives, key=j.key)
        for name, value in (("viscous_friction", j.damping), ("coulomb_friction", j.friction)):
            if value:
                coefficient = "fv" if name == "viscous_friction" else "fc"
                b.effect(name, cname, {coefficient: value}, key=f"{j.key}.dynamics")
        motions.append((joint, jtype, j.limits))
        if jtype in ("R", "P"):
            names[j.name] = cname
    followers = _couplings(b, joints, names)
    _motors(b, urdf.transmissions, names, used, notes)
    motions = [(joint, jtype, _leader_limits(joint, limits, joints, names, followers))
               for joint, jtype, limits in motions if not set(joint.coordinates) & followers]
    b.trajectory(default_trajectory(urdf.robot, motions), t_start=0, t_end=T_END, samples=SAMPLES,
                 key="trajectory")
    mech = replace(b.build(), parameter_keys=_parameter_keys(urdf, links, notes))
    return UrdfResult(mech, notes, {v: k for k, v in label.items() if v}, merge_fixed, merged_into)


def _parameter_keys(urdf: Urdf, links: Sequence[str], notes: list[str]) -> tuple[str, ...]:
    """Each body's name in parameter names (``m_forearm``, issue 45): its link's name, made
    an identifier (noted when it had to change) and unique."""
    used: set[str] = set()
    keys = []
    for name in links:
        key = _identifier(name, used)
        if key != name:
            notes.append(f"{urdf.links[name].key}: parameters named {parameter_name('m', key)} ... "
                         f"(parameter names need identifiers)")
        keys.append(key)
    return tuple(keys)


def _couplings(b: MechanismBuilder, joints: Sequence[UrdfJoint], names: Mapping[str, str]) -> set[str]:
    """``<mimic>`` joints as couplings: the coordinate = multiplier * the leader's + offset."""
    followers = set()
    for j in joints:
        if j.mimic is None:
            continue
        leader, multiplier, offset = j.mimic
        if leader not in names:
            raise InputError(f"joint {leader!r} is not a moving joint of the model", file=b.path,
                             key=f"{j.key}.mimic.joint")
        b.coupling(names[j.name], names[leader], multiplier, offset, key=f"{j.key}.mimic")
        followers.add(names[j.name])
    return followers


def _contradicting_limits(joints: Sequence[UrdfJoint]) -> list[tuple[str, str]]:
    """Followers whose own limits no leader value inside the leader's limits meets (PR2's
    r_gripper_r_parallel_root_joint = -1 x r_gripper_l_finger_joint, both in [0, 0.548]):
    their limits are dropped, with a warning, so that the default trajectory exists."""
    by_name = {j.name: j for j in joints}
    out = []
    for j in joints:
        leader = by_name.get(j.mimic[0]) if j.mimic is not None else None
        if leader is None or j.mimic is None or j.limits is None or leader.limits is None:
            continue
        _, multiplier, offset = j.mimic
        ends = sorted((multiplier * leader.limits[0] + offset, multiplier * leader.limits[1] + offset))
        if max(ends[0], j.limits[0]) >= min(ends[1], j.limits[1]):
            out.append((f"{j.key}.limit", f"[{j.limits[0]}, {j.limits[1]}] is not reached by {multiplier} x "
                        f"{leader.name} + {offset} with {leader.name} in [{leader.limits[0]}, {leader.limits[1]}] "
                        "(the file's limits contradict its <mimic>): these limits are not enforced"))
            j.limits = None
    return out


def _leader_limits(joint: Joint, limits: Bounds | None, joints: Sequence[UrdfJoint], names: Mapping[str, str],
                   followers: set[str]) -> Bounds | None:
    """The leader's range for the default trajectory, narrowed so that every joint mimicking it
    stays inside its own limits (follower = multiplier * leader + offset)."""
    if not followers:
        return limits
    lo, hi = (Decimal(limits[0]), Decimal(limits[1])) if limits is not None else (None, None)
    for j in joints:
        if j.mimic is None or j.limits is None or names.get(j.mimic[0]) not in joint.coordinates:
            continue
        _, multiplier, offset = j.mimic
        ends = sorted(((j.limits[0] - offset) / multiplier, (j.limits[1] - offset) / multiplier))
        lo = ends[0] if lo is None else max(lo, ends[0])
        hi = ends[1] if hi is None else min(hi, ends[1])
    return (lo, hi) if lo is not None and hi is not None and lo < hi else limits


def motor_ratios(transmission: UrdfTransmission) -> list[tuple[str, dict[str, Decimal]]] | str:
    """Each actuator's position as gear ratios of its joints' positions, or why the
    transmission is not understood. ros_control's conventions (actuator a, joint j,
    reductions ar, jr): simple a = ar jr j (jr = 1 when not given); differential
    a1 = ar1 (jr1 j1 + jr2 j2), a2 = ar2 (jr1 j1 - jr2 j2); four-bar linkage a1 = ar1 jr1 j1,
    a2 = ar2 (jr1 j1 + jr2 j2)."""
    kind, joints, actuators = transmission.type, transmission.joints, transmission.actuators
    if kind == "SimpleTransmission" and len(joints) == 1 and len(actuators) == 1:
        (j, jr), (a, ar) = joints[0], actuators[0]
        return [(a, {j: ar * jr})]
    if kind in ("DifferentialTransmission", "FourBarLinkageTransmission") and len(joints) == len(actuators) == 2:
        (j1, jr1), (j2, jr2) = joints
        (a1, ar1), (a2, ar2) = actuators
        if kind == "DifferentialTransmission":
            return [(a1, {j1: ar1 * jr1, j2: ar1 * jr2}), (a2, {j1: ar2 * jr1, j2: -ar2 * jr2})]
        return [(a1, {j1: ar1 * jr1}), (a2, {j1: ar2 * jr1, j2: ar2 * jr2})]
    return (f"type {kind or 'missing'!r} with {len(joints)} joint(s) and {len(actuators)} actuator(s) "
            "is not one this reader maps (simple, differential, four-bar linkage)")


def _motors(b: MechanismBuilder, transmissions: Sequence[UrdfTransmission], names: Mapping[str, str],
            used: set[str], notes: list[str]) -> None:
    """The transmissions' actuators as motors of the drive chain (docs/urdf.md)."""
    from baseparams.model.builder import name_problem
    for t in transmissions:
        found = motor_ratios(t)
        if isinstance(found, str):
            notes.append(f"{t.key}: ignored: {found}")
            continue
        missing = [j for _, ratios in found for j in ratios if j not in names]
        if missing:
            notes.append(f"{t.key}: ignored: joint {missing[0]!r} is not a moving joint of the model")
            continue
        for actuator, ratios in found:
            name = _identifier(actuator, used)
            if name_problem(name):
                name = _identifier(f"motor_{name}", used)
            if name != actuator:
                notes.append(f"{t.key}: actuator {actuator!r} named {name!r} (an identifier that is "
                             "no parameter name)")
            b.motor(name, {names[j]: r for j, r in ratios.items()}, key=t.key)


def _copy(j: UrdfJoint) -> UrdfJoint:
    return type(j)(**vars(j))


def _merge_fixed(ground: str, joints: list[UrdfJoint], links: list[str], inertia: dict[str, tuple[Fraction, ...]],
                 merged_into: dict[str, str]) -> tuple[list[UrdfJoint], list[str]]:
    """Fixed joints removed: each child link's parameters moved exactly into its parent's
    frame and added, in rationals (parameters are linear in the mass distribution; the
    rotations are the exact rational ones the file's angles give, composed exactly through
    chains of fixed joints); its children hang from the parent with composed origins (a
    composed rotation whose entries grew long is shortened for the joint frame only). A link fixed to the root joins the ground. ``merged_into`` gets
    link -> the link (or ground) that now carries it."""
    exact: dict[int, Any] = {}          # id(joint) -> its exact rotation where j.rotation was shortened
    while True:
        fixed = next((j for j in joints if j.type == "fixed"), None)
        if fixed is None:
            return joints, links
        parent, child = fixed.parent, fixed.child
        rotation = exact.get(id(fixed), fixed.rotation)
        if parent != ground:
            moved = transform_parameters(inertia[child], rotation, fixed.origin)
            inertia[parent] = tuple(a + c for a, c in zip(inertia[parent], moved))
        for link, into in list(merged_into.items()):
            if into == child:
                merged_into[link] = parent
        merged_into[child] = parent
        for j in joints:
            if j.parent == child:
                j.parent = parent
                j.origin = tuple(a + c for a, c in zip(matvec(rotation, j.origin), fixed.origin))
                exact[id(j)] = matmul(rotation, exact.get(id(j), j.rotation))
                j.rotation = bounded_rotation(exact[id(j)])      # the frame: short entries, within 2e-17 rad
        joints = [j for j in joints if j is not fixed]
        links = [name for name in links if name != child]


def _merge_notes(merged_into: Mapping[str, str], ground: str, inertia: Mapping[str, tuple[Fraction, ...]]) -> list[str]:
    """One note per body that lumps links, and one for the links with inertia fixed to the
    ground (``inertia``: each link's, its own lumped children's included)."""
    into: dict[str, list[str]] = {}
    for link, target in merged_into.items():
        into.setdefault(target, []).append(link)
    notes = []
    for target, links in into.items():
        if target != ground:
            notes.append(f"link {target!r} lumps the fixed link(s) {', '.join(links)} (fixed joints merged "
                         "exactly; merge_fixed=False keeps them as bodies)")
        elif any(any(inertia[link]) for link in links):
            notes.append(f"link(s) {', '.join(link for link in links if any(inertia[link]))} fixed to the "
                         "root link: merged into the ground, their inertia does not act")
    return notes


def _frames(j: UrdfJoint, jtype: str) -> tuple[dict[str, list[Any]], dict[str, list[Any]]]:
    """(parent_frame, child_frame): z along the joint axis, the same axes on both sides."""
    if jtype in ("R", "P"):
        axis = j.axis
        k = min(range(3), key=lambda i: (abs(axis[i]), i))
        ek = tuple(Fraction(int(i == k)) for i in range(3))
        norm2 = sum(a * a for a in axis)
        ref = ek if axis[k] == 0 else tuple(norm2 * e - axis[k] * a for e, a in zip(ek, axis))
    else:
        axis = (Fraction(0), Fraction(0), Fraction(1))
        ref = (Fraction(1), Fraction(0), Fraction(0))
    parent = {"point": list(j.origin), "axis": list(matvec(j.rotation, axis)), "ref": list(matvec(j.rotation, ref))}
    child: dict[str, list[Any]] = {"point": [0, 0, 0], "axis": list(axis), "ref": list(ref)}
    return parent, child


def _identifier(name: str, used: set[str]) -> str:
    text = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not text or text[0].isdigit() or text in RESERVED:
        text = "j_" + text
    base, k = text, 2
    while text in used:
        text, k = f"{base}_{k}", k + 1
    used.add(text)
    return text


def _mechanism_name(robot: str) -> str:
    return re.sub(r"[^a-z0-9_]", "_", robot.lower()) or "robot"


def default_trajectory(robot: str, motions: Sequence[tuple[Joint, str, Bounds | None]]) -> dict[str, str]:
    """A Fourier series per coordinate (an offset and three sines of distinct frequencies)
    inside its limits: centred in the range and reaching ``RANGE_SHARE`` of the half range
    (at most 1.2 rad or 0.2 m); free joints 0.2 m and 0.6 rad. Deterministic per robot."""
    rng = random.Random(f"urdf:{robot}")
    q = {}
    for joint, jtype, limits in motions:
        for k, name in enumerate(joint.coordinates):
            if jtype == "Free":
                centre, amplitude = Fraction(0), FLOATING_AMPLITUDE[k]
            elif limits is not None:
                lo, hi = Fraction(limits[0]), Fraction(limits[1])
                centre = (lo + hi) / 2
                amplitude = min(RANGE_SHARE * (hi - lo) / 2, FREE_AMPLITUDE[jtype])
            else:
                centre, amplitude = Fraction(0), FREE_AMPLITUDE[jtype]
            q[name] = _fourier(rng, amplitude, centre)
    return q


def _fourier(rng: random.Random, amplitude: Fraction, centre: Fraction) -> str:
    freqs = rng.sample([Fraction(k, 10) for k in range(5, 31)], 3)
    weights = [Fraction(rng.randint(20, 100), 100) for _ in range(3)]
    total = sum(weights)
    centre = Fraction(round(centre * 10 ** 6), 10 ** 6)
    terms = [exact_text(centre)] if centre else []
    for w, f in zip(weights, freqs):
        a = Fraction(int(amplitude * w / total * 1000), 1000)          # rounded down: stays inside
        phase = Fraction(rng.randint(0, 30), 10)
        terms.append(f"{exact_text(a)}*sin({exact_text(f)}*t + {exact_text(phase)})")
    return " + ".join(terms) or "0"
