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

from __future__ import annotations

import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import sympy

from baseparams.numeric.backends import Symbolic
from baseparams.model.mechanism import Frame, Joint, Mechanism
from baseparams.model.multipoles import TransferRule

Tensor = list[list[Any]]              # 3 x 3, rows (exact numbers or sympy expressions)
Placement = tuple[list[list[Any]], list[Any]]   # (R, p) of a frame in its body's axes

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
    vector: dict[str, Any]
    kind: str
    multipole: str
    condition: int
    bodies: tuple[int, ...]
    joint: Joint | None = None
    sides: dict[int, dict[str, Any]] = field(default_factory=dict)
    label: str = ""
    preference: list[Any] = field(default_factory=list)
    donor: int | None = None
    acceptor: int | None = None

    @property
    def joint_name(self) -> str:
        return self.joint.name if self.joint is not None else ""

    @property
    def joint_type(self) -> str:
        return self.joint.type.name if self.joint is not None else ""


# ----- multipoles as ten-parameter changes (generic in the number type) -------------------
def tensor_entries(t: Sequence[Sequence[Any]]) -> list[Any]:
    """A symmetric 3x3 tensor (rows) as the six entries Ixx Ixy Ixz Iyy Iyz Izz."""
    return [t[i][j] for i, j in TENSOR_INDEX]


def monopole_params(b: Sequence[Any]) -> list[Any]:
    """Ten parameters of a unit point mass at body point ``b`` (about the origin)."""
    bx, by, bz = b
    return [1, bx, by, bz, by * by + bz * bz, -bx * by, -bx * bz, bx * bx + bz * bz, -by * bz,
            bx * bx + by * by]


def dipole_params(b: Sequence[Any], u: Sequence[Any]) -> list[Any]:
    """Ten parameters of a unit dipole along ``u`` placed at ``b``: (0, u, 2(b.u)1 - (bu^T + ub^T))."""
    bu = b[0] * u[0] + b[1] * u[1] + b[2] * u[2]
    t = [[(2 * bu if i == j else 0) - (b[i] * u[j] + u[i] * b[j]) for j in range(3)] for i in range(3)]
    return [0, u[0], u[1], u[2]] + tensor_entries(t)


def quadrupole_params(tensor: Sequence[Sequence[Any]]) -> list[Any]:
    return [0, 0, 0, 0] + tensor_entries(tensor)


def axisymmetric(u: Sequence[Any]) -> Tensor:
    """``1 - u u^T`` (u a unit vector): the quadrupole a relative rotation about u cannot see."""
    return [[(1 if i == j else 0) - u[i] * u[j] for j in range(3)] for i in range(3)]


def basis_tensor(k: int) -> Tensor:
    """The k-th symmetric basis tensor, matching INERTIA_KINDS[k] (unit entry, both halves)."""
    i, j = TENSOR_INDEX[k]
    t: Tensor = [[0, 0, 0] for _ in range(3)]
    t[i][j] = 1
    t[j][i] = 1
    return t


