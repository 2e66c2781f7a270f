"""The mechanism model: bodies, joints, kinematic graph, spanning tree, loops, coordinates.

The model is immutable and exact: geometry is held as sympy expressions in named
geometry symbols whose values are exact rationals. Numbers in a given arithmetic are made
on demand by :meth:`Mechanism.numeric_frame` (and cached per backend), in the spirit of
Pinocchio's split between an immutable ``Model`` and per-evaluation ``Data``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import sympy

from baseparams.model.expressions import exact_text
from baseparams.model.joints import JointType
from baseparams.model.params import BodyKey, body_parameter_names, parameter_name, parameter_names, split_name

if TYPE_CHECKING:
    from baseparams.numeric.backends import Backend

Vector = tuple[Any, ...]              # three exact sympy expressions
Limits = tuple[float, float]


@dataclass(frozen=True)
class Frame:
    """A joint frame on one body: origin, z axis, x axis (None: default), as sympy exprs."""
    point: Vector
    axis: Vector = (sympy.Integer(0), sympy.Integer(0), sympy.Integer(1))
    ref: Vector | None = None


@dataclass(frozen=True)
class Body:
    label: int
    name: str = ""
    inertia: tuple[Fraction, ...] | None = None   # ten exact parameters about the origin, or None


@dataclass(frozen=True)
class Joint:
    name: str
    type: JointType
    parent: int
    child: int
    parent_frame: Frame
    child_frame: Frame
    coordinates: tuple[str, ...]      # coordinate names, one per motion
    limits: Mapping[str, Limits] = field(default_factory=dict, compare=False)  # name -> (lo, hi) floats
    loop: bool = False                # requested as loop-closing
    # name -> {"velocity": max |qd|, "effort": max |tau|} floats (a URDF's <limit velocity effort>)
    drive_limits: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class TreeEdge:
    """A tree joint as traversed from the body already placed (``known``) to ``new``."""
    joint: Joint
    reversed: bool

    @property
    def known(self) -> int:
        return self.joint.child if self.reversed else self.joint.parent

    @property
    def new(self) -> int:
        return self.joint.parent if self.reversed else self.joint.child


MAX_SAMPLES = 1_000_000
"""The most samples a trajectory may ask for (``trajectory.samples``, ``--samples``): W has
a row per sample and independent coordinate, and the float64 working memory is estimated
(and refused above a limit) before the samples are made (baseparams.dynamics.trajectory)."""


@dataclass(frozen=True)
class TrajectorySpec:
    """Default exciting trajectory: one expression of t per independent coordinate."""
    expressions: Mapping[str, Any]    # name -> sympy expression in t
    t_start: Fraction = Fraction(0)
    t_end: Fraction = Fraction(10)
    samples: int = 200


@dataclass(frozen=True)
class EffectSpec:
    """A model effect the mechanism includes (``[[effects]]``): its registered kind, the joint
    coordinate it acts on, and the coefficients already known (name -> exact value)."""
    kind: str
    coordinate: str
    values: Mapping[str, Fraction] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Motor:
    """A drive's motor-side coordinate: a fixed linear combination of joint coordinates,
    ``position = sum(ratio * q)``, so gear ratios of any sign, a coupled wrist (the TX40's
    motor 6 turns with ``32 (q5 + q6)``) and a differential are one form. Effects may act on
    it (rotor inertia, friction), and a recording may measure it (motor encoders, motor
    torques); its generalized force maps to the joints by the same ratios (power balance)."""
    name: str
    ratios: tuple[tuple[str, Fraction], ...]   # ((coordinate, ratio), ...), file order


@dataclass(frozen=True)
class Coupling:
    """A joint coordinate that follows another linearly, ``coordinate = ratio * leader +
    offset`` (a gear train between two joints, URDF's ``<mimic>``): it is not independent,
    and its velocity and acceleration are the leader's times ``ratio``."""
    coordinate: str
    leader: str
    ratio: Fraction
    offset: Fraction = Fraction(0)


@dataclass(frozen=True, eq=False)
class Mechanism:
    name: str
    bodies: tuple[Body, ...]          # ordered by label
    joints: tuple[Joint, ...]         # file order
    tree: tuple[TreeEdge, ...]        # traversal order
    loops: tuple[Joint, ...]          # loop-closing
    coordinates: tuple[str, ...]      # tree coordinate names, traversal order
    independent: tuple[str, ...]      # chosen independent coordinates
    geometry: Mapping[str, Fraction]  # name -> exact value
    gravity: Vector                   # sympy exprs, ground axes
    trajectory: TrajectorySpec | None = None
    title: str = ""
    description: str = ""
    source: str = ""
    path: str | None = None
    gruebler: int = 0
    effects: tuple[EffectSpec, ...] = ()      # file order
    warnings: tuple[str, ...] = ()            # remarks on the input that did not stop the build
    motors: tuple[Motor, ...] = ()            # file order: the drive chain (may be empty)
    couplings: tuple[Coupling, ...] = ()      # file order: coordinates following another
    nonphysical: tuple[tuple[str, str], ...] = ()   # (key, reason) of bodies accepted with a non-physical inertia
    nonphysical_labels: tuple[int, ...] = ()         # those bodies' labels, in the same order
    # per body, in body order: the name its parameters carry (``m_forearm``: a URDF's link
    # names, issue 45); empty: the labels (``m3``), as every mechanism file's bodies
    parameter_keys: tuple[str, ...] = ()

    # ----- names and counts -------------------------------------------------
    @property
    def body_labels(self) -> list[int]:
        return [b.label for b in self.bodies]

    @property
    def body_keys(self) -> list[BodyKey]:
        """What names each body in parameter names: its name (named bodies) or its label."""
        keys: list[BodyKey] = list(self.parameter_keys) if self.parameter_keys else list(self.body_labels)
        return keys

    @property
    def parameters(self) -> list[str]:
        return parameter_names(self.body_keys)

    def body_key(self, label: int) -> BodyKey:
        """Body ``label``'s key in parameter names (the label itself for the ground, 0)."""
        labels = self.body_labels
        return self.parameter_keys[labels.index(label)] if self.parameter_keys and label in labels else label

    def body_parameters(self, label: int) -> list[str]:
        """Body ``label``'s ten parameter names, as :attr:`parameters` writes them."""
        return body_parameter_names(self.body_key(label))

    def parameter_body(self, name: str) -> tuple[str, int]:
        """(kind, body label) of a parameter name in either form: this mechanism's
        (``m_forearm`` for a named body) or the label's (``m3``, accepted for every body).
        ValueError when it is no parameter name of this mechanism."""
        kind, key = split_name(name)
        if isinstance(key, int) and key in self.body_labels:
            return kind, key
        if isinstance(key, str) and key in self.parameter_keys:
            return kind, self.body_labels[self.parameter_keys.index(key)]
        raise ValueError(f"{name!r} names no body of {self.name}")

    def parameter(self, name: str) -> str:
        """This mechanism's name of a parameter given in either form (``m3`` -> ``m_forearm``)."""
        kind, label = self.parameter_body(name)
        return parameter_name(kind, self.body_key(label))

    @property
    def closure_equation_count(self) -> int:
        """The loop joints' closure equations and, on a mechanism with loops, one per
        coupling (solved with them: the closure Jacobian's rows)."""
        return sum(len(j.type.closure) for j in self.loops) + (len(self.couplings) if self.loops else 0)

    @property
    def motor_names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.motors)

    def motor(self, name: str) -> Motor:
        for m in self.motors:
            if m.name == name:
                return m
        raise KeyError(name)

    def joint_of_coordinate(self, name: str) -> Joint:
        for joint in self.joints:
            if name in joint.coordinates:
                return joint
        raise KeyError(name)

    def coordinate_kind(self, name: str) -> str:
        """'angle' or 'length': what a joint coordinate measures."""
        joint = self.joint_of_coordinate(name)
        return joint.type.coordinate_kinds[joint.coordinates.index(name)]

    def is_angle(self, name: str) -> bool:
        """Whether a coordinate (or a motor: all its coordinates) is an angle, not a length."""
        if name in self.motor_names:
            return all(self.is_angle(c) for c, _ in self.motor(name).ratios)
        return self.coordinate_kind(name) == "angle"

    def body(self, label: int) -> Body:
        for b in self.bodies:
            if b.label == label:
                return b
        raise KeyError(label)

    @property
    def geometry_text(self) -> dict[str, str]:
        """{name: exact decimal string}: the geometry as results and reports print it."""
        return {name: exact_text(value) for name, value in self.geometry.items()}

    @property
    def geometry_subs(self) -> dict[Any, Any]:
        """{sympy symbol: exact sympy rational}: substitutes the geometry into expressions."""
        return {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator) for k, v in self.geometry.items()}

    # ----- numbers in a backend --------------------------------------------
    def geometry_env(self, backend: Backend, symbolic: bool = False) -> dict[str, Any]:
        """Geometry values in ``backend`` (or sympy symbols when ``symbolic``)."""
        if symbolic:
            return {name: sympy.Symbol(name) for name in self.geometry}
        return {name: backend.rational(value) for name, value in self.geometry.items()}

    def numeric_frame(self, frame: Frame, backend: Backend,
                      symbolic: bool = False) -> tuple[list[list[Any]], list[Any]]:
        """(R, p): rotation (rows; columns are the frame's x, y, z) and origin in ``backend``."""
        env = self.geometry_env(backend, symbolic)
        p = [backend.evaluate(c, env) for c in frame.point]
        subs = self.geometry_subs
        z = _normalize(backend, [backend.evaluate(c, env) for c in _rescaled(frame.axis, subs)])
        if frame.ref is not None:
            x_raw = [backend.evaluate(c, env) for c in _rescaled(frame.ref, subs)]
        else:
            x_raw = _default_ref(frame.axis, self.geometry_subs, backend)
        d = x_raw[0] * z[0] + x_raw[1] * z[1] + x_raw[2] * z[2]
        x = _normalize(backend, [x_raw[i] - d * z[i] for i in range(3)])
        y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
        rot = [[x[i], y[i], z[i]] for i in range(3)]
        return rot, p

    def numeric_gravity(self, backend: Backend, symbolic: bool = False) -> list[Any]:
        env = self.geometry_env(backend, symbolic)
        return [backend.evaluate(c, env) for c in self.gravity]


