"""Physically consistent standard parameters that reproduce identified base parameters.

Base parameters say nothing about the standard parameters they group, and their estimates
may even be physically impossible; a model that is simulated needs every body's mass,
first moments and inertia, physically consistent. Wensing, Kim and Slotine (IEEE RA-L
2017, "Linear matrix inequalities for physically consistent inertial parameter
identification: a statistical perspective on the mass distribution") show that a body's
parameters come from a (nonnegative) mass distribution exactly when its pseudo-inertia

    J = [[Sigma, h], [h^T, m]],  Sigma = tr(I)/2 * 1 - I,  h = (mx, my, mz),

is positive semidefinite (I the rotational inertia about the body origin). This module
solves the semidefinite programme

    minimise  || (B phi - phi_b_hat) / std ||^2 + weight * || (phi - prior) / typical ||^2
    subject to  J_body(phi) >= 0 for every body

with cvxpy (optional extra ``physical``): the first term reproduces the base estimates in
units of their standard deviations, the small second one picks one solution among the
standard parameters the data cannot tell apart (the prior: the file's inertias when it
gives them, else the least-norm parameters B^+ phi_b_hat), in units of each kind's typical
size (mass, first moment, inertia).
"""

from dataclasses import dataclass
from typing import Any

import numpy as np

try:
    import cvxpy as cp
except ImportError:            # the optional extra is not installed: physical_fit says how to get it
    cp = None  # type: ignore[assignment]

from baseparams.errors import InputError
from baseparams.identify.base import BaseModel

WEIGHT = 1e-4
# std below this fraction of |estimate| (noise-free data) is raised to it, to keep the
# programme's scaling sane.
STD_FLOOR = 1e-9
KIND_GROUPS = (slice(0, 1), slice(1, 4), slice(4, 10))      # m; mx my mz; Ixx ... Izz


@dataclass(frozen=True)
class PhysicalFit:
    """``parameters``: the standard parameters (mechanism order); ``deviation``: (B phi -
    phi_b_hat) / std per base parameter; ``min_eigenvalues``: each body's pseudo-inertia's
    smallest eigenvalue (>= about -1e-9 relative: semidefinite); the solver's status."""
    parameters: np.ndarray
    deviation: np.ndarray
    min_eigenvalues: np.ndarray
    status: str
    solver: str

    @property
    def max_deviation(self) -> float:
        return float(np.max(np.abs(self.deviation))) if self.deviation.size else 0.0


INTERIOR = 1e-6
"""The pseudo-inertia is kept this far (relative to the body's typical inertia and mass)
inside the positive semidefinite cone."""


def require_cvxpy() -> None:
    if cp is None:
        raise InputError("physically consistent parameters (--physical) need cvxpy: "
                         "pip install 'baseparams[physical]'", key="--physical")


def pseudo_inertia(phi: np.ndarray) -> np.ndarray:
    """The 4 x 4 pseudo-inertia of one body's ten parameters (m mx my mz Ixx Ixy Ixz Iyy Iyz Izz,
    off-diagonal entries as tensor entries)."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in phi)
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    sigma = np.trace(inertia) / 2 * np.eye(3) - inertia
    h = np.array([mx, my, mz])
    return np.block([[sigma, h[:, None]], [h[None, :], np.array([[m]])]])


def _pseudo_inertia_expression(phi: Any) -> Any:
    """The same, as a cvxpy expression of ten affine entries."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (phi[k] for k in range(10))
    half = (ixx + iyy + izz) / 2
    return cp.bmat([[half - ixx, -ixy, -ixz, mx],
                    [-ixy, half - iyy, -iyz, my],
                    [-ixz, -iyz, half - izz, mz],
                    [mx, my, mz, m]])


def _typical(prior: np.ndarray) -> np.ndarray:
    """Each parameter's typical size: the RMS of its kind over the bodies (1 if all zero)."""
    bodies = prior.reshape(-1, 10)
    out = np.empty_like(bodies)
    for group in KIND_GROUPS:
        rms = float(np.sqrt(np.mean(bodies[:, group] ** 2)))
        out[:, group] = rms if rms > 0 else 1.0
    return out.reshape(-1)


def physical_fit(base_estimate: np.ndarray, base: BaseModel, *, std: np.ndarray | None = None,
                 prior: np.ndarray | None = None, weight: float = WEIGHT) -> PhysicalFit:
    """Physically consistent standard parameters reproducing ``base_estimate`` (see above)."""
    require_cvxpy()
    estimate = np.asarray(base_estimate, dtype=float)
    P = base.B.shape[1]
    if P % 10:
        raise ValueError(f"{P} standard parameters: not ten per body")
    std = np.ones_like(estimate) if std is None else np.asarray(std, dtype=float)
    std = np.maximum(std, STD_FLOOR * np.maximum(np.abs(estimate), np.abs(estimate).max(initial=1.0)))
    if prior is None:
        prior = np.linalg.lstsq(base.B, estimate, rcond=None)[0]
    typical = _typical(np.asarray(prior, dtype=float))
    # unknowns in units of their kind's typical size, so the programme is well scaled
    x = cp.Variable(P)
    phi = cp.multiply(typical, x)
    fit = cp.sum_squares(cp.multiply(1 / std, base.B @ phi - estimate))
    regular = weight * cp.sum_squares(x - prior / typical)
    constraints = []
    for body in range(P // 10):
        J = _pseudo_inertia_expression(phi[10 * body: 10 * body + 10])
        # strictly inside the cone by a small margin: a solution on its boundary (a thin rod)
        # would, after the solver's own tolerance, break the exact checks of the mechanism
        # reader (triangle inequalities) when the parameters are written back to a file
        t = typical[10 * body: 10 * body + 10]
        margin = INTERIOR * np.diag([t[4], t[4], t[4], t[0]])
        constraints.append((J + J.T) / 2 - margin >> 0)
    problem = cp.Problem(cp.Minimize(fit + regular), constraints)
    used = ""
    for solver in ("CLARABEL", "SCS"):
        if solver not in cp.installed_solvers():
            continue
        try:
            problem.solve(solver=solver)
        except cp.error.SolverError:
            continue
        used = solver
        if problem.status in ("optimal", "optimal_inaccurate"):
            break
    if x.value is None:
        raise InputError(f"the semidefinite programme for physically consistent parameters failed "
                         f"(status {problem.status}, solver {used or 'none available'})", key="--physical")
    parameters = typical * np.asarray(x.value, dtype=float)
    deviation = (base.B @ parameters - estimate) / std
    eigenvalues = np.array([np.linalg.eigvalsh(pseudo_inertia(parameters[10 * b: 10 * b + 10]))[0]
                            for b in range(P // 10)])
    return PhysicalFit(parameters, deviation, eigenvalues, str(problem.status), used)


def physical_parameters(base_estimate: np.ndarray, base: BaseModel, *, std: np.ndarray | None = None,
                        prior: np.ndarray | None = None, weight: float = WEIGHT) -> np.ndarray:
    """The standard parameter vector of :func:`physical_fit`."""
    return physical_fit(base_estimate, base, std=std, prior=prior, weight=weight).parameters


def physical_json(fit: PhysicalFit, parameters: tuple[str, ...]) -> dict[str, str]:
    """``{"m1": "...", ...}``: every standard parameter as a decimal string (shortest round trip)."""
    return {name: repr(float(value)) for name, value in zip(parameters, fit.parameters)}
