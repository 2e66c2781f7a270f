"""Multipoles as parameter vectors, and the null generators of multipole transfers at joints.

Ros et al.'s method works with multipoles at points of a body; the base-parameter
algebra works with the ten parameters about the body origin (``m mx my mz Ixx Ixy Ixz Iyy
Iyz Izz``, inertia as tensor entries, ``Ixy = -∫xy dm``). This module is the bridge: the
change of the ten parameters when a multipole is added at a body point b,

- monopole mu at b: ``mu (1, b, |b|^2 1 - b b^T)`` (a point mass's inertia about the origin);
- dipole d along unit u at b: ``d (0, u, 2(b.u) 1 - (b u^T + u b^T))`` (= ``-(b~u~ + u~b~)``,
  ~ the skew matrix), the limit of +m at b + e u/2 and -m at b - e u/2 with m e = d;
- quadrupole: a symmetric tensor Q added to the inertia, ``(0, 0, Q)``; the axisymmetric
  one about u is ``lambda (1 - u u^T)``.

A joint-type rule (:class:`baseparams.model.multipoles.TransferRule`) names a multipole that may
cross a joint; mapping it into both bodies' frames with the joint's exact placement
(joint-frame point x -> body point p + R x, direction u -> R u, tensor E -> R E R^T) gives
a vector n = (acceptor's change) - (donor's change) with W n = 0: a *null generator*.
Ground has no parameters, so a transfer with ground changes one body only.
"""

import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from fractions import Fraction

import sympy

from baseparams.numeric.backends import Symbolic
from baseparams.model.params import body_parameter_names

INERTIA_KINDS = ("Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")
TENSOR_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))   # same order as INERTIA_KINDS
AXIS_NAMES = "xyz"


@dataclass
class Generator:
    """A null vector of the observation matrix, with where it comes from (for reports).

    ``vector``: parameter name -> exact sympy coefficient (zeros left out).
    ``kind``: "condition" (one body, seed paper's section 3.2) or "transfer" (two bodies
    across a joint, section 3.3). ``condition``: the paper's condition number.
    ``sides``: body label -> {"point": [...], "direction": [...]} where the multipole sits
    in that body's axes (for the derivation report). ``donor``/``acceptor`` are set by
    the solver for transfers (0 stands for ground).
    """
    vector: dict
    kind: str
    multipole: str
    condition: int
    bodies: tuple
    joint: object = None
    sides: dict = field(default_factory=dict)
    label: str = ""
    preference: list = field(default_factory=list)
    donor: int | None = None
    acceptor: int | None = None

    @property
    def joint_name(self):
        return self.joint.name if self.joint is not None else ""

    @property
    def joint_type(self):
        return self.joint.type.name if self.joint is not None else ""


# ----- multipoles as ten-parameter changes (generic in the number type) -------------------
def tensor_entries(t):
    """A symmetric 3x3 tensor (rows) as the six entries Ixx Ixy Ixz Iyy Iyz Izz."""
    return [t[i][j] for i, j in TENSOR_INDEX]


def monopole_params(b):
    """Ten parameters of a unit point mass at body point ``b`` (about the origin)."""
    bx, by, bz = b
    return [1, bx, by, bz, by * by + bz * bz, -bx * by, -bx * bz, bx * bx + bz * bz, -by * bz,
            bx * bx + by * by]


def dipole_params(b, u):
    """Ten parameters of a unit dipole along ``u`` placed at ``b``: (0, u, 2(b.u)1 - (bu^T + ub^T))."""
    bu = b[0] * u[0] + b[1] * u[1] + b[2] * u[2]
    t = [[(2 * bu if i == j else 0) - (b[i] * u[j] + u[i] * b[j]) for j in range(3)] for i in range(3)]
    return [0, u[0], u[1], u[2]] + tensor_entries(t)


def quadrupole_params(tensor):
    return [0, 0, 0, 0] + tensor_entries(tensor)


def axisymmetric(u):
    """``1 - u u^T`` (u a unit vector): the quadrupole a relative rotation about u cannot see."""
    return [[(1 if i == j else 0) - u[i] * u[j] for j in range(3)] for i in range(3)]


def basis_tensor(k):
    """The k-th symmetric basis tensor, matching INERTIA_KINDS[k] (unit entry, both halves)."""
    i, j = TENSOR_INDEX[k]
    t = [[0, 0, 0] for _ in range(3)]
    t[i][j] = 1
    t[j][i] = 1
    return t


