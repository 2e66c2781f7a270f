"""Parameters without effect, found from each body's motion (seed paper, section 3.2, Tab. 4).

A direction n in one body's ten parameters has no effect on the dynamics exactly when the
body's Lagrangian contribution along n is a constant: its kinetic part ``T_i . n`` (a
quadratic form in the velocities) vanishes in every state and its potential part
``V_i . n`` is the same in every configuration. The paper's six conditions are the cases of
this (a point at rest, an angular velocity of constant direction, a translating body,
``g . d`` constant ...). Rather than asking the user which case applies, each body's motion
is sampled at random states in ball arithmetic:

1. the numeric null space of the stacked rows ``T_i(s)`` and ``V_i(s) - V_i(s_0)`` gives
   how many such directions the body has;
2. exact candidates are built from the mechanism's own exact data: the angular velocity's
   span (0: translating; 1: a constant direction u, taken from a body axis or a joint axis
   parallel to it; 2: a constant plane) gives the quadrupoles Q with ``w^T Q w = 0``;
   dipoles along body and joint axes placed at the origin or at a joint point, and
   monopoles at the origin or at a joint point, are kept when their numeric residual
   vanishes (a point at rest, ``g . d`` constant ...);
3. a maximal independent set of the valid candidates is returned as exact generators.

A candidate is accepted here on numerical evidence only (relative residual below 1e-14 on
12 states at 28 digits); the solver re-checks every accepted generator in ball arithmetic
on the observation matrix (:func:`baseparams.plugins.solvers.symbolic.elimination.certify`). If fewer exact
generators are found than numeric null directions exist, the body is reported (the
symbolic count then misses dependencies; the rank check shows it). Sampled transfers
across joints use the same states: :mod:`baseparams.plugins.solvers.symbolic.sampled_transfers`.
"""

import random
import weakref
from dataclasses import dataclass, field
from collections.abc import Sequence
from typing import Any
from fractions import Fraction

import mpmath
import numpy as np
import sympy
from flint import arb, fmpq_mat

from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Arb, Float64
from baseparams.numeric.rank import numerical_rank, to_fmpq
from baseparams.dynamics.evaluator import Evaluator, independent_rows
from baseparams.dynamics.observation import RationalStates, evaluate_states
from baseparams.errors import InputError
from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.transfers import (INERTIA_KINDS, TENSOR_INDEX, Generator, as_vector, dipole_params,
                        monopole_params, quadrupole_params, symbolic_frame)

with mpmath.workprec(53):              # a fixed constant, whatever precision is current at import
    NULL_TOL = mpmath.mpf(10) ** -14  # relative size of a null singular value / residual
INDEPENDENCE_TOL = 1e-10              # relative norm left after projecting out a basis


@dataclass
class BodyMotion:
    """What sampling says about one body's motion, and the exact generators found."""
    label: int
    omega_rank: int                       # dimension of the angular velocity's span in body axes
    null_dimension: int                   # numeric count of directions without effect
    axis: list | None = None              # exact constant direction of omega (omega_rank 1)
    rest_points: list = field(default_factory=list)   # exact candidate points at rest
    generators: list = field(default_factory=list)

    @property
    def motion(self) -> str:
        if self.omega_rank == 0:
            return "translation" if not self.rest_points else "at rest"
        if self.omega_rank == 1:
            return "rotation about a fixed axis" if self.rest_points else "planar (constant rotation axis direction)"
        if self.omega_rank == 2:
            return "rotation axis in a constant plane"
        return "general"

    @property
    def missing(self) -> int:
        return self.null_dimension - len(self.generators)


