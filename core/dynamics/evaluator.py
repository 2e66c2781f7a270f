"""States on the constraint manifold and the regressor in the independent coordinates.

For a closed-loop mechanism the tree coordinates q split into the chosen independent
ones z and dependent ones d. Positions: Newton-Raphson on the loop-closure equations, in
the backend's own arithmetic (float64 first, then refined at D digits until the residual
is below 10^-(D-5)). Velocities and accelerations: solved from the differentiated
equations, ``qd = R zd`` and ``qdd = R zdd + s``, never by finite differences. The
regressor in the independent coordinates is ``K = R^T K_tree`` (the seed paper's
projection onto an orthogonal complement of the constraint Jacobian).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from baseparams.numeric.backends import Arb, Float64, TanHalf, in_backend_precision
from baseparams.errors import KinematicsError
from baseparams.kinematics.tree import TreeKinematics
from baseparams.kinematics.krawczyk import enclose
from baseparams.dynamics.regressor import energy_forms, tree_regressor_array
from baseparams.dynamics import codegen
from baseparams.dynamics.closure import ClosureStructure, closure_structure, independent_rows  # noqa: F401

if TYPE_CHECKING:
    from baseparams.kinematics.tree import BodyState
    from baseparams.model.mechanism import Mechanism
    from baseparams.numeric.backends import Backend

Array = np.ndarray               # float64 (numpy's stubs type most results as floating[Any])
Rows = list[list[Any]]          # a matrix by rows, entries in the backend (or float64 arrays over samples)


@dataclass
class Sample:
    """One evaluated state (or a batch of them, for float64): everything the regressor needs.

    ``states`` (the body states of the generic kinematics) may be given as None: they are
    then computed when first read (the generated float64 regressor does not need them)."""
    q: Sequence[Any]
    qd: Sequence[Any]
    qdd: Sequence[Any]
    _states: dict[int, BodyState] | None
    projection: Rows     # R: n rows x f columns, qd = R zd
    kin: TreeKinematics

    @property
    def states(self) -> dict[int, BodyState]:
        if self._states is None:
            with self.kin.backend.activate():
                self._states = self.kin.forward(self.q, self.qd)
        return self._states

    @in_backend_precision
    def regressor(self) -> Rows:
        """K in the independent coordinates: f rows of 10 * bodies entries."""
        k_tree = codegen.regressor_rows(self.kin, self.q, self.qd, self.qdd, lambda: self.states)
        if not self.kin.mechanism.loops and not self.kin.mechanism.couplings:
            return k_tree
        return project(self.projection, k_tree, self.kin.zero, codegen.regressor_columns(self.kin))

    def regressor_array(self) -> Array:
        """float64 only: K as an array (samples, f, 10 * bodies), without per-entry Python work."""
        mech = self.kin.mechanism
        if codegen.worthwhile(mech, "regressor", self.q):
            k_tree = codegen.tree_regressor(mech, self.q, self.qd, self.qdd)
        else:
            k_tree = tree_regressor_array(self.kin, self.states, self.qdd)
        if not self.kin.mechanism.loops and not self.kin.mechanism.couplings:
            return k_tree
        shape = k_tree.shape[:-2]
        r = np.stack([np.stack([np.broadcast_to(v, shape) for v in row], axis=-1) for row in self.projection],
                     axis=-2)
        return np.einsum("...kf,...kp->...fp", r, k_tree)

    @in_backend_precision
    def energies(self) -> tuple[list[Any], list[Any]]:
        return energy_forms(self.kin, self.states)


def _one_state(values: Sequence[Any]) -> bool:
    """float64 values of one state (Python floats or numpy float64 scalars, a subclass),
    not arrays over samples."""
    return all(isinstance(v, float) for v in values)


def project(r: Rows, k_tree: Rows, zero: Any, columns: Sequence[Sequence[int]] | None = None) -> Rows:
    """R^T K_tree. ``columns``: per row of K_tree the columns that can be nonzero; the
    others, exact zeros, are skipped (the same sums: adding an exact zero changes nothing;
    on the SLA 159 of 770 entries are not zero)."""
    f = len(r[0])
    out: Rows = []
    if columns is not None:
        for j in range(f):
            row: list[Any] = [None] * len(k_tree[0])
            for k, rk in enumerate(r):
                coeff = rk[j]
                if isinstance(coeff, int) and coeff == 0:
                    continue
                kr = k_tree[k]
                for c in columns[k]:
                    term = coeff * kr[c]
                    row[c] = term if row[c] is None else row[c] + term
            out.append([zero if v is None else v for v in row])
        return out
    for j in range(f):
        sums: list[Any] | None = None
        for k, rk in enumerate(r):
            coeff = rk[j]
            if isinstance(coeff, int) and coeff == 0:
                continue
            if sums is None:
                sums = [coeff * v for v in k_tree[k]]
            else:
                sums = [a + coeff * v for a, v in zip(sums, k_tree[k])]
        out.append(sums if sums is not None else [zero] * len(k_tree[0]))
    return out


class Evaluator:
    """Evaluates a mechanism's states and regressor in one backend."""

    def __init__(self, mechanism: Mechanism, backend: Backend, symbolic_geometry: bool = False,
                 certify: bool = False) -> None:
        """``certify`` (arb only): replace Newton's dependent coordinates by balls proven to
        contain the exact loop-closure solution (see :mod:`baseparams.kinematics.krawczyk`)."""
        self.mechanism = mechanism
        self.backend = backend
        self.certify = certify and isinstance(backend, Arb)
        self.kin = TreeKinematics(mechanism, backend, symbolic_geometry)
        # arb: the closure terms by generated straight-line ball arithmetic (codegen.scalar_closure)
        self._generated_balls = SCALAR_CLOSURE and isinstance(backend, Arb) and not symbolic_geometry
        self.structure = closure_structure(mechanism)
        self.n = self.kin.n
        self._solved: tuple[Any, Array] | None = None   # (q, closure Jacobian at q) of the last batched assembly
        # (closure values, Jacobian rows) at the last Newton result
        self._newton_closure: tuple[list[Any], Rows] | None = None

    # ----- positions ------------------------------------------------------
    def tolerance(self) -> int:
        """Decimal exponent of the closure residual Newton must reach: 10^-(D-5) at D digits."""
        digits = getattr(self.backend, "digits", None)
        return -12 if digits is None else -(digits - 5)

    @in_backend_precision
    def assemble(self, z: Sequence[Any], guess: Sequence[Any] | None = None, where: str = "") -> list[Any]:
        """Tree coordinates with independent values ``z``; dependent ones by Newton-Raphson."""
        st = self.structure
        q = list(guess) if guess is not None else [self.kin.zero] * self.n
        for value, i in zip(z, st.independent):
            q[i] = value
        if not self.mechanism.loops:
            for i, leader, ratio, offset in self._couplings():
                q[i] = _follow(q[leader], ratio, offset, self.mechanism.coordinates[i])
            return q
        if self.backend.exact:
            raise KinematicsError("exact and symbolic arithmetic cannot solve loop closure; "
                                  "give all tree coordinates or use float64 / arb")
        if self._batched(z):
            solved = self._assemble_batch(z, guess)
            if solved is not None:
                return solved
        if guess is None:
            # continuation from the reference configuration (q = 0 closes the loops), in steps
            # of at most 0.25 in every independent coordinate, each stage started from the
            # last one moved along its tangent (Euler, as the batched path predicts): from
            # the last solution itself a parallelogram with a short coupler took a 2.6 rad
            # Newton step onto its crossed branch at 0.15 rad of crank
            reach = max(float(np.max(np.abs(self.backend.to_float(v)))) for v in z)
            steps = max(4, int(np.ceil(reach / 0.25)))
            q = [self.kin.zero] * self.n
            self._newton_closure = self.closure(q)            # the tangent at the reference
            dz = [v * self.backend.rational(Fraction(1, steps)) for v in z]
            for step in range(1, steps):
                lam = self.backend.rational(Fraction(step, steps))
                q = self._newton(self._predicted(q, dz), [lam * v for v in z], -6, where + "(continuation) ")
            q = self._predicted(q, dz)
        q = self._newton(q, z, self.tolerance(), where)
        return enclose(self, q, where, at=self._newton_closure) if self.certify else q

    def _predicted(self, q: list[Any], dz: Sequence[Any]) -> list[Any]:
        """``q`` (a continuation stage's solution) with the dependent coordinates moved by
        -Phi_d^-1 Phi_z dz, the tangent step for the independent ones' move ``dz``, using
        the closure Jacobian of Newton's last evaluation (at q); q unchanged when that
        Jacobian is singular (Newton then reports it)."""
        if self._newton_closure is None:
            return q
        st = self.structure
        _, rows = self._newton_closure
        jd = [[rows[i][j] for j in st.dependent] for i in st.rows]
        shift = [[_dot([rows[i][j] for j in st.independent], dz, self.kin.zero)] for i in st.rows]
        try:
            step = self.backend.solve(jd, shift)
        except KinematicsError:
            return q
        out = list(q)
        for (s,), j in zip(step, st.dependent):
            out[j] = self.backend.point(q[j] - s)
        return out

    def _newton(self, q: list[Any], z: Sequence[Any], tol: int, where: str) -> list[Any]:
        st = self.structure
        q = list(q)
        for value, i in zip(z, st.independent):
            q[i] = value
        residual = None
        # float64 takes one more (quadratically convergent) step once within tolerance, so that
        # positions are as exact as double precision allows, not merely below 1e-12
        polish = isinstance(self.backend, Float64) and tol <= -12
        for _ in range(60):
            values, rows = self.closure(q)
            res = [values[i] for i in st.rows]
            if all(self.backend.small(v, tol) for v in res):
                if not polish:
                    break
                polish = False
            residual = max(self.backend.magnitude(v) for v in res)
            jd = [[rows[i][j] for j in st.dependent] for i in st.rows]
            try:
                step = self.backend.solve(jd, [[v] for v in res])
            except KinematicsError as exc:
                raise KinematicsError(f"{where}singular configuration while closing the loops ({exc}); "
                                      f"{self.singular_joints(jd)}{self.describe(q)}") from None
            for (s,), j in zip(step, st.dependent):
                q[j] = self.backend.point(q[j] - s)
        else:
            raise KinematicsError(f"{where}the loops do not close (residual {residual:.3g} after 60 "
                                  f"Newton iterations): out of the reachable range? independent "
                                  f"{self.describe(q, self.structure.independent)}")
        # every equation, the redundant ones included, must now hold, to 1000 times the Newton
        # tolerance: the redundant ones were not solved for, they follow (``values``: the
        # loop's last evaluation, at this q)
        slack = tol + 3
        if not all(self.backend.small(v, slack) for v in values):
            worst = max(self.backend.magnitude(v) for v in values)
            raise KinematicsError(f"{where}a redundant closure equation is violated (residual "
                                  f"{worst:.3g}): the geometry is inconsistent; {self.describe(q)}")
        self._newton_closure = (values, rows)        # at the q returned: Krawczyk's test starts there
        return q

    # ----- float64 batches: continuation on arrays ---------------------------------------
    def _batched(self, values: Sequence[Any]) -> bool:
        """A float64 batch that runs the generated closure code (see :meth:`_closure`)."""
        return (BATCHED_NEWTON and isinstance(self.backend, Float64) and bool(self.mechanism.loops)
                and codegen.worthwhile(self.mechanism, "closure", values))

    def _assemble_batch(self, z: Sequence[Any], guess: Sequence[Any] | None) -> list[Any] | None:
        """:meth:`assemble` for a float64 batch, on (coordinates, samples) arrays; None when
        anything is unusual, and the general path then runs (and reports) as before.

        The same continuation stages lam = k/steps, the same tolerances (1e-6 on the way,
        then 1e-12 and one more polishing step per sample) and the same condition bound on
        every Jacobian inverted; what differs is where each stage starts: extrapolated along
        the path from the solved stages with its tangent dq_d/dlam = -Phi_d^-1 Phi_z z
        (:func:`_predict`: Euler from q = 0, then cubic Hermite), so a stage needs two or
        three closure evaluations instead of five to seven, and Newton steps only the
        samples not yet converged. The tangent reuses the inverse the condition check needs
        anyway (an inverse is the step, no separate solve). Both paths follow the same
        homotopy to the same root at every stage, hence the same branch
        (tests/test_closure_speed_paths.py compares positions and W with the general path)."""
        st = self.structure
        try:
            shape = np.broadcast_shapes(*(np.shape(v) for v in list(z) + list(guess or [])))
        except ValueError:
            return None
        if len(shape) != 1:
            # one state at a time (the excitation check's random draws) keeps the general
            # path; its stages are tangent-predicted too since issue 49 (before, plain Newton
            # stages could land on another assembly mode than the followed path)
            return None
        dep, ind, rows = list(st.dependent), list(st.independent), list(st.rows)
        zs = np.array([np.broadcast_to(np.asarray(v, dtype=float), shape) for v in z])    # (f, samples)
        if guess is None:
            q = np.zeros((self.n,) + shape)
            reach = float(np.max(np.abs(zs))) if zs.size else 0.0
            if not np.isfinite(reach):
                return None
            steps = max(4, int(np.ceil(reach / 0.25)))
            stages = [(self.backend.rational(Fraction(k, steps)), -6) for k in range(1, steps)]
        else:
            q = np.array([np.broadcast_to(np.asarray(v, dtype=float), shape) for v in guess])
            stages = []
        stages.append((1.0, self.tolerance()))
        inverse = jac = phi = None
        path = []                  # (lam, dependent coordinates, tangent) at the solved stages
        lam_solved = 0.0
        for lam, tol in stages:
            if guess is None:
                if inverse is None:                 # the reference configuration's Jacobian
                    phi, jac = codegen.closure_arrays(self.mechanism, q)
                    inverse = self._checked_inverse(jac, rows, dep)
                    if inverse is None:
                        return None
                assert jac is not None
                tangent = -np.einsum("sij,sjk,ks->is", inverse, jac[:, rows][:, :, ind], zs, optimize=True)
                path.append((lam_solved, q[dep].copy(), tangent))
                q[dep] = _predict(path[-2:], lam)
            q[ind] = lam * zs
            lam_solved = lam
            newton = self._newton_batch(q, tol, phi, jac, inverse)
            if newton is None:
                return None
            phi, jac, inverse = newton
        assert phi is not None and jac is not None          # stages are never empty
        if not np.all(np.abs(phi) <= 10.0 ** (stages[-1][1] + 3)):     # the redundant equations too
            return None
        solved = [zs[ind.index(i)] if i in ind else q[i] for i in range(self.n)]
        self._solved = (solved, jac)
        return solved

    def _newton_batch(self, q: Array, tol: float, phi: Array | None, jac: Array | None,
                      inverse: Array | None) -> tuple[Array, Array, Array | None] | None:
        """Newton on the (n, samples) array ``q`` (in place) until every sample's closure
        residual is within 10^tol (below 1e-12: and then one more step for that sample, as
        :meth:`_newton` polishes), stepping only the samples not yet there. Returns the
        closure values, Jacobians and Phi_d inverses per sample (the last ones computed),
        or None (not converged within NEWTON_BUDGET steps, or a Jacobian failing the
        condition bound)."""
        st = self.structure
        dep, rows = list(st.dependent), list(st.rows)
        count = q.shape[1]
        limit = 10.0 ** tol
        polish = tol <= -12
        polished = np.zeros(count, dtype=bool)
        active = np.arange(count)
        for _ in range(NEWTON_BUDGET + 1):
            phi_a, jac_a = codegen.closure_arrays(self.mechanism, q[:, active])
            if phi is None or jac is None:           # both or neither
                phi, jac = phi_a, jac_a
            else:
                phi[active], jac[active] = phi_a, jac_a
            res = phi_a[:, rows]
            within = np.all(np.abs(res) <= limit, axis=1)
            done = within & polished[active] if polish else within
            polished[active] |= within
            stepping = ~done
            if not stepping.any():
                return phi, jac, inverse
            active, res = active[stepping], res[stepping]
            inv_a = self._checked_inverse(jac_a[stepping], rows, dep)
            if inv_a is None:
                return None
            if inverse is None:
                inverse = np.empty((count, len(dep), len(dep)))
            inverse[active] = inv_a
            q[np.ix_(dep, active)] -= np.einsum("sij,sj->is", inv_a, res)
        return None

    @staticmethod
    def _checked_inverse(jac: Array, rows: Sequence[int], dep: Sequence[int]) -> Array | None:
        """Phi_d^-1 per sample if every Phi_d passes Float64.solve's condition bound
        (cond_2 <= n cond_1 <= 1e13), else None."""
        jd = jac[:, rows][:, :, dep]
        try:
            with np.errstate(all="ignore"):
                inverse = np.linalg.inv(jd)
                bound = (len(dep) * np.abs(jd).sum(axis=-2).max(axis=-1)
                         * np.abs(inverse).sum(axis=-2).max(axis=-1))
        except np.linalg.LinAlgError:
            return None
        return inverse if np.all(bound <= 1e13) else None

    def closure(self, q: Sequence[Any]) -> tuple[list[Any], Rows]:
        """Closure values and Jacobian rows at q (float64: generated code once it pays, over
        arrays for a batch, on Python floats for one state; arb: generated ball arithmetic)."""
        if self._generated_balls:
            return codegen.scalar_closure(self.mechanism, self.backend, q)
        if isinstance(self.backend, Float64) and codegen.worthwhile(self.mechanism, "closure", q):
            if SCALAR_CLOSURE and _one_state(q):
                return codegen.scalar_closure(self.mechanism, self.backend, [float(v) for v in q])
            return codegen.closure(self.mechanism, q)
        values, rows, _ = self.kin.closure(self.kin.forward(q), q=q)
        return values, rows

    def singular_joints(self, jd: Rows) -> str:
        """Names the joints whose dependent coordinates move along the closure Jacobian's
        weakest direction (the motion the loops no longer fix), e.g. "joints at the
        singularity: J6_7 (damper_s); ". In a batch, at the worst state."""
        try:
            a = np.array([[np.atleast_1d(self.backend.to_float(v)) for v in row] for row in jd], dtype=float)
        except (TypeError, ValueError):
            return ""
        a = np.moveaxis(a, -1, 0)                                  # (states, rows, dependent)
        if not a.size or not np.all(np.isfinite(a)):
            return ""
        _, sv, vt = np.linalg.svd(a)
        worst = int(np.argmin(sv[:, -1]))
        v = np.abs(vt[worst, -1])
        names = [self.mechanism.coordinates[self.structure.dependent[k]]
                 for k in np.nonzero(v >= 0.3 * v.max())[0]]
        joints = []
        for name in names:
            joint = self.mechanism.joint_of_coordinate(name).name
            if joint not in joints:
                joints.append(joint)
        labels = ", ".join(f"{j} ({', '.join(c for c in names if self.mechanism.joint_of_coordinate(c).name == j)})"
                           for j in joints)
        return f"joints at the singularity: {labels}; "

    def describe(self, q: Sequence[Any], only: Sequence[int] | None = None) -> str:
        parts = []
        for i, (name, v) in enumerate(zip(self.mechanism.coordinates, q)):
            if only is not None and i not in only:
                continue
            f = np.atleast_1d(self.backend.to_float(v))
            parts.append(f"{name}={f[0]:.6g}" if f.size == 1 else f"{name}=[{f.min():.4g}..{f.max():.4g}]")
        return "coordinates: " + ", ".join(parts)

    # ----- full state -----------------------------------------------------
    @in_backend_precision
    def sample(self, z: Sequence[Any], zd: Sequence[Any], zdd: Sequence[Any],
               guess: Sequence[Any] | None = None, where: str = "") -> Sample:
        """The state with independent positions, velocities and accelerations z, zd, zdd."""
        q = self.assemble(z, guess, where)
        if self.mechanism.loops:
            return self._closed_sample(q, zd, zdd, where)
        zero, one = self.kin.zero, self.kin.one
        st = self.structure
        qd, qdd = [zero] * self.n, [zero] * self.n
        r = [[zero] * len(st.independent) for _ in range(self.n)]    # a permutation (and couplings)
        for j, i in enumerate(st.independent):
            qd[i], qdd[i], r[i][j] = zd[j], zdd[j], one
        for i, leader, ratio, _ in self._couplings():
            qd[i], qdd[i] = ratio * qd[leader], ratio * qdd[leader]
            r[i] = [ratio * v for v in r[leader]]
        # the body states when first read (Sample.states), in every arithmetic: the generated
        # regressor (float64 batches, arb, rationals) does not read them; at every sample of a
        # long recording they are most of its memory, and in arb a quarter of W's time (issue 47)
        return Sample(q, qd, qdd, None, r, self.kin)

    def _couplings(self) -> list[tuple[int, int, Any, Any]]:
        """(coordinate index, leader index, ratio, offset) in this backend, per coupling."""
        names = list(self.mechanism.coordinates)
        return [(names.index(c.coordinate), names.index(c.leader), self.backend.rational(c.ratio),
                 self.backend.rational(c.offset)) for c in self.mechanism.couplings]

    def _closed_sample(self, q: list[Any], zd: Sequence[Any], zdd: Sequence[Any], where: str) -> Sample:
        """qd = R zd with R = [I; -Phi_d^-1 Phi_z]; qdd = R zdd - [0; Phi_d^-1 gamma]."""
        solved, self._solved = self._solved, None
        if solved is not None and solved[0] is q:
            return self._closed_batch(q, solved[1], zd, zdd, where)
        st = self.structure
        zero, one = self.kin.zero, self.kin.one
        _, rows = self.closure(q)
        jd = [[rows[i][j] for j in st.dependent] for i in st.rows]
        jz = [[rows[i][j] for j in st.independent] for i in st.rows]
        try:
            x = self.backend.solve(jd, jz)
        except KinematicsError as exc:
            raise KinematicsError(f"{where}singular configuration ({exc}); {self.singular_joints(jd)}"
                                  f"{self.describe(q)}") from None
        r = [[zero] * len(st.independent) for _ in range(self.n)]
        for j, i in enumerate(st.independent):
            r[i][j] = one
        for a, i in enumerate(st.dependent):
            r[i] = [-v for v in x[a]]
        qd = [_dot(r[i], zd, zero) for i in range(self.n)]
        states = None                  # body states: computed when first read (Sample.states)
        if self._generated_balls:
            bias = codegen.scalar_closure_bias(self.mechanism, self.backend, q, qd)
        elif isinstance(self.backend, Float64) and codegen.worthwhile(self.mechanism, "closure", q):
            if SCALAR_CLOSURE and _one_state(q) and _one_state(qd):
                bias = codegen.scalar_closure_bias(self.mechanism, self.backend, [float(v) for v in q],
                                                   [float(v) for v in qd])
            else:
                bias = codegen.closure_bias(self.mechanism, q, qd)
        else:
            states = self.kin.forward(q, qd)
            _, _, bias = self.kin.closure(states, want_bias=True, q=q)
        s = self.backend.solve(jd, [[bias[i]] for i in st.rows])
        extra = [zero] * self.n
        for a, i in enumerate(st.dependent):
            extra[i] = -s[a][0]
        qdd = [_dot(r[i], zdd, zero) + extra[i] for i in range(self.n)]
        return Sample(q, qd, qdd, states, r, self.kin)

    def _closed_batch(self, q: list[Any], jac: Array, zd: Sequence[Any], zdd: Sequence[Any],
                      where: str) -> Sample:
        """:meth:`_closed_sample` for a float64 batch that :meth:`_assemble_batch` solved:
        the Jacobian at q is the one its last evaluation gave, the products are array ones,
        the solves :meth:`Float64.solve_arrays` (the same condition check and messages)."""
        st = self.structure
        dep, ind, rows = list(st.dependent), list(st.independent), list(st.rows)
        shape = np.shape(q[dep[0]])
        jr = jac[:, rows]
        jd = jr[:, :, dep]
        try:
            x = Float64.solve_arrays(jd, jr[:, :, ind])                  # (samples, d, f)
        except KinematicsError as exc:
            jd_rows = [[jd[:, i, j] for j in range(len(dep))] for i in range(len(rows))]
            raise KinematicsError(f"{where}singular configuration ({exc}); {self.singular_joints(jd_rows)}"
                                  f"{self.describe(q)}") from None
        zero, one = self.kin.zero, self.kin.one
        zds = np.array([np.broadcast_to(np.asarray(v, dtype=float), shape) for v in zd])      # (f, samples)
        zdds = np.array([np.broadcast_to(np.asarray(v, dtype=float), shape) for v in zdd])
        qd_dep = -np.einsum("sdf,fs->ds", x, zds)
        r = [[zero] * len(ind) for _ in range(self.n)]
        qd = [None] * self.n
        for j, i in enumerate(ind):
            r[i][j] = one
            qd[i] = zds[j]
        for a, i in enumerate(dep):
            r[i] = [-x[:, a, j] for j in range(len(ind))]
            qd[i] = qd_dep[a]
        bias = codegen.closure_bias(self.mechanism, q, qd)
        s = Float64.solve_arrays(jd, np.stack([bias[i] for i in rows], axis=-1)[..., None])[..., 0]
        qdd = [None] * self.n
        for j, i in enumerate(ind):
            qdd[i] = zdds[j]
        qdd_dep = -np.einsum("sdf,fs->ds", x, zdds) - s.T
        for a, i in enumerate(dep):
            qdd[i] = qdd_dep[a]
        return Sample(q, qd, qdd, None, r, self.kin)


