"""States on the constraint manifold and the regressor in the independent coordinates.

For a closed-loop mechanism the tree coordinates q split into the chosen independent
ones z and dependent ones d. Positions: Newton-Raphson on the loop-closure equations, in
the backend's own arithmetic (float64 first, then refined at D digits until the residual
is below 10^-(D-5)). Velocities and accelerations: solved from the differentiated
equations, ``qd = R zd`` and ``qdd = R zdd + s``, never by finite differences. The
regressor in the independent coordinates is ``K = R^T K_tree`` (the seed paper's
projection onto an orthogonal complement of the constraint Jacobian).
"""

import functools
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from baseparams.numeric.backends import Arb, Float64, in_backend_precision
from baseparams.errors import KinematicsError, InputError
from baseparams.kinematics.tree import TreeKinematics
from baseparams.kinematics.krawczyk import enclose
from baseparams.dynamics.regressor import energy_forms, tree_regressor_array
from baseparams.dynamics import codegen


@dataclass(frozen=True)
class ClosureStructure:
    rows: tuple          # indices of the independent closure equations
    independent: tuple   # coordinate indices of z
    dependent: tuple     # coordinate indices of d
    rank: int            # rank of the closure Jacobian
    redundant: int       # closure equations implied by the others

    @property
    def dof(self):
        return len(self.independent)


@functools.lru_cache(maxsize=64)
def closure_structure(mechanism):
    """Independent closure equations and dependent coordinates, from the Jacobian at q = 0."""
    n = len(mechanism.coordinates)
    names = list(mechanism.coordinates)
    if not mechanism.loops:
        if mechanism.independent and sorted(mechanism.independent) != sorted(names):
            raise InputError(f"a mechanism without loops has {n} degrees of freedom: every tree coordinate "
                             f"is independent ({', '.join(names)}); omit coordinates.independent or list "
                             f"them all", file=mechanism.path, key="coordinates.independent")
        indep = tuple(names.index(c) for c in mechanism.independent) if mechanism.independent else tuple(range(n))
        return ClosureStructure((), indep, (), 0, 0)
    kin = TreeKinematics(mechanism, Float64())
    _, rows, _ = kin.closure(kin.forward([0.0] * n))
    jac = np.array([[float(v) for v in row] for row in rows])
    tol = 1e-9 * max(1.0, np.abs(jac).max())
    chosen = independent_rows(jac, tol)
    rank = len(chosen)
    if mechanism.independent:
        indep = [names.index(c) for c in mechanism.independent]
        dep = [i for i in range(n) if i not in indep]
        sub = jac[np.ix_(chosen, dep)]
        if len(dep) != rank or np.linalg.matrix_rank(sub, tol) < rank:
            raise InputError(
                f"the independent coordinates {list(mechanism.independent)} do not parameterize the "
                f"mechanism: {n} tree coordinates, {rank} independent closure equations, so "
                f"{n - rank} independent coordinates are needed and the others must be solvable",
                file=mechanism.path, key="coordinates.independent")
    else:
        dep = independent_rows(jac[chosen].T, tol)
        indep = [i for i in range(n) if i not in dep]
    return ClosureStructure(tuple(chosen), tuple(indep), tuple(dep), rank, len(rows) - rank)


def independent_rows(matrix, tol):
    """Greedy Gram-Schmidt: indices of rows independent of the earlier ones."""
    chosen, basis = [], []
    for i, row in enumerate(matrix):
        r = row.astype(float).copy()
        for b in basis:
            r -= (r @ b) * b
        norm = np.linalg.norm(r)
        if norm > tol:
            chosen.append(i)
            basis.append(r / norm)
    return chosen


@dataclass
class Sample:
    """One evaluated state (or a batch of them, for float64): everything the regressor needs."""
    q: list
    qd: list
    qdd: list
    states: dict
    projection: list     # R: n rows x f columns, qd = R zd
    kin: TreeKinematics

    @in_backend_precision
    def regressor(self):
        """K in the independent coordinates: f rows of 10 * bodies entries."""
        k_tree = codegen.regressor_rows(self.kin, self.q, self.qd, self.qdd, self.states)
        if not self.kin.mechanism.loops:
            return k_tree
        return project(self.projection, k_tree, self.kin.zero)

    def regressor_array(self):
        """float64 only: K as an array (samples, f, 10 * bodies), without per-entry Python work."""
        mech = self.kin.mechanism
        if codegen.worthwhile(mech, "regressor", self.q):
            k_tree = codegen.tree_regressor(mech, self.q, self.qd, self.qdd)
        else:
            k_tree = tree_regressor_array(self.kin, self.states, self.qdd)
        if not self.kin.mechanism.loops:
            return k_tree
        shape = k_tree.shape[:-2]
        r = np.stack([np.stack([np.broadcast_to(v, shape) for v in row], axis=-1) for row in self.projection],
                     axis=-2)
        return np.einsum("...kf,...kp->...fp", r, k_tree)

    @in_backend_precision
    def energies(self):
        return energy_forms(self.kin, self.states)


def project(r, k_tree, zero):
    """R^T K_tree."""
    f = len(r[0])
    out = []
    for j in range(f):
        row = None
        for k, rk in enumerate(r):
            coeff = rk[j]
            if isinstance(coeff, int) and coeff == 0:
                continue
            if row is None:
                row = [coeff * v for v in k_tree[k]]
            else:
                row = [a + coeff * v for a, v in zip(row, k_tree[k])]
        out.append(row if row is not None else [zero] * len(k_tree[0]))
    return out