# ----- random states ---------------------------------------------------------------------
def random_states(mechanism: Mechanism, count: int = 12, digits: int = 30, seed: int = 1) -> tuple[list, Arb]:
    """``count`` random states (Arb samples) on the constraint manifold.

    Positions: the default trajectory's positions at random times (so closed loops close
    on the assembly branch the trajectory follows); without a trajectory (open chains
    only) random angles in [-1, 1]. Velocities and accelerations: random rationals.
    """
    rng = random.Random(seed)
    names = mechanism.independent or mechanism.coordinates
    f = len(names)
    if mechanism.trajectory is not None:
        traj = Trajectory.default(mechanism)
        t0, t1 = float(traj.times[0]), float(traj.times[-1])
        times = np.array([t0 + (t1 - t0) * rng.random() for _ in range(count)])
        z_float, _, _ = traj.independent_values(mechanism, Float64(), times)
        z_float = [np.broadcast_to(np.asarray(v, float), times.shape) for v in z_float]
        zs = [[Fraction(float(z_float[j][k])).limit_denominator(10 ** 9) for j in range(f)]
              for k in range(count)]
    elif mechanism.loops:
        raise InputError("the mechanism has closed loops but no [trajectory]: random states "
                         "need a trajectory to stay on the assembly branch",
                         file=mechanism.path, key="trajectory")
    else:
        zs = [[Fraction(rng.randint(-1000, 1000), 1000) for _ in range(f)] for _ in range(count)]
    zds = [[Fraction(rng.randint(-1000, 1000), 1000) for _ in range(f)] for _ in range(count)]
    zdds = [[Fraction(rng.randint(-1000, 1000), 1000) for _ in range(f)] for _ in range(count)]
    guesses: list[Any] = [None] * count
    if mechanism.loops:
        fl = Evaluator(mechanism, Float64())
        zarr = [np.array([float(zs[k][j]) for k in range(count)]) for j in range(f)]
        q = fl.assemble(zarr, where="random states: ")
        guesses = [[Fraction(float(np.atleast_1d(v)[k])) for v in q] for k in range(count)]
    backend = Arb(digits)
    z, zd, zdd = (tuple(map(tuple, v)) for v in (zs, zds, zdds))
    states: Any = RationalStates(z, zd, zdd, start=tuple(guesses) if mechanism.loops else None, name="random state")
    return evaluate_states(mechanism, backend, states, certify=False), backend


def to_mpf(x: arb | float | int | Fraction, dps: int) -> mpmath.mpf:
    """An arb ball's midpoint (or any real number) as an mpmath number, read to ``dps``
    digits and 5 more (call inside ``mpmath.workdps(dps)``)."""
    if isinstance(x, arb):
        return mpmath.mpf(x.mid().str(dps + 5, radius=False))
    return mpmath.mpf(x)


# ----- numeric helpers -------------------------------------------------------------------
class Rows(list):
    """Rows of mpmath numbers (a list) that also keep their exact rational copy, built once:
    every mpf is a dyadic rational, so products and sums of them can be made exactly in C
    (python-flint ``fmpq_mat``) instead of one mpmath operation at a time."""

    _exact = None

    def exact(self) -> fmpq_mat:
        if self._exact is None:
            self._exact = exact_matrix(self)
        return self._exact


def exact_matrix(rows: Sequence[Sequence[mpmath.mpf]]) -> fmpq_mat:
    if not rows:
        return fmpq_mat(0, 0)
    return fmpq_mat(len(rows), len(rows[0]), [to_fmpq(v) for row in rows for v in row])


def _normalized_rows(rows: Sequence[Sequence[mpmath.mpf]], dps: int) -> Rows:
    """Rows scaled to unit max-norm; rows that are zero at ``dps`` digits are dropped."""
    peaks = [max(abs(v) for v in row) for row in rows]
    scale = max(peaks, default=mpmath.mpf(0))
    if scale == 0:
        return Rows()
    out = Rows()
    floor = scale * mpmath.mpf(10) ** (-(dps - 8))
    for row, m in zip(rows, peaks):
        if m > floor:
            out.append([v / m for v in row])
    return out


def null_basis(rows: Sequence[Sequence[mpmath.mpf]], ncols: int, tol: mpmath.mpf = NULL_TOL) -> list[list[mpmath.mpf]]:
    """Orthonormal basis (list of vectors) of the numeric null space of ``rows``."""
    if not rows:
        return [[mpmath.mpf(int(i == j)) for i in range(ncols)] for j in range(ncols)]
    a = mpmath.matrix(rows)
    if a.rows < ncols:
        a = mpmath.matrix(list(rows) + [[0] * ncols] * (ncols - a.rows))
    _, s, v = mpmath.svd_r(a)
    top = max(abs(x) for x in s) or 1
    return [[v[k, i] for i in range(ncols)] for k in range(ncols)
            if k >= len(s) or abs(s[k]) <= tol * top]


