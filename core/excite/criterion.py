"""Trajectory criteria on the observation matrix as identification sees it, with gradients.

The matrix: the base regressor K_b = K B^+ (any solver's certified base columns, so it has
full column rank by construction unless the motion fails to excite) and the columns of the
effects to identify, rows weighted per coordinate (1 / noise SD, as ``identify`` weights
them), stacked over samples, each column scaled to unit norm (as the solvers and ``identify``
scale them). On it:

- ``condition``: log of the condition number sigma_1 / sigma_r (``identify``'s figure),
- ``d-optimal``: minus the mean log of the squared singular values (log det of A^T A / r),
- ``separation``: the largest log variance inflation among the columns of the effects to
  separate: for unit-norm columns [(A^T A)^-1]_kk = 1 / sin^2 theta_k, theta_k the angle
  between column k and the span of all the others (the model and the other effects), so
  minimising it maximises the smallest such angle.

Gradients: d(criterion)/dA in closed form from the SVD (or the inverse), through the column
scaling to the unweighted columns, then through B^+ to K and the effects' columns, and to
the trajectory's inputs with the forward-mode tangents of the generated regressor code
(:mod:`.tangent`) and the effects' exact derivatives (:data:`EFFECT_DERIVATIVES`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
import scipy.linalg

from baseparams.identify.base import BaseModel
from baseparams.dynamics.evaluator import Sample
from baseparams.dynamics.forces import drive_rows, effect_columns
from baseparams.model.mechanism import EffectSpec, Mechanism
from baseparams.excite.tangent import tree_regressor_with_tangents

CRITERIA = ("condition", "d-optimal", "separation")


def _zeros(x: np.ndarray) -> np.ndarray:
    return np.zeros_like(x)


def _ones(x: np.ndarray) -> np.ndarray:
    return np.ones_like(x)


# Per built-in effect kind: for each column, its derivatives (d/dq, d/dqd, d/dqdd) as functions
# of (q, qd, qdd) of the effect's coordinate. Coulomb's sign(qd) is flat between reversals.
EFFECT_DERIVATIVES = {
    "viscous_friction": [lambda q, qd, qdd: (_zeros(q), _ones(q), _zeros(q))],
    "coulomb_friction": [lambda q, qd, qdd: (_zeros(q), _zeros(q), _zeros(q))],
    "stribeck_friction": [lambda q, qd, qdd: (_zeros(q), np.sign(qd) * np.exp(-(qd / 0.01) ** 2)
                                              * (-2 * qd / 0.01 ** 2), _zeros(q))],
    "offset": [lambda q, qd, qdd: (_zeros(q), _zeros(q), _zeros(q))],
    "spring": [lambda q, qd, qdd: (_ones(q), _zeros(q), _zeros(q)),
               lambda q, qd, qdd: (_zeros(q), _zeros(q), _zeros(q))],
    "rotor_inertia": [lambda q, qd, qdd: (_zeros(q), _zeros(q), _ones(q))],
}


@dataclass
class Columns:
    """The model's columns at some samples: ``matrix`` (N, f, m) (base columns, then the
    effects'), ``names``, and optionally ``tangents`` (3 n, N, f, m) with respect to the tree
    inputs (q, qd, qdd of each tree coordinate)."""
    matrix: np.ndarray
    names: tuple[str, ...]
    tangents: np.ndarray | None = None
    torque_tangents: np.ndarray | None = None        # (3 f, N, f) of K phi
    torque: np.ndarray | None = None                 # (N, f) K phi
    margin: np.ndarray | None = None                 # closed loops: (N,) 1/cond of J_d ...
    margin_tangents: np.ndarray | None = None        # ... and its derivatives (3 f, N)


@dataclass
class Model:
    """What the criterion is computed on: the base model, the effects to identify, the per
    coordinate weights and, for torque limits, the file's inertial parameters."""
    mechanism: Mechanism
    base: BaseModel
    effects: tuple[EffectSpec, ...] = ()
    weights: np.ndarray | None = None
    phi: np.ndarray | None = None
    drop: tuple[int, ...] = ()                 # effect columns left out: a combination of the others on any motion
    _bplus: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._bplus = np.linalg.pinv(self.base.B) if self.base.rank else np.zeros((self.base.B.shape[1], 0))
        self.effects = tuple(self.effects)

    @property
    def all_names(self) -> tuple[str, ...]:
        out = list(self.base.names)
        from baseparams import registry
        for spec in self.effects:
            out += registry.effects()[spec.kind].item.coefficient_names(spec.coordinate)
        return tuple(out)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for k, name in enumerate(self.all_names) if k not in self.drop)

    @property
    def differentiable(self) -> bool:
        """Analytic gradients: open chains without couplings (built-in effects on joint
        coordinates), closed loops without effects."""
        m = self.mechanism
        return (not m.couplings and (not m.loops or not self.effects) and
                all(s.kind in EFFECT_DERIVATIVES for s in self.effects))

    def columns(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tangents: bool = False,
                sample: Sample | None = None) -> Columns:
        """The columns at samples of the independent coordinates (N, f); with ``tangents``
        (open chains only) their derivatives too. ``sample``: an evaluated
        :class:`~baseparams.dynamics.evaluator.Sample` (closed loops)."""
        n = q.shape[0]
        margin = dmargin = None
        if tangents and self.mechanism.loops:
            from baseparams.excite.loops import regressor_with_tangents
            from baseparams.dynamics.forces import Motion, evaluate
            if sample is None:
                sample = evaluate(self.mechanism, Motion(np.arange(n, dtype=float), q, qd, qdd))
            K, dK, margin, dmargin = regressor_with_tangents(self.mechanism, sample, qd, qdd)
        elif tangents:
            K, dK = tree_regressor_with_tangents(self.mechanism, q, qd, qdd)
        else:
            from baseparams.dynamics.forces import Motion, evaluate, inertial_columns
            if sample is None:
                sample = evaluate(self.mechanism, Motion(np.arange(n, dtype=float), q, qd, qdd))
            K, dK = inertial_columns(sample, n), None
        base = K @ self._bplus
        source: Any = sample           # the evaluated states, or an open chain's stand-in
        if source is None:
            source = SimpleNamespace(q=list(q.T), qd=list(qd.T), qdd=list(qdd.T),
                                     projection=[[1.0 if i == j else 0.0 for j in range(q.shape[1])]
                                                 for i in range(q.shape[1])])
        blocks = [base]
        dblocks: list[Any] = [None if dK is None else dK @ self._bplus]
        for spec in self.effects:
            _, block = effect_columns(self.mechanism, source, n, spec.kind, spec.coordinate)
            blocks.append(block)
            if dK is not None:
                dblocks.append(self._effect_tangents(spec, q, qd, qdd, block.shape))
        kept = [k for k in range(len(self.all_names)) if k not in self.drop]
        matrix = np.concatenate(blocks, axis=-1)[..., kept]
        out = Columns(matrix, self.names, margin=margin, margin_tangents=dmargin)
        if dK is not None:
            out.tangents = np.concatenate(dblocks, axis=-1)[..., kept]
            if self.phi is not None:
                out.torque = K @ self.phi
                out.torque_tangents = dK @ self.phi
        elif self.phi is not None:
            out.torque = K @ self.phi
        return out

    def _effect_tangents(self, spec: EffectSpec, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                         shape: tuple[int, ...]) -> np.ndarray:
        m = self.mechanism
        row = drive_rows(m, [spec.coordinate])[0]
        values = [v @ row for v in (q, qd, qdd)]
        n_tree = len(m.coordinates)
        out = np.zeros((3 * n_tree,) + shape)
        for c, derivative in enumerate(EFFECT_DERIVATIVES[spec.kind]):
            parts = derivative(*values)
            for g in range(3):
                for i in np.nonzero(row)[0]:
                    # column c on coordinate j is row_j * col_c(s); d/d input (g, i) = row_j dcol/ds_g row_i
                    out[g * n_tree + i, :, :, c] = np.outer(parts[g], row) * row[i]
        return out

    def weighted(self, matrix: np.ndarray) -> np.ndarray:
        w = np.ones(matrix.shape[1]) if self.weights is None else self.weights
        return matrix * w[None, :, None]