class Evaluator:
    """Evaluates a mechanism's states and regressor in one backend."""

    def __init__(self, mechanism, backend, symbolic_geometry=False, certify=False):
        """``certify`` (arb only): replace Newton's dependent coordinates by balls proven to
        contain the exact loop-closure solution (see :mod:`baseparams.kinematics.krawczyk`)."""
        self.mechanism = mechanism
        self.backend = backend
        self.certify = certify and isinstance(backend, Arb)
        self.kin = TreeKinematics(mechanism, backend, symbolic_geometry)
        self.structure = closure_structure(mechanism)
        self.n = self.kin.n

    # ----- positions ------------------------------------------------------
    def tolerance(self):
        """Decimal exponent of the closure residual Newton must reach: 10^-(D-5) at D digits."""
        digits = getattr(self.backend, "digits", None)
        return -12 if digits is None else -(digits - 5)

    @in_backend_precision
    def assemble(self, z, guess=None, where=""):
        """Tree coordinates with independent values ``z``; dependent ones by Newton-Raphson."""
        st = self.structure
        q = list(guess) if guess is not None else [self.kin.zero] * self.n
        for value, i in zip(z, st.independent):
            q[i] = value
        if not self.mechanism.loops:
            return q
        if self.backend.exact:
            raise KinematicsError("exact and symbolic arithmetic cannot solve loop closure; "
                                  "give all tree coordinates or use float64 / arb")
        if guess is None:
            # continuation from the reference configuration (q = 0 closes the loops), in steps
            # of at most 0.25 in every independent coordinate
            reach = max(float(np.max(np.abs(self.backend.to_float(v)))) for v in z)
            steps = max(4, int(np.ceil(reach / 0.25)))
            for step in range(1, steps):
                lam = self.backend.rational(Fraction(step, steps))
                q = self._newton(q, [lam * v for v in z], -6, where + "(continuation) ")
        q = self._newton(q, z, self.tolerance(), where)
        return enclose(self, q, where) if self.certify else q

    def _newton(self, q, z, tol, where):
        st = self.structure
        q = list(q)
        for value, i in zip(z, st.independent):
            q[i] = value
        residual = None
        # float64 takes one more (quadratically convergent) step once within tolerance, so that
        # positions are as exact as double precision allows, not merely below 1e-12
        polish = isinstance(self.backend, Float64) and tol <= -12
        for _ in range(60):
            values, rows = self._closure(q)
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
        # tolerance: the redundant ones were not solved for, they follow
        slack = tol + 3
        values, _ = self._closure(q)
        if not all(self.backend.small(v, slack) for v in values):
            worst = max(self.backend.magnitude(v) for v in values)
            raise KinematicsError(f"{where}a redundant closure equation is violated (residual "
                                  f"{worst:.3g}): the geometry is inconsistent; {self.describe(q)}")
        return q

    def _closure(self, q):
        """Closure values and Jacobian rows at q (float64 batches: generated code once it pays)."""
        if isinstance(self.backend, Float64) and codegen.worthwhile(self.mechanism, "closure", q):
            return codegen.closure(self.mechanism, q)
        values, rows, _ = self.kin.closure(self.kin.forward(q))
        return values, rows

    def singular_joints(self, jd) -> str:
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

    def describe(self, q, only=None):
        parts = []
        for i, (name, v) in enumerate(zip(self.mechanism.coordinates, q)):
            if only is not None and i not in only:
                continue
            f = np.atleast_1d(self.backend.to_float(v))
            parts.append(f"{name}={f[0]:.6g}" if f.size == 1 else f"{name}=[{f.min():.4g}..{f.max():.4g}]")
        return "coordinates: " + ", ".join(parts)

    # ----- full state -----------------------------------------------------
    @in_backend_precision
    def sample(self, z, zd, zdd, guess=None, where=""):
        """The state with independent positions, velocities and accelerations z, zd, zdd."""
        q = self.assemble(z, guess, where)
        if self.mechanism.loops:
            return self._closed_sample(q, zd, zdd, where)
        zero, one = self.kin.zero, self.kin.one
        st = self.structure
        qd, qdd = [zero] * self.n, [zero] * self.n
        r = [[zero] * len(st.independent) for _ in range(self.n)]    # a permutation
        for j, i in enumerate(st.independent):
            qd[i], qdd[i], r[i][j] = zd[j], zdd[j], one
        return Sample(q, qd, qdd, self.kin.forward(q, qd), r, self.kin)

    def _closed_sample(self, q, zd, zdd, where):
        """qd = R zd with R = [I; -Phi_d^-1 Phi_z]; qdd = R zdd - [0; Phi_d^-1 gamma]."""
        st = self.structure
        zero, one = self.kin.zero, self.kin.one
        _, rows = self._closure(q)
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
        states = self.kin.forward(q, qd)
        if isinstance(self.backend, Float64) and codegen.worthwhile(self.mechanism, "closure", q):
            bias = codegen.closure_bias(self.mechanism, q, qd)
        else:
            _, _, bias = self.kin.closure(states, want_bias=True)
        s = self.backend.solve(jd, [[bias[i]] for i in st.rows])
        extra = [zero] * self.n
        for a, i in enumerate(st.dependent):
            extra[i] = -s[a][0]
        qdd = [_dot(r[i], zdd, zero) + extra[i] for i in range(self.n)]
        return Sample(q, qd, qdd, states, r, self.kin)


def _dot(row, values, zero):
    total = zero
    for a, b in zip(row, values):
        if isinstance(a, int) and a == 0:
            continue
        total = total + a * b
    return total