def _follow(value: Any, ratio: Any, offset: Any, name: str) -> Any:
    """A follower's position, ratio * leader + offset; for an exact angle (rational
    tan(theta/2), the exact solver's) only where that is exact too: ratio +-1, offset 0
    (a parallelogram's angles, a mirrored gripper finger), tan(-theta/2) = -t."""
    if isinstance(value, TanHalf):
        if offset == 0 and ratio in (1, -1):
            return TanHalf(value.t if ratio == 1 else -value.t)
        raise KinematicsError(f"{name} follows an exact angle with a ratio other than +-1 or an offset: "
                              "its tan(theta/2) is not rational")
    return ratio * value + offset


def _predict(path: Sequence[tuple[float, Array, Array]], lam: float) -> Array:
    """The dependent coordinates at ``lam`` extrapolated from the last solved stages: cubic
    Hermite through the last two (values and tangents), Euler from a single one."""
    if len(path) == 1:
        lam0, q0, t0 = path[0]
        return q0 + (lam - lam0) * t0
    (lam0, q0, t0), (lam1, q1, t1) = path
    h = lam1 - lam0
    s = (lam - lam0) / h
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * q0 + (s3 - 2 * s2 + s) * h * t0
            + (-2 * s3 + 3 * s2) * q1 + (s3 - s2) * h * t1)


NEWTON_BUDGET = 12     # Newton iterations per stage before a batch falls back to the general path
BATCHED_NEWTON = True  # False: float64 batches take the general path too (the reference in tests and benchmarks)
# One state (arb; float64 once the closure code is compiled): the closure terms by the generated
# scalar code. False: the generic kinematics (arb) and numpy code (float64), the reference in tests.
SCALAR_CLOSURE = True


def _dot(row: Sequence[Any], values: Sequence[Any], zero: Any) -> Any:
    total = zero
    for a, b in zip(row, values):
        if isinstance(a, int) and a == 0:
            continue
        total = total + a * b
    return total
