"""Plan the motion: one optimisation from a random start, under the limits.

Open chains: SLSQP with the criterion's analytic gradient (:mod:`.criterion`, through the
generated regressor's tangents), position, velocity and acceleration limits as linear
inequalities on a grid of the period (the form is linear in its variables), torque limits
as nonlinear ones with their exact Jacobian. Closed loops (their dependent coordinates
come from Newton on the closure equations, which the tangent code does not follow):
COBYLA, derivative-free, with the same limits plus the reachable range (every sample must
close) and the singularity margin (the dependent block of the closure Jacobian must keep
1/cond >= margin at every sample).

The optimiser sees the limits shrunk by :data:`SAFETY`; the planner then verifies the
written (rounded) motion on a grid ten times finer and shrinks its amplitude until every
limit holds there (:mod:`.plan`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np
import scipy.optimize

from baseparams.dynamics import codegen
from baseparams.dynamics.evaluator import Sample, closure_structure
from baseparams.errors import KinematicsError
from baseparams.excite.criterion import Model, criterion
from baseparams.excite.fourier import FourierForm
from baseparams.excite.limits import Limits
from baseparams.dynamics.forces import Motion, evaluate
from baseparams.model.mechanism import Mechanism

T = TypeVar("T")

SAFETY = 0.02                  # the optimiser keeps 2 % of each range and limit in reserve
START_FILL = 0.7               # a random start fills 70 % of the tightest limit
PENALTY = 1e3                  # criterion value of a motion that does not close
CANDIDATES = 10                # closed loops: random motions tried for a start ...
LOOP_FILL = 0.95               # ... filling this much of their limits


@dataclass
class Problem:
    """Everything one optimisation needs."""
    model: Model
    limits: Limits
    form: FourierForm
    samples: int
    kind: str = "condition"
    separate: tuple[Any, ...] = ()
    margin: float = 0.0              # closed loops: min 1/cond of the dependent closure Jacobian
    maxiter: int = 200

    @property
    def mechanism(self) -> Mechanism:
        return self.model.mechanism

    def times(self, factor: int = 1) -> np.ndarray:
        return np.linspace(0.0, self.form.period, factor * (self.samples - 1) + 1)


@dataclass
class Check:
    """A motion's figures: criterion value, condition number, smallest separation angle,
    singular values, and the margins (>= 0 when the limit holds) of each kind of limit."""
    value: float
    condition: float
    angle: float | None
    singular_values: np.ndarray
    margins: dict[str, float]
    feasible: bool
    reason: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"criterion": _finite(self.value), "condition_number": _finite(self.condition),
                "smallest_angle_deg": self.angle, "singular_values": [float(v) for v in self.singular_values],
                "margins": {k: _finite(v) for k, v in self.margins.items()}, "feasible": self.feasible,
                **({"reason": self.reason} if self.reason else {})}


def _finite(x: float | None) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def singularity_margin(mechanism: Mechanism, sample: Sample) -> np.ndarray:
    """Per sample: 1/cond of the closure Jacobian's block in the dependent coordinates."""
    structure = closure_structure(mechanism)
    n = len(mechanism.coordinates)
    count = max(np.size(v) for v in sample.q)
    q = np.array([np.broadcast_to(np.asarray(v, float), (count,)) for v in sample.q]).reshape(n, count)
    _, jac = codegen.closure_arrays(mechanism, q)
    block = jac[:, list(structure.rows)][:, :, list(structure.dependent)]
    s = np.linalg.svd(block, compute_uv=False)
    return s[:, -1] / s[:, 0]