def _rescaled(vector: Vector, subs: Mapping[Any, Any], spread: int = 20) -> Vector:
    """``vector`` (exact expressions) times an exact power of two that brings its largest
    component into [1, 2), when that component lies outside [2^-spread, 2^spread]: a
    direction does not depend on its length, and an axis such as (1e-300, 0, 0) would
    otherwise square to zero (or an axis of 1e200 to infinity) in double precision. Axes
    of ordinary lengths are left exactly as written."""
    values = [sympy.sympify(c).xreplace(subs) for c in vector]
    if not all(v.is_Rational for v in values):
        return vector
    largest = max(abs(Fraction(int(v.p), int(v.q))) for v in values)
    if largest == 0:
        return vector
    k = largest.numerator.bit_length() - largest.denominator.bit_length()
    if abs(k) <= spread:
        return vector
    scale = sympy.Integer(2) ** (-k)
    return tuple(sympy.sympify(c) * scale for c in vector)


def _normalize(backend: Backend, v: list[Any]) -> list[Any]:
    n2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    one = backend.rational(Fraction(1))
    inv = one / backend.sqrt(n2)
    return [v[0] * inv, v[1] * inv, v[2] * inv]


def _default_ref(axis: Vector, subs: Mapping[Any, Any], backend: Backend) -> list[Any]:
    """The body axis least aligned with ``axis`` (first in x, y, z order on ties)."""
    values = [abs(sympy.sympify(c).xreplace(subs)) for c in axis]
    k = min(range(3), key=lambda i: (values[i], i))
    e = [backend.rational(Fraction(int(i == k))) for i in range(3)]
    return e
