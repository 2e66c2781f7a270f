"""The dynamic regressor K(q, qd, qdd): tau = K phi, ten inertial parameters per body.

For one body with parameters (m, c = (mx, my, mz), I about the origin), in body axes, the
Newton-Euler wrench about the origin is linear in them:

    f = m a + omega_dot x c + omega x (omega x c)          (a: origin acceleration - g)
    n = I omega_dot + omega x (I omega) + c x a

and its contribution to the generalized forces of the tree coordinates is
``tau_k = Jv_k . f + Jw_k . n``. The energies T and V are linear forms in phi too; they
are computed separately (not from K), so the energy balance is an independent check.
"""

from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import Any

import numpy as np

from baseparams.kinematics.tree import BodyState, Columns, TreeKinematics, Vector
from baseparams.numeric import vec
from baseparams.numeric.backends import Float64

Wrench = tuple[Vector, Vector]        # (force, moment), body axes

# d(I w)/d(I entry): which (row, col) pairs each of Ixx Ixy Ixz Iyy Iyz Izz fills.
_INERTIA_ENTRIES = (((0, 0),), ((0, 1), (1, 0)), ((0, 2), (2, 0)), ((1, 1),), ((1, 2), (2, 1)), ((2, 2),))


def _inertia_times(entry: int, w: Vector, zero: Any) -> Vector:
    out = [zero, zero, zero]
    for i, j in _INERTIA_ENTRIES[entry]:
        out[i] = out[i] + w[j]
    return out


def body_wrench_columns(w: Vector, dw: Vector, a: Vector, zero: Any) -> list[Wrench]:
    """The ten (f, n) pairs (body axes) for unit values of each parameter."""
    cols: list[Wrench] = [(a, [zero, zero, zero])]
    for k in range(3):
        e = [zero, zero, zero]
        e[k] = e[k] + 1
        f = vec.add(vec.cross(dw, e), vec.cross(w, vec.cross(w, e)))
        cols.append((f, vec.cross(e, a)))
    for entry in range(6):
        n = vec.add(_inertia_times(entry, dw, zero), vec.cross(w, _inertia_times(entry, w, zero)))
        cols.append(([zero, zero, zero], n))
    return cols


def tree_regressor(kin: TreeKinematics, states: Mapping[int, BodyState], qdd: Sequence[Any]) -> list[list[Any]]:
    """K for the tree coordinates: a list of n rows, each 10 * bodies entries."""
    if isinstance(kin.backend, Float64):
        full = tree_regressor_array(kin, states, qdd)
        return [[full[..., k, p] for p in range(full.shape[-1])] for k in range(kin.n)]
    return generic_tree_regressor(kin, states, qdd)


def generic_tree_regressor(kin: TreeKinematics, states: Mapping[int, BodyState],
                           qdd: Sequence[Any]) -> list[list[Any]]:
    """K's rows in any number type (the definition; float64 runs its generated form)."""
    zero = kin.zero
    rows: list[list[Any]] = [[] for _ in range(kin.n)]
    for body in kin.mechanism.body_labels:
        jw, jv, cols = _body_terms(kin, states[body], qdd)
        for k in range(kin.n):
            if k not in jw:
                rows[k].extend([zero] * 10)
                continue
            rows[k].extend(vec.dot(jv[k], f) + vec.dot(jw[k], n) for f, n in cols)
    return rows


def _body_terms(kin: TreeKinematics, s: BodyState, qdd: Sequence[Any]) -> tuple[Columns, Columns, list[Wrench]]:
    """Body-axes Jacobian columns and the ten wrench columns of one body."""
    dw, acc = kin.accelerations(s, qdd)
    acc = vec.sub(acc, kin.gravity)
    w, _, _, _ = s.moving()
    wb, dwb, ab = vec.tmatvec(s.rot, w), vec.tmatvec(s.rot, dw), vec.tmatvec(s.rot, acc)
    cols = body_wrench_columns(wb, dwb, ab, kin.zero)
    jw = {c: vec.tmatvec(s.rot, col) for c, col in s.jw.items()}
    jv = {c: vec.tmatvec(s.rot, col) for c, col in s.jv.items()}
    return jw, jv, cols


def tree_regressor_array(kin: TreeKinematics, states: Mapping[int, BodyState], qdd: Sequence[Any]) -> np.ndarray:
    """float64 only: K_tree as an array (..., n, 10 * bodies). Same as the generic path, with the Jacobian-transpose products as one einsum per body:
    over a batch of samples this replaces thousands of small array operations. Each body's
    block is written into one array (no per-body array and concatenation: 37 MB copied
    twice for TIAGo's 200 samples)."""
    size = np.broadcast_shapes(*(np.shape(v) for v in qdd))
    out = np.zeros(size + (kin.n, 10 * len(kin.mechanism.body_labels)))
    for b, body in enumerate(kin.mechanism.body_labels):
        jw, jv, cols = _body_terms(kin, states[body], qdd)
        coords = sorted(jw)
        if not coords:              # a body welded to the ground (a URDF base link): no columns
            continue
        wrench = _stack([[f[0], f[1], f[2], n[0], n[1], n[2]] for f, n in cols], size)   # (..., 10, 6)
        jac = _stack([jv[c] + jw[c] for c in coords], size)                              # (..., k, 6)
        out[..., coords, 10 * b:10 * b + 10] = np.einsum("...kr,...pr->...kp", jac, wrench)
    return out


def _stack(rows: Sequence[Sequence[Any]], size: tuple[int, ...]) -> np.ndarray:
    """``rows`` (lists of per-sample arrays or scalars) as one array (..., rows, columns):
    each value written into its place (broadcast), the same numbers as stacking them."""
    out = np.empty(size + (len(rows), len(rows[0]) if rows else 0))
    for i, row in enumerate(rows):
        for j, v in enumerate(row):
            out[..., i, j] = v
    return out


def energy_forms(kin: TreeKinematics, states: Mapping[int, BodyState]) -> tuple[list[Any], list[Any]]:
    """(T, V): kinetic and potential energy as lists of coefficients of phi.

    T = 1/2 m v.v + c.(v x w) + 1/2 w.I w, V = -g.(m p + R c), velocities of the origin.
    """
    zero = kin.zero
    half = kin.backend.rational(Fraction(1)) / kin.backend.rational(Fraction(2))
    t_form: list[Any] = []
    v_form: list[Any] = []
    for body in kin.mechanism.body_labels:
        s = states[body]
        w, v, _, _ = s.moving()
        wb, vb = vec.tmatvec(s.rot, w), vec.tmatvec(s.rot, v)
        gb = vec.tmatvec(s.rot, kin.gravity)
        vxw = vec.cross(vb, wb)
        t_form.extend([half * vec.dot(vb, vb), vxw[0], vxw[1], vxw[2],
                       half * wb[0] * wb[0], wb[0] * wb[1], wb[0] * wb[2],
                       half * wb[1] * wb[1], wb[1] * wb[2], half * wb[2] * wb[2]])
        v_form.extend([-vec.dot(kin.gravity, s.pos), -gb[0], -gb[1], -gb[2]] + [zero] * 6)
    return t_form, v_form