def check(problem: Problem, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, safety: float = 0.0) -> Check:
    """The figures of a motion given by its samples (N, f), limits shrunk by ``safety``."""
    lim, m = problem.limits, problem.mechanism
    half = (lim.upper - lim.lower) / 2
    margins = {
        "position": float(np.min(np.minimum(q - lim.lower, lim.upper - q) - safety * half)),
        "velocity": float(np.min((1 - safety) * lim.velocity - np.abs(qd))),
        "acceleration": float(np.min((1 - safety) * lim.acceleration - np.abs(qdd))),
    }
    sample = None
    if m.loops or m.couplings:
        try:
            sample = evaluate(m, Motion(np.arange(len(q), dtype=float), q, qd, qdd))
        except KinematicsError as exc:
            return Check(np.inf, np.inf, None, np.zeros(0), margins, False, str(exc))
        if m.loops:
            margins["singularity"] = float(np.min(singularity_margin(m, sample)) - problem.margin)
    try:
        columns = problem.model.columns(q, qd, qdd, sample=sample) if sample is not None else \
            problem.model.columns(q, qd, qdd, tangents=False)
    except KinematicsError as exc:                    # a file's coordinate limit (open chains)
        return Check(np.inf, np.inf, None, np.zeros(0), margins, False, str(exc))
    if columns.torque is not None and np.any(np.isfinite(lim.torque)):
        margins["torque"] = float(np.min((1 - safety) * lim.torque - np.abs(columns.torque)))
    value = criterion(problem.kind, columns.matrix, problem.model.weights, problem.separate)
    feasible = all(v >= 0 for v in margins.values())
    bad = [k for k, v in margins.items() if v < 0]
    return Check(value.value, value.condition, value.smallest_angle_deg, value.singular_values, margins,
                 feasible, f"outside the {', '.join(bad)} limits" if bad else "")