def residual(rows: Sequence[Sequence[mpmath.mpf]], n: Sequence[mpmath.mpf]) -> mpmath.mpf:
    """max |row . n| / |n| over ``rows`` (each scaled to unit max-norm): how far n is from null.
    The dot products are exact (rationals, in C), then rounded once to working precision."""
    norm = mpmath.sqrt(sum(x * x for x in n))
    if norm == 0 or not rows:
        return mpmath.mpf(0)
    a = rows.exact() if isinstance(rows, Rows) else exact_matrix(rows)
    products = a * fmpq_mat(len(n), 1, [to_fmpq(x) for x in n])
    top = max(abs(products[i, 0]) for i in range(products.nrows()))
    return mpmath.mpf(int(top.p)) / int(top.q) / norm


def independent(vectors: Sequence[Sequence[Any]]) -> list[int]:
    """Indices of the vectors independent of the earlier ones, in order (greedy
    Gram-Schmidt on unit vectors, so the tolerance is relative: a candidate is dependent
    when less than ``INDEPENDENCE_TOL`` of it is left). Float64 is enough: the vectors
    are exact data of moderate size, only their independence is decided."""
    rows = []
    for v in vectors:
        a = np.array([float(x) for x in v])
        n = np.linalg.norm(a)
        rows.append(a / n if n > 0 else a)
    return independent_rows(np.array(rows), INDEPENDENCE_TOL) if rows else []


# ----- exact candidates ------------------------------------------------------------------
def to_number(expr: object, subs: dict, dps: int) -> mpmath.mpf:
    """An exact expression at the geometry ``subs``, as an mpmath number to ``dps`` digits
    (call inside ``mpmath.workdps(dps)``).
    A rational (int, Fraction, sympy Rational: most entries) is divided out directly,
    without sympy's substitution and evaluation."""
    if isinstance(expr, int):
        return mpmath.mpf(expr)
    if isinstance(expr, Fraction):
        return mpmath.mpf(expr.numerator) / expr.denominator
    if isinstance(expr, sympy.Rational):
        return mpmath.mpf(int(expr.p)) / int(expr.q)
    return mpmath.mpf(sympy.N(sympy.sympify(expr).subs(subs), dps + 5))


_CANDIDATES: weakref.WeakKeyDictionary[Mechanism, dict[int, tuple[tuple, tuple]]] = weakref.WeakKeyDictionary()


def body_candidates(mechanism: Mechanism, label: int) -> tuple[tuple, tuple]:
    """Exact candidate points and unit directions of a body (body axes), as tuples: computed
    once per mechanism and body (the body conditions and every sampled transfer across the
    body's joints ask for them; a Mechanism is immutable)."""
    known = _CANDIDATES.setdefault(mechanism, {})
    if label not in known:
        points, dirs = _body_candidates(mechanism, label)
        known[label] = (tuple(points), tuple(dirs))
    return known[label]


def _body_candidates(mechanism: Mechanism, label: int) -> tuple[list, list]:
    """Exact candidate points and unit directions of a body (body axes).

    Points: the origin and the body's joint points. Directions: the body axes, its joint
    frames' axes, and those of every body that turns with it (connected through joints
    that only translate, P or Fixed), carried over exactly: a prismatic joint's sliding
    body sees the rotation axis of the joint above it (a planar motion's axis)."""
    zero = sympy.Integer(0)
    points = [("origin", [zero, zero, zero])]
    dirs = []
    for other, rot in same_rotation(mechanism, label):
        via = "" if other == label else f" (body {other}'s, carried over)"
        dirs += [(f"{a}{other}{via}", [rot[i][k] for i in range(3)]) for k, a in enumerate("xyz")]
        for joint in mechanism.joints:
            for side, frame in ((joint.parent, joint.parent_frame), (joint.child, joint.child_frame)):
                if side != other:
                    continue
                r, p = symbolic_frame(mechanism, frame)
                if other == label:
                    points.append((f"{joint.name} point", [sympy.sympify(c) for c in p]))
                for k, a in enumerate("xyz"):
                    column = [r[i][k] for i in range(3)]
                    dirs.append((f"{joint.name} {a} axis{via}",
                                 [sum(rot[i][m] * column[m] for m in range(3)) for i in range(3)]))
    return points, dirs


