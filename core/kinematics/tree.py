"""Tree kinematics and loop-closure equations, in any arithmetic backend.

One forward pass over the spanning tree gives, for every body, its pose, its Jacobians
(angular velocity and origin velocity per tree coordinate, world axes) and, when the
velocities are given, the acceleration terms that do not depend on the accelerations
("bias": angular and linear acceleration with qdd = 0). Then for any qdd:
``omega_dot = Jw qdd + bias_w`` and ``a = Jv qdd + bias_a``.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

from baseparams.numeric import vec
from baseparams.model.joints import AXES, elementary_rotation

if TYPE_CHECKING:
    from baseparams.model.mechanism import Joint, Mechanism
    from baseparams.numeric.backends import Backend

Vector = list[Any]                   # three numbers of the backend
Rotation = list[list[Any]]           # three rows
Columns = dict[int, Vector]          # coordinate index -> a column (world)
Frame = tuple[Rotation, Vector]


@dataclass
class BodyState:
    rot: Rotation      # body axes in world (rows); columns are the body's x, y, z
    pos: Vector        # origin, world
    jw: Columns        # coordinate index -> angular velocity column (world)
    jv: Columns        # coordinate index -> origin velocity column (world)
    w: Vector | None = None    # angular velocity (world), when qd is given
    v: Vector | None = None    # origin velocity (world)
    bw: Vector | None = None   # bias angular acceleration (qdd = 0)
    ba: Vector | None = None   # bias origin acceleration (qdd = 0)

    def moving(self) -> tuple[Vector, Vector, Vector, Vector]:
        """(w, v, bw, ba) of a state of ``forward(q, qd)`` (velocities given)."""
        w, v, bw, ba = self.w, self.v, self.bw, self.ba
        if w is None or v is None or bw is None or ba is None:
            raise ValueError("body velocities are needed: call forward(q, qd) with qd")
        return w, v, bw, ba


# mechanism -> {(backend type, digits, symbolic geometry): (edges, loops, couplings, gravity, zero, one)}
_PREPARED: weakref.WeakKeyDictionary[Mechanism, dict[tuple[Any, ...], tuple[Any, ...]]] = (
    weakref.WeakKeyDictionary())


class TreeKinematics:
    """Precomputed numeric frames of a mechanism in one backend; evaluates states.

    The frames are computed once per mechanism, backend kind and precision and then shared
    (read only): evaluating them goes through sympy (most of the SLA's warm float64 W
    before this cache: docs/performance.md). A backend's numbers depend on nothing but its kind and digits."""

    edges: list[tuple[int, int, Frame, list[tuple[str, int, int, int]], Frame]]
    loops: list[tuple[Joint, Frame, Frame]]
    couplings: list[tuple[int, int, Any, Any]]   # closed loops only: (follower, leader, ratio, offset)
    gravity: list[Any]
    zero: Any
    one: Any

    def __init__(self, mechanism: Mechanism, backend: Backend, symbolic_geometry: bool = False) -> None:
        self.mechanism = mechanism
        self.backend = backend
        self.n = len(mechanism.coordinates)
        index = {name: i for i, name in enumerate(mechanism.coordinates)}
        self.index = index
        key = (type(backend), getattr(backend, "digits", None), bool(symbolic_geometry))
        cached = _PREPARED.setdefault(mechanism, {})
        if key not in cached:
            with backend.activate():
                self._prepare(mechanism, backend, symbolic_geometry, index)
            cached[key] = (self.edges, self.loops, self.couplings, self.gravity, self.zero, self.one)
        self.edges, self.loops, self.couplings, self.gravity, self.zero, self.one = cached[key]

    def _prepare(self, mechanism: Mechanism, backend: Backend, symbolic_geometry: bool,
                 index: Mapping[str, int]) -> None:
        frame = lambda f: mechanism.numeric_frame(f, backend, symbolic_geometry)  # noqa: E731
        self.edges = []
        for edge in mechanism.tree:
            joint = edge.joint
            fp, fc = frame(joint.parent_frame), frame(joint.child_frame)
            motions = [(kind, AXES[axis], index[name], 1)
                       for (kind, axis), name in zip(joint.type.motions, joint.coordinates)]
            if edge.reversed:
                known_frame, new_frame = fc, fp
                motions = [(kind, axis, c, -1) for kind, axis, c, _ in reversed(motions)]
            else:
                known_frame, new_frame = fp, fc
            self.edges.append((edge.known, edge.new, known_frame, motions, new_frame))
        self.loops = [(j, frame(j.parent_frame), frame(j.child_frame)) for j in mechanism.loops]
        # on a closed loop a coupling is one more closure equation, solved with the loops'
        # (a follower may follow a dependent coordinate, a leader may close a loop); an open
        # chain's followers are filled in directly by the evaluator instead
        self.couplings = [(index[c.coordinate], index[c.leader], backend.rational(c.ratio),
                           backend.rational(c.offset)) for c in mechanism.couplings] if mechanism.loops else []
        self.gravity = mechanism.numeric_gravity(backend, symbolic_geometry)
        self.zero = backend.rational(Fraction(0))
        self.one = backend.rational(Fraction(1))

    # ------------------------------------------------------------------
    def forward(self, q: Sequence[Any], qd: Sequence[Any] | None = None) -> dict[int, BodyState]:
        """Body states for tree coordinates ``q`` (and velocities ``qd``, optional)."""
        z, one = self.zero, self.one
        ground = BodyState([[one, z, z], [z, one, z], [z, z, one]], [z, z, z], {}, {})
        if qd is not None:
            ground.w, ground.v, ground.bw, ground.ba = [z] * 3, [z] * 3, [z] * 3, [z] * 3
        states = {0: ground}
        for known, new, (fr, fp), motions, (nr, np_) in self.edges:
            s = states[known]
            st = BodyState(vec.matmul(s.rot, fr), s.pos, dict(s.jw), dict(s.jv), s.w, s.v, s.bw, s.ba)
            _offset(st, vec.matvec(s.rot, fp))
            for kind, axis, c, sign in motions:
                u = vec.column(st.rot, axis)
                su = u if sign > 0 else vec.scale(u, -1)
                value = q[c] if sign > 0 else -q[c]
                rate = None if qd is None else (qd[c] if sign > 0 else -qd[c])
                if kind == "R":
                    cos, sin = self.backend.cos_sin(value)
                    st.rot = vec.matmul(st.rot, elementary_rotation(axis, cos, sin, one, z))
                    moved, still = st.jw, st.jv
                else:
                    _offset(st, vec.scale(u, value))
                    moved, still = st.jv, st.jw
                moved[c] = vec.add(moved[c], su) if c in moved else su
                still.setdefault(c, [z, z, z])
                if rate is None:
                    continue
                w, v, bw, ba = st.moving()
                if kind == "R":
                    st.bw = vec.add(bw, vec.scale(vec.cross(w, u), rate))
                    st.w = vec.add(w, vec.scale(u, rate))
                else:
                    st.ba = vec.add(ba, vec.scale(vec.cross(w, u), 2 * rate))
                    st.v = vec.add(v, vec.scale(u, rate))
            st.rot = vec.matmul_t(st.rot, nr)
            _offset(st, vec.scale(vec.matvec(st.rot, np_), -1))
            states[new] = st
        return states

    # ------------------------------------------------------------------
    def closure(self, states: Mapping[int, BodyState], want_bias: bool = False,
                q: Sequence[Any] | None = None) -> tuple[list[Any], list[list[Any]], list[Any]]:
        """Loop-closure equations: values, Jacobian rows (length n) and, optionally, bias terms.

        The bias gamma is the second time derivative of the equations with qdd = 0, so that
        ``Phi_q qdd + gamma = 0`` on the constraint manifold. Needs ``forward(q, qd)``.
        After the loops' equations, one per coupling (closed loops only):
        ``q_follower - ratio q_leader - offset = 0``, linear, so its bias is zero; its value
        needs the coordinates ``q`` (required when the mechanism has couplings).
        """
        values: list[Any] = []
        rows: list[list[Any]] = []
        biases: list[Any] = []
        n, z = self.n, self.zero
        for joint, (ra, pa), (rb, pb) in self.loops:
            sa, sb = states[joint.parent], states[joint.child]
            axes_a = vec.matmul(sa.rot, ra)
            axes_b = vec.matmul(sb.rot, rb)
            arm_a = vec.matvec(sa.rot, pa)
            arm_b = vec.matvec(sb.rot, pb)
            for eq in joint.type.closure:
                u = vec.column(axes_a, AXES[eq[1]])
                u_cols = {c: vec.cross(w, u) for c, w in sa.jw.items()}
                if eq[0] == "gap":
                    other = vec.sub(vec.add(sb.pos, arm_b), vec.add(sa.pos, arm_a))
                    o_cols = _point_columns(sb, arm_b)
                    for c, col in _point_columns(sa, arm_a).items():
                        o_cols[c] = vec.sub(o_cols.get(c, [z, z, z]), col)
                else:
                    other = vec.column(axes_b, AXES[eq[2]])
                    o_cols = {c: vec.cross(w, other) for c, w in sb.jw.items()}
                values.append(vec.dot(u, other))
                row = [z] * n
                for c, col in u_cols.items():
                    row[c] = row[c] + vec.dot(col, other)
                for c, col in o_cols.items():
                    row[c] = row[c] + vec.dot(u, col)
                rows.append(row)
                if want_bias:
                    wa, _, bwa, _ = sa.moving()
                    u_dot = vec.cross(wa, u)
                    u_dd = vec.add(vec.cross(bwa, u), vec.cross(wa, u_dot))
                    if eq[0] == "gap":
                        o_dot = vec.sub(_point_velocity(sb, arm_b), _point_velocity(sa, arm_a))
                        o_dd = vec.sub(_point_bias(sb, arm_b), _point_bias(sa, arm_a))
                    else:
                        wb, _, bwb, _ = sb.moving()
                        o_dot = vec.cross(wb, other)
                        o_dd = vec.add(vec.cross(bwb, other), vec.cross(wb, o_dot))
                    biases.append(vec.dot(u_dd, other) + 2 * vec.dot(u_dot, o_dot) + vec.dot(u, o_dd))
        if self.couplings and q is None:
            raise ValueError("the closure of a mechanism with couplings needs the coordinates q")
        for follower, leader, ratio, offset in self.couplings:
            assert q is not None
            values.append(q[follower] - ratio * q[leader] - offset)
            row = [z] * n
            row[follower] = self.one
            row[leader] = -ratio
            rows.append(row)
            if want_bias:
                biases.append(z)
        return values, rows, biases

    def accelerations(self, state: BodyState, qdd: Sequence[Any]) -> tuple[Vector, Vector]:
        """(omega_dot, a) of a body (world) from its Jacobians, bias terms and ``qdd``."""
        _, _, bw, ba = state.moving()
        return (vec.add(bw, _combine(state.jw, qdd, self.zero)),
                vec.add(ba, _combine(state.jv, qdd, self.zero)))