def start(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """The start of one optimisation: a random motion (:func:`random_start`); for a
    derivative-free run (closed loops), the best feasible of CANDIDATES random motions
    filling LOOP_FILL of their limits (a random motion there is often numerically rank
    deficient, where the criterion is flat)."""
    if problem.model.differentiable and not problem.mechanism.loops:
        return random_start(problem, rng)
    best: tuple[float, np.ndarray] | None = None
    first: np.ndarray | None = None
    for _ in range(CANDIDATES):
        x = scale_to_limits(problem, random_start(problem, rng), LOOP_FILL)
        first = x if first is None else first
        result = check(problem, *problem.form.motion(x, problem.times()), safety=SAFETY)
        if result.feasible and (best is None or result.value < best[0]):
            best = (result.value, x)
    assert first is not None                   # CANDIDATES > 0
    return first if best is None else best[1]


def random_start(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """A random motion at rest at both ends, centred in the ranges, filling START_FILL of
    its tightest limit."""
    form, lim = problem.form, problem.limits
    L = form.harmonics
    f = len(form.names)
    coefficients = np.zeros((f, 2 * L + 1))
    coefficients[:, 0] = (lim.lower + lim.upper) / 2
    decay = 1.0 / np.arange(1, L + 1)
    coefficients[:, 1:L + 1] = rng.standard_normal((f, L)) * decay
    coefficients[:, L + 1:] = rng.standard_normal((f, L)) * decay
    x = form.variables(coefficients)
    return scale_to_limits(problem, x, START_FILL)


def scale_to_limits(problem: Problem, x: np.ndarray, fill: float) -> np.ndarray:
    """``x`` with its oscillation scaled so that position, velocity and acceleration use at
    most ``fill`` of their limits (the centre kept)."""
    form, lim = problem.form, problem.limits
    coefficients = form.coefficients(x)
    centre = coefficients[:, 0]
    q, qd, qdd = form.motion(x, problem.times())
    ratios = [np.max(np.abs(q - centre), axis=0) / np.minimum(centre - lim.lower, lim.upper - centre),
              np.max(np.abs(qd), axis=0) / lim.velocity, np.max(np.abs(qdd), axis=0) / lim.acceleration]
    worst = np.max(np.vstack(ratios), axis=0)
    coefficients[:, 1:] *= (fill / np.maximum(worst, 1e-12))[:, None]
    return form.variables(coefficients)


def shrink(problem: Problem, x: np.ndarray, factor: float) -> np.ndarray:
    """The oscillation of ``x`` times ``factor`` (centres kept): velocities and accelerations
    scale with it, positions move toward the centre."""
    coefficients = problem.form.coefficients(x)
    coefficients[:, 1:] *= factor
    return problem.form.variables(coefficients)


def _linear_constraints(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """(G, h): position, velocity and acceleration limits (shrunk by SAFETY) as G x + h >= 0."""
    form, lim = problem.form, problem.limits
    rows = form.rows(problem.times())
    f, m = len(form.names), form.per_coordinate
    half = (lim.upper - lim.lower) / 2
    blocks, offsets = [], []
    bounds = [(lim.upper - SAFETY * half, lim.lower + SAFETY * half),
              ((1 - SAFETY) * lim.velocity, -(1 - SAFETY) * lim.velocity),
              ((1 - SAFETY) * lim.acceleration, -(1 - SAFETY) * lim.acceleration)]
    for phi, (upper, lower) in zip(rows, bounds):
        for j in range(f):
            G = np.zeros((len(phi), f * m))
            G[:, j * m:(j + 1) * m] = phi
            blocks += [-G, G]
            offsets += [np.full(len(phi), upper[j]), np.full(len(phi), -lower[j])]
    return np.vstack(blocks), np.concatenate(offsets)


@dataclass
class Outcome:
    x: np.ndarray
    value: float
    feasible: bool
    converged: bool
    message: str
    iterations: int = 0
    evaluations: int = 0
    extra: dict = field(default_factory=dict)


def optimise(problem: Problem, x0: np.ndarray) -> Outcome:
    """One local optimisation from ``x0``: SLSQP with gradients (open chains) or COBYLA."""
    if problem.model.differentiable:
        return _slsqp(problem, x0)
    return _cobyla(problem, x0)


def _chain(problem: Problem, inputs: np.ndarray, rows: Sequence[np.ndarray]) -> np.ndarray:
    """d/dx from d/d(independent inputs z, zd, zdd) summed over the samples: ``inputs``
    (3 f, N, ...) -> (..., f m)."""
    f, m = len(problem.form.names), problem.form.per_coordinate
    parts = inputs.reshape((3, f) + inputs.shape[1:])
    out = np.einsum("gin...,gnk->...ik", parts, np.stack(rows))
    return out.reshape(out.shape[:-2] + (f * m,))


def _per_sample(problem: Problem, inputs: np.ndarray, rows: Sequence[np.ndarray]) -> np.ndarray:
    """d/dx of per-sample values: ``inputs`` (3 f, N, k) -> (N, k, f m)."""
    f = len(problem.form.names)
    parts = inputs.reshape((3, f) + inputs.shape[1:])
    out = np.einsum("gink,gnm->nkim", parts, np.stack(rows))
    return out.reshape(out.shape[:2] + (-1,))


def _slsqp(problem: Problem, x0: np.ndarray) -> Outcome:
    form, lim, model = problem.form, problem.limits, problem.model
    t = problem.times()
    rows = form.rows(t)
    G, h = _linear_constraints(problem)
    torque_limited = model.phi is not None and np.any(np.isfinite(lim.torque))

    def evaluate(x: np.ndarray) -> dict[str, Any]:
        q, qd, qdd = form.motion(x, t)
        try:
            columns = model.columns(q, qd, qdd, tangents=True)
        except KinematicsError:            # a closed loop that does not close, a file's limit
            return dict(f=PENALTY, g=np.zeros_like(x), columns=None)
        value = criterion(problem.kind, columns.matrix, model.weights, problem.separate, gradient=True)
        if value.gradient is None:
            return dict(f=PENALTY, g=np.zeros_like(x), columns=columns)
        assert columns.tangents is not None        # asked for
        inputs = np.einsum("nfm,dnfm->dn", value.gradient, columns.tangents)
        return dict(f=value.value, g=_chain(problem, inputs, rows), columns=columns)

    evaluate_at = _LastPoint(evaluate)

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        c = evaluate_at(x)
        return c["f"], c["g"]

    constraints: list[dict[str, Any]] = [{"type": "ineq", "fun": lambda x: G @ x + h, "jac": lambda x: G}]
    if torque_limited:
        finite = np.isfinite(lim.torque)
        bound = (1 - SAFETY) * lim.torque[finite]

        def torque(x: np.ndarray) -> np.ndarray:
            columns = evaluate_at(x)["columns"]
            if columns is None:
                return -np.ones(2 * len(t) * int(finite.sum()))
            tau = columns.torque[:, finite]
            return np.concatenate([(bound - tau).ravel(), (bound + tau).ravel()])

        def torque_jac(x: np.ndarray) -> np.ndarray:
            columns = evaluate_at(x)["columns"]
            if columns is None:
                return np.zeros((2 * len(t) * int(finite.sum()), x.size))
            d = _per_sample(problem, columns.torque_tangents, rows)[:, finite]
            d = d.reshape(-1, d.shape[-1])
            return np.vstack([-d, d])

        constraints.append({"type": "ineq", "fun": torque, "jac": torque_jac})
    if problem.mechanism.loops:
        least = (1 + SAFETY) * problem.margin

        def margin(x: np.ndarray) -> np.ndarray:
            columns = evaluate_at(x)["columns"]
            return -np.ones(len(t)) if columns is None else columns.margin - least

        def margin_jac(x: np.ndarray) -> np.ndarray:
            columns = evaluate_at(x)["columns"]
            if columns is None:
                return np.zeros((len(t), x.size))
            return _per_sample(problem, columns.margin_tangents[:, :, None], rows)[:, 0, :]

        constraints.append({"type": "ineq", "fun": margin, "jac": margin_jac})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = scipy.optimize.minimize(objective, x0, jac=True, method="SLSQP", constraints=constraints,
                                         options={"maxiter": problem.maxiter, "ftol": 1e-7})
    x = result.x
    q, qd, qdd = form.motion(x, t)
    final = check(problem, q, qd, qdd)
    return Outcome(x, final.value, final.feasible, bool(result.success), str(result.message),
                   int(getattr(result, "nit", 0)), evaluate_at.count)


class _LastPoint(Generic[T]):
    """``evaluate`` at the last point asked, kept: scipy asks for the objective and each
    constraint separately at the same x. ``count``: the evaluations made."""

    def __init__(self, evaluate: Callable[[np.ndarray], T]) -> None:
        self.evaluate = evaluate
        self.key: bytes | None = None
        self.value: T | None = None
        self.count = 0

    def __call__(self, x: np.ndarray) -> T:
        key = x.tobytes()
        if self.value is None or key != self.key:
            self.count += 1
            self.value, self.key = self.evaluate(x), key
        return self.value


def _cobyla(problem: Problem, x0: np.ndarray) -> Outcome:
    form = problem.form
    t = problem.times()
    G, h = _linear_constraints(problem)
    evaluate_at = _LastPoint(lambda x: check(problem, *form.motion(x, t), safety=SAFETY))

    def objective(x: np.ndarray) -> float:
        result = evaluate_at(x)
        return result.value if math.isfinite(result.value) else PENALTY

    def nonlinear(x: np.ndarray) -> np.ndarray:
        result = evaluate_at(x)
        if not math.isfinite(result.value):
            return np.array([-1.0])
        extra = [v for k, v in result.margins.items() if k in ("singularity", "torque")]
        return np.array(extra or [1.0])

    constraints = [{"type": "ineq", "fun": lambda x: G @ x + h}, {"type": "ineq", "fun": nonlinear}]
    scale = float(np.max(np.abs(problem.form.coefficients(x0)[:, 1:]))) or 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = scipy.optimize.minimize(objective, x0, method="COBYLA", constraints=constraints,
                                         options={"maxiter": problem.maxiter * 5, "rhobeg": 0.2 * scale,
                                                  "tol": 1e-6})
    x = result.x
    q, qd, qdd = form.motion(x, t)
    final = check(problem, q, qd, qdd)
    return Outcome(x, final.value, final.feasible, bool(result.success), str(result.message),
                   int(getattr(result, "nfev", 0)), evaluate_at.count)


def independent_states(problem: Problem, count: int, seed: int = 0) -> Check:
    """The criterion at ``count`` independent random states drawn inside the limits (position
    uniform in its range, velocity and acceleration uniform within their limits): what a
    motion could reach if it were not a motion. Closed loops: draws that do not close or
    break the singularity margin are redrawn."""
    rng = np.random.default_rng(seed)
    lim, m = problem.limits, problem.mechanism
    f = len(lim.names)
    q = rng.uniform(lim.lower, lim.upper, size=(count, f))
    qd = rng.uniform(-lim.velocity, lim.velocity, size=(count, f))
    qdd = rng.uniform(-lim.acceleration, lim.acceleration, size=(count, f))
    sample = None
    if m.loops or m.couplings:
        kept: list[np.ndarray] = []
        for k in range(count * 20):
            if len(kept) == count:
                break
            z = rng.uniform(lim.lower, lim.upper, size=(1, f))
            try:
                s = evaluate(m, Motion(np.zeros(1), z, np.zeros((1, f)), np.zeros((1, f))))
            except KinematicsError:
                continue
            if m.loops and np.min(singularity_margin(m, s)) < problem.margin:
                continue
            kept.append(z[0])
        q = np.array(kept)
        qd, qdd = qd[:len(q)], qdd[:len(q)]
        sample = evaluate(m, Motion(np.arange(len(q), dtype=float), q, qd, qdd))
    columns = problem.model.columns(q, qd, qdd, sample=sample) if sample is not None else \
        problem.model.columns(q, qd, qdd)
    value = criterion(problem.kind, columns.matrix, problem.model.weights, problem.separate)
    return Check(value.value, value.condition, value.smallest_angle_deg, value.singular_values, {}, True)