@dataclass
class Value:
    """A criterion's value, the figures reported with it and d(value)/d(columns) (N, f, m)."""
    value: float
    condition: float
    singular_values: np.ndarray
    smallest_angle_deg: float | None
    gradient: np.ndarray | None


def criterion(kind: str, matrix: np.ndarray, weights: np.ndarray | None, separate: tuple = (),
              gradient: bool = False) -> Value:
    """``kind`` on the columns ``matrix`` (N, f, m); ``separate``: the indices of the columns
    to tell apart (``separation``)."""
    n, f, m = matrix.shape
    w = np.ones(f) if weights is None else np.asarray(weights, float)
    X = (matrix * w[None, :, None]).reshape(n * f, m)
    norms = np.linalg.norm(X, axis=0)
    if np.any(norms == 0) or n * f < m:
        return Value(np.inf, np.inf, np.zeros(min(n * f, m)), 0.0, None)
    A = X / norms
    U, s, Vt = scipy.linalg.svd(A, full_matrices=False)
    condition = float(s[0] / s[-1]) if s[-1] > 0 else np.inf
    angle = None
    if separate:
        inverse = (Vt.T / s ** 2) @ Vt
        inflation = np.diag(inverse)[list(separate)]
        angle = float(np.degrees(np.arcsin(np.clip(1 / np.sqrt(np.max(inflation)), 0, 1))))
    if s[-1] <= 0:
        return Value(np.inf, np.inf, s, angle, None)
    if kind == "condition":
        value = float(np.log(condition))
        GA = np.outer(U[:, 0], Vt[0]) / s[0] - np.outer(U[:, -1], Vt[-1]) / s[-1] if gradient else None
    elif kind == "d-optimal":
        value = float(-2 * np.mean(np.log(s)))
        GA = -2 / m * (U / s) @ Vt if gradient else None
    elif kind == "separation":
        if not separate:
            raise ValueError("separation needs the columns to separate")
        k = list(separate)[int(np.argmax(inflation))]
        value = float(np.log(np.max(inflation)))
        if gradient:
            z = inverse[:, k]
            GA = -2 * np.outer(A @ z, z) / inverse[k, k]
        else:
            GA = None
    else:
        raise ValueError(f"unknown criterion {kind!r}")
    grad = None
    if gradient:
        # A = X / norms: dL/dX_k = (G_k - a_k (a_k . G_k)) / norm_k
        GX = (GA - A * np.sum(A * GA, axis=0)) / norms
        grad = GX.reshape(n, f, m) * w[None, :, None]
    return Value(value, condition, s, angle, grad)