def rotate_tensor(r, t):
    """R T R^T for R given as rows."""
    rt = [[sum(r[i][k] * t[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    return [[sum(rt[i][k] * r[j][k] for k in range(3)) for j in range(3)] for i in range(3)]


def as_vector(label, values, sign=1):
    """Ten values of body ``label`` -> {parameter name: sympy expr}, zeros dropped."""
    out = {}
    for name, v in zip(body_parameter_names(label), values):
        v = sympy.sympify(v) * sign
        if v != 0:
            out[name] = v
    return out


def add_vectors(a, b):
    out = dict(a)
    for k, v in b.items():
        s = out.get(k, 0) + v
        if s == 0:
            out.pop(k, None)
        else:
            out[k] = s
    return out


# ----- rules at joints -------------------------------------------------------------------
_FRAMES = weakref.WeakKeyDictionary()      # mechanism -> {id(frame): (R, p)}


def symbolic_frame(mechanism, frame):
    """Exact (R, p) of one of ``mechanism``'s frames in its body's axes (geometry symbols):
    ``mechanism.numeric_frame(frame, Symbolic(), symbolic=True)``, computed once per frame
    (each joint's rules, the sampled transfers and every body's candidate directions ask
    for the same frames, and each costs sympy substitutions). A Mechanism and
    its frames are immutable and live together, so the frame's id is a key. Callers must
    not change the lists returned."""
    known = _FRAMES.setdefault(mechanism, {})
    key = id(frame)
    if key not in known:
        known[key] = mechanism.numeric_frame(frame, Symbolic(), symbolic=True)
    return known[key]


def joint_frames(mechanism, joint):
    """Exact (R, p) of the joint frame in the parent's and the child's body axes (symbols)."""
    return {joint.parent: symbolic_frame(mechanism, joint.parent_frame),
            joint.child: symbolic_frame(mechanism, joint.child_frame)}


def map_point(frame, x):
    """Joint-frame point x in body axes: p + R x (exact)."""
    r, p = frame
    return [sympy.sympify(p[i]) + sum(r[i][k] * x[k] for k in range(3)) for i in range(3)]


def map_direction(frame, u):
    """Joint-frame direction u in body axes: R u (exact)."""
    r, _ = frame
    return [sum(r[i][k] * u[k] for k in range(3)) for i in range(3)]


def rule_generators(mechanism, joint, rule):
    """The null generators of one rule at one joint (six for 'any quadrupole', else one).

    The vector is (parent's change) - (child's change); its sign is immaterial (null space).
    """
    frames = joint_frames(mechanism, joint)
    x = [sympy.sympify(c) for c in rule.point]
    u = None if rule.direction is None else [sympy.sympify(c) for c in rule.direction]
    if u is not None:
        norm = sympy.sqrt(sum(c * c for c in u))
        u = [c / norm for c in u]
    moving = [b for b in (joint.parent, joint.child) if b != 0]
    out = []
    if rule.multipole == "quadrupole" and u is None:
        variants = [(k, lambda fr, k=k: quadrupole_params(rotate_tensor(fr[0], basis_tensor(k))))
                    for k in range(6)]
    elif rule.multipole == "quadrupole":
        variants = [(None, lambda fr: quadrupole_params(axisymmetric(map_direction(fr, u))))]
    elif rule.multipole == "dipole":
        variants = [(None, lambda fr: dipole_params(map_point(fr, x), map_direction(fr, u)))]
    else:
        variants = [(None, lambda fr: monopole_params(map_point(fr, x)))]
    for k, make in variants:
        vector = {}
        sides = {}
        for body, sign in ((joint.parent, 1), (joint.child, -1)):
            fr = frames[body]
            sides[body] = {"point": map_point(fr, x),
                           "direction": None if u is None else map_direction(fr, u)}
            if body == 0:
                continue
            vector = add_vectors(vector, as_vector(body, make(fr), sign))
        label = rule.multipole if k is None else f"quadrupole {INERTIA_KINDS[k]}"
        out.append(Generator(vector=vector, kind="transfer", multipole=rule.multipole,
                             condition=rule.condition, bodies=tuple(moving), joint=joint,
                             sides=sides, label=label))
    return out


def transfer_generators(mechanism, rules_of: Callable[[str], list | None]):
    """(generators, joints without rules): every rule of every joint, tree and loop-closing.

    ``rules_of``: joint type name -> its :class:`~baseparams.model.multipoles.TransferRule`
    list, or None when unknown. Callers pass ``baseparams.registry.transfer_rules`` (or rules
    of their own, in tests): the dynamics do not ask the plugin registry themselves.
    """
    gens, missing = [], []
    for joint in mechanism.joints:
        rules = rules_of(joint.type.name)
        if rules is None:
            missing.append(joint)
            continue
        for rule in rules:
            gens.extend(rule_generators(mechanism, joint, rule))
    return gens, missing


def numeric_vector(generator, mechanism, values=None):
    """The generator's full 10*bodies vector with the geometry substituted (exact Fractions or
    sympy numbers when a square root of a non-square remains)."""
    subs = mechanism.geometry_subs if values is None else \
        {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator) for k, v in values.items()}
    out = []
    for name in mechanism.parameters:
        v = generator.vector.get(name)
        if v is None:
            out.append(Fraction(0))
            continue
        v = sympy.simplify(sympy.sympify(v).subs(subs))
        out.append(Fraction(int(v.p), int(v.q)) if v.is_Rational else v)
    return out