def _offset(st: BodyState, r: Vector) -> None:
    """Move the state's reference point by the world vector ``r`` fixed in the moving frame."""
    st.pos = vec.add(st.pos, r)
    for c, w in st.jw.items():
        st.jv[c] = vec.add(st.jv[c], vec.cross(w, r))
    if st.w is not None:
        w, v, bw, ba = st.moving()
        wr = vec.cross(w, r)
        st.ba = vec.add(ba, vec.add(vec.cross(bw, r), vec.cross(w, wr)))
        st.v = vec.add(v, wr)



def _point_columns(state: BodyState, arm: Vector) -> Columns:
    return {c: vec.add(state.jv[c], vec.cross(w, arm)) for c, w in state.jw.items()}


def _point_velocity(state: BodyState, arm: Vector) -> Vector:
    w, v, _, _ = state.moving()
    return vec.add(v, vec.cross(w, arm))


def _point_bias(state: BodyState, arm: Vector) -> Vector:
    w, _, bw, ba = state.moving()
    return vec.add(ba, vec.add(vec.cross(bw, arm), vec.cross(w, vec.cross(w, arm))))


def _combine(columns: Columns, rates: Sequence[Any], zero: Any) -> Vector:
    total = [zero, zero, zero]
    for c, col in columns.items():
        total = vec.add(total, vec.scale(col, rates[c]))
    return total