def same_rotation(mechanism: Mechanism, label: int) -> list:
    """[(body, M)]: the bodies that always turn with ``label`` (through joints whose motions
    are all translations), with M the exact rotation from that body's axes to ``label``'s
    (``label`` itself first, M = 1). Ground is left out: its directions are not the body's."""
    one, zero = sympy.Integer(1), sympy.Integer(0)
    identity = [[one if i == j else zero for j in range(3)] for i in range(3)]
    found = {label: identity}
    frontier = [label]
    while frontier:
        body = frontier.pop()
        for joint in mechanism.joints:
            if any(kind != "P" for kind, _ in joint.type.motions) or body not in (joint.parent, joint.child):
                continue
            mine, theirs = ((joint.parent_frame, joint.child_frame) if body == joint.parent
                            else (joint.child_frame, joint.parent_frame))
            other = joint.child if body == joint.parent else joint.parent
            if other == 0 or other in found:
                continue
            r_mine, _ = symbolic_frame(mechanism, mine)
            r_theirs, _ = symbolic_frame(mechanism, theirs)
            # other's axes -> joint frame (R_theirs^T) -> body's axes (R_mine) -> label's (found)
            step = [[sum(r_mine[i][k] * r_theirs[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
            m = found[body]
            found[other] = [[sympy.cancel(sum(m[i][k] * step[k][j] for k in range(3))) for j in range(3)]
                            for i in range(3)]
            frontier.append(other)
    return list(found.items())


def dedupe(items: list, subs: dict, dps: int, directions: bool = False) -> list:
    """(name, exact vector, numeric vector) for the items whose vector (or, for
    ``directions``, its line) at the geometry ``subs`` differs from every earlier one.

    Numbers at ``dps`` digits (call inside ``mpmath.workdps(dps)``). Duplicates are
    decided at that precision (1e-20); a float64 copy of the keys only
    spares that comparison for the pairs it shows far apart (by more than 1e-8, a thousand
    million times float64's error), so the decisions are the working-precision ones."""
    out: list[tuple[str, Any, list[mpmath.mpf]]] = []
    seen: list[list[mpmath.mpf]] = []
    seen_float: list[np.ndarray] = []
    tiny = mpmath.mpf(10) ** -20
    for name, vec in items:
        num = [to_number(c, subs, dps) for c in vec]
        key = num
        if directions:
            norm = mpmath.sqrt(sum(x * x for x in num))
            if norm == 0:
                continue
            key = [x / norm for x in num]
        key_float = np.array([float(x) for x in key])
        if seen_float:
            others = np.array(seen_float)
            if directions:
                near = np.abs(np.abs(others @ key_float) - 1) <= 1e-8
            else:
                near = np.max(np.abs(others - key_float), axis=1) <= 1e-8 * (1 + np.max(np.abs(key_float)))
            candidates = [seen[k] for k in np.flatnonzero(near)]
        else:
            candidates = []
        dup = False
        for other in candidates:
            if directions:
                dot = mpmath.fsum(a * b for a, b in zip(key, other))
                dup = abs(abs(dot) - 1) < tiny
            else:
                dup = max(abs(a - b) for a, b in zip(key, other)) < tiny
            if dup:
                break
        if not dup:
            seen.append(key)
            seen_float.append(key_float)
            out.append((name, vec, num))
    return out


def _quadrupole_family(span: Sequence[Sequence[Any]], span_num: Sequence[Sequence[mpmath.mpf]]) -> list[tuple[list, int]]:
    """Exact symmetric tensors Q (six entries) with s_a^T Q s_b = 0 for a basis s of the span,
    and for each the entry it is designated to eliminate (a free variable)."""
    def coeffs(a: Sequence[Any], b: Sequence[Any]) -> list[Any]:
        row = []
        for i, j in TENSOR_INDEX:
            row.append(a[i] * b[i] if i == j else a[i] * b[j] + a[j] * b[i])
        return row

    pairs = [(a, b) for a in range(len(span)) for b in range(a, len(span))]
    rows = [coeffs(span[a], span[b]) for a, b in pairs]
    rows_num = [coeffs(span_num[a], span_num[b]) for a, b in pairs]
    # dependent variables: the entries the span sees most (largest coefficients) go first
    weight = [max((abs(r[c]) for r in rows_num), default=0) for c in range(6)]
    order = sorted(range(6), key=lambda c: (-weight[c], c))
    if not rows:
        return [([int(i == c) for i in range(6)], c) for c in range(6)]
    m = sympy.Matrix([[r[c] for c in order] for r in rows])
    rref, pivots = m.rref(simplify=sympy.cancel)
    free = [k for k in range(6) if k not in pivots]
    out = []
    for f in free:
        q = [sympy.Integer(0)] * 6
        q[order[f]] = sympy.Integer(1)
        for r, p in enumerate(pivots):
            q[order[p]] = sympy.cancel(-rref[r, f])
        out.append((q, order[f]))
    return out


def lagrangian_forms(states: list, dps: int) -> list:
    """Per state: (T form, V form, {body: rotation rows}, {body: omega}) as mpmath numbers
    to ``dps`` digits (call inside ``mpmath.workdps(dps)``)."""
    out = []
    for sample in states:
        t_form, v_form = sample.energies()
        rots = {b: [[to_mpf(x, dps) for x in row] for row in st.rot] for b, st in sample.states.items() if b}
        omegas = {b: [to_mpf(x, dps) for x in st.w] for b, st in sample.states.items() if b}
        out.append(([to_mpf(x, dps) for x in t_form], [to_mpf(x, dps) for x in v_form], rots, omegas))
    return out


def lagrangian_rows(mechanism: Mechanism, labels: list[int], forms: list, dps: int) -> Rows:
    """Rows whose common null space holds the parameter directions of ``labels`` without
    effect: ``T(s)`` and ``V(s) - V(s_0)`` restricted to those bodies, normalized (the
    forms' ``dps`` digits)."""
    cols: list[int] = []
    for label in labels:
        i = mechanism.body_labels.index(label)
        cols.extend(range(10 * i, 10 * i + 10))
    t_rows = [[t[c] for c in cols] for t, _, _, _ in forms]
    v_rows = [[v[c] for c in cols] for _, v, _, _ in forms]
    rows = t_rows + [[a - b for a, b in zip(r, v_rows[0])] for r in v_rows[1:]]
    return _normalized_rows(rows, dps)


def analyse_body(mechanism: Mechanism, label: int, forms: list, dps: int) -> BodyMotion:
    """Classify one body's motion from sampled states (``forms`` at ``dps`` digits; call
    inside ``mpmath.workdps(dps)``) and build its exact generators."""
    rows = lagrangian_rows(mechanism, [label], forms, dps)
    omegas = []
    for _, _, rots, ws in forms:
        rot, w = rots[label], ws[label]
        omegas.append([mpmath.fsum(rot[k][i] * w[k] for k in range(3)) for i in range(3)])
    null_dim = 10 - numerical_rank(rows.exact(), NULL_TOL) if rows else 10
    omega_rows = _normalized_rows(omegas, dps)
    omega_rank = numerical_rank(omega_rows.exact(), NULL_TOL) if omega_rows else 0

    subs = mechanism.geometry_subs
    point_candidates, direction_candidates = body_candidates(mechanism, label)
    points = dedupe(list(point_candidates), subs, dps)
    dirs = dedupe(list(direction_candidates), subs, dps, directions=True)
    motion = BodyMotion(label, omega_rank, null_dim)
    names = mechanism.body_parameters(label)

    def norm(v: Sequence[mpmath.mpf]) -> list[mpmath.mpf]:
        n = mpmath.sqrt(sum(x * x for x in v))
        return [x / n for x in v]

    # directions of the angular velocity's span (exact, from the candidates)
    span, span_num = [], []
    if 0 < omega_rank < 3:
        complement = null_basis(omega_rows, 3)
        # u is in the span if it is orthogonal to the numeric complement of the span
        inside = [(vec, num) for _, vec, num in dirs
                  if all(abs(mpmath.fsum(a * b for a, b in zip(norm(num), c))) < NULL_TOL for c in complement)]
        for k in independent([num for _, num in inside])[:omega_rank]:
            span.append(inside[k][0])
            span_num.append(inside[k][1])
        if omega_rank == 1 and span:
            motion.axis = span[0]

    candidates = []
    if omega_rank == 0 or len(span) == omega_rank < 3:
        cond = 6 if omega_rank == 0 else 5
        for q, pivot in _quadrupole_family(span, span_num):
            tensor = [[0] * 3 for _ in range(3)]
            for k, (i, j) in enumerate(TENSOR_INDEX):
                tensor[i][j] = tensor[j][i] = q[k]
            candidates.append(("quadrupole", cond, quadrupole_params(tensor), [names[4 + pivot]],
                               {"tensor": q}, f"quadrupole {INERTIA_KINDS[pivot]}"))
    rest = []
    for pname, b, bnum in points:
        vec = monopole_params(bnum)
        if residual(rows, vec) < NULL_TOL:
            rest.append((pname, b, bnum))
    motion.rest_points = [b for _, b, _ in rest]
    for pname, b, bnum in points:
        for dname, d, dnum in dirs:
            n = dipole_params(bnum, norm(dnum))
            if residual(rows, n) >= NULL_TOL:
                continue
            dn = norm(dnum)
            along_axis = omega_rank == 1 and span_num and abs(abs(mpmath.fsum(
                a * c for a, c in zip(dn, norm(span_num[0])))) - 1) < NULL_TOL
            at_rest = any(b is rb for _, rb, _ in rest)
            cond = 2 if along_axis else (4 if omega_rank == 0 or at_rest else 3)
            best = max(range(3), key=lambda k: (abs(dnum[k]), -k))
            candidates.append(("dipole", cond, dipole_params(b, d), [names[1 + best]],
                               {"point": b, "direction": d, "where": pname, "along": dname},
                               f"dipole along {dname} at {pname}"))
    for pname, b, bnum in rest:
        pref = [names[0]] if pname == "origin" else []
        candidates.append(("monopole", 1, monopole_params(b), pref, {"point": b, "where": pname},
                           f"monopole at {pname}"))
    valid = []
    for multipole, cond, values, pref, side, text in candidates:
        vector = as_vector(names, values)
        num = [to_number(vector.get(n, 0), subs, dps) for n in names]
        if residual(rows, num) >= NULL_TOL * 100:
            continue           # a quadrupole of a wrongly identified span: never trust it
        valid.append((num, vector, multipole, cond, pref, side, text))
    for k in independent([v[0] for v in valid]):
        _, vector, multipole, cond, pref, side, text = valid[k]
        motion.generators.append(Generator(
            vector=vector, kind="condition", multipole=multipole, condition=cond,
            bodies=(label,), sides={label: side}, label=text, preference=list(pref)))
    return motion


def analyse_bodies(mechanism: Mechanism, states: list | None = None, count: int = 12, digits: int = 30,
                   seed: int = 1) -> tuple[list[BodyMotion], list]:
    """(BodyMotion for every moving body, the sampled Lagrangian forms for reuse), in
    mpmath numbers at ``digits - 2`` digits (a local ``mpmath.workdps``: the caller's
    precision is neither read nor changed)."""
    if states is None:
        states, _ = random_states(mechanism, count=count, digits=digits, seed=seed)
    dps = digits - 2
    with mpmath.workdps(dps):
        forms = lagrangian_forms(states, dps)
        return [analyse_body(mechanism, label, forms, dps) for label in mechanism.body_labels], forms