def rotate_tensor(r: Sequence[Sequence[Any]], t: Sequence[Sequence[Any]]) -> Tensor:
    """R T R^T for R given as rows."""
    rt = [[sum(r[i][k] * t[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    return [[sum(rt[i][k] * r[j][k] for k in range(3)) for j in range(3)] for i in range(3)]


def as_vector(names: Sequence[str], values: Sequence[Any], sign: int = 1) -> dict[str, Any]:
    """Ten values of a body -> {parameter name: sympy expr}, zeros dropped; ``names``: the
    body's ten names (``Mechanism.body_parameters``)."""
    out: dict[str, Any] = {}
    for name, value in zip(names, values):
        v = sympy.sympify(value) * sign
        if v != 0:
            out[name] = v
    return out


def add_vectors(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        s = out.get(k, 0) + v
        if s == 0:
            out.pop(k, None)
        else:
            out[k] = s
    return out


# ----- rules at joints -------------------------------------------------------------------
_FRAMES: weakref.WeakKeyDictionary[Mechanism, dict[int, Placement]] = weakref.WeakKeyDictionary()   # {id(frame): (R, p)}


def symbolic_frame(mechanism: Mechanism, frame: Frame) -> Placement:
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


def joint_frames(mechanism: Mechanism, joint: Joint) -> dict[int, Placement]:
    """Exact (R, p) of the joint frame in the parent's and the child's body axes (symbols)."""
    return {joint.parent: symbolic_frame(mechanism, joint.parent_frame),
            joint.child: symbolic_frame(mechanism, joint.child_frame)}


def map_point(frame: Placement, x: Sequence[Any]) -> list[Any]:
    """Joint-frame point x in body axes: p + R x (exact)."""
    r, p = frame
    return [sympy.sympify(p[i]) + sum(r[i][k] * x[k] for k in range(3)) for i in range(3)]


def map_direction(frame: Placement, u: Sequence[Any]) -> list[Any]:
    """Joint-frame direction u in body axes: R u (exact)."""
    r, _ = frame
    return [sum(r[i][k] * u[k] for k in range(3)) for i in range(3)]


def rule_generators(mechanism: Mechanism, joint: Joint, rule: TransferRule) -> list[Generator]:
    """The null generators of one rule at one joint (six for 'any quadrupole', else one).

    The vector is (parent's change) - (child's change); its sign is immaterial (null space).
    """
    frames = joint_frames(mechanism, joint)
    x = [sympy.sympify(c) for c in rule.point]
    u: list[Any] | None = None
    if rule.direction is not None:
        raw = [sympy.sympify(c) for c in rule.direction]
        norm = sympy.sqrt(sum(c * c for c in raw))
        u = [c / norm for c in raw]
    moving = [b for b in (joint.parent, joint.child) if b != 0]
    out: list[Generator] = []
    variants: list[tuple[int | None, Callable[[Placement], list[Any]]]]
    along: list[Any] = u or []          # read only where the rule has a direction
    if rule.multipole == "quadrupole" and u is None:
        variants = [(k, _basis_quadrupole(k)) for k in range(6)]
    elif rule.multipole == "quadrupole":
        variants = [(None, lambda fr: quadrupole_params(axisymmetric(map_direction(fr, along))))]
    elif rule.multipole == "dipole":
        variants = [(None, lambda fr: dipole_params(map_point(fr, x), map_direction(fr, along)))]
    else:
        variants = [(None, lambda fr: monopole_params(map_point(fr, x)))]
    for k, make in variants:
        vector: dict[str, Any] = {}
        sides: dict[int, dict[str, Any]] = {}
        for body, sign in ((joint.parent, 1), (joint.child, -1)):
            fr = frames[body]
            sides[body] = {"point": map_point(fr, x),
                           "direction": None if u is None else map_direction(fr, u)}
            if body == 0:
                continue
            vector = add_vectors(vector, as_vector(mechanism.body_parameters(body), make(fr), sign))
        label = rule.multipole if k is None else f"quadrupole {INERTIA_KINDS[k]}"
        out.append(Generator(vector=vector, kind="transfer", multipole=rule.multipole,
                             condition=rule.condition, bodies=tuple(moving), joint=joint,
                             sides=sides, label=label))
    return out


def _basis_quadrupole(k: int) -> Callable[[Placement], list[Any]]:
    """The k-th basis quadrupole (any symmetric tensor crosses) in a body's axes."""
    return lambda fr: quadrupole_params(rotate_tensor(fr[0], basis_tensor(k)))


def transfer_generators(mechanism: Mechanism, rules_of: Callable[[str], Sequence[TransferRule] | None],
                        ) -> tuple[list[Generator], list[Joint]]:
    """(generators, joints without rules): every rule of every joint, tree and loop-closing.

    ``rules_of``: joint type name -> its :class:`~baseparams.model.multipoles.TransferRule`
    list, or None when unknown. Callers pass ``baseparams.registry.transfer_rules`` (or rules
    of their own, in tests): the dynamics do not ask the plugin registry themselves.
    """
    gens: list[Generator] = []
    missing: list[Joint] = []
    for joint in mechanism.joints:
        rules = rules_of(joint.type.name)
        if rules is None:
            missing.append(joint)
            continue
        for rule in rules:
            gens.extend(rule_generators(mechanism, joint, rule))
    return gens, missing


def numeric_vector(generator: Generator, mechanism: Mechanism,
                   values: Mapping[str, Fraction] | None = None) -> list[Any]:
    """The generator's full 10*bodies vector with the geometry substituted (exact Fractions or
    sympy numbers when a square root of a non-square remains)."""
    subs = mechanism.geometry_subs if values is None else \
        {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator) for k, v in values.items()}
    out: list[Any] = []
    for name in mechanism.parameters:
        given = generator.vector.get(name)
        if given is None:
            out.append(Fraction(0))
            continue
        v = sympy.simplify(sympy.sympify(given).subs(subs))
        out.append(Fraction(int(v.p), int(v.q)) if v.is_Rational else v)
    return out
