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
from baseparams.excite.collision import slack
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
    scene: Any = None                # collision.Scene: distances the motion must keep, or None
    buffer: float = 0.0              # m the optimiser keeps beyond the clearance (between samples)

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
    collision: dict[str, Any] | None = None      # smallest distance, where, guaranteed between samples

    def to_json(self) -> dict[str, Any]:
        return {"criterion": _finite(self.value), "condition_number": _finite(self.condition),
                "smallest_angle_deg": self.angle, "singular_values": [float(v) for v in self.singular_values],
                "margins": {k: _finite(v) for k, v in self.margins.items()}, "feasible": self.feasible,
                **({"reason": self.reason} if self.reason else {}),
                **({"collision": self.collision} if self.collision is not None else {})}


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


def check(problem: Problem, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, safety: float = 0.0,
          jerk: np.ndarray | None = None, times: np.ndarray | None = None, motion: Any = None) -> Check:
    """The figures of a motion given by its samples (N, f), limits shrunk by ``safety``;
    ``jerk`` (N, f) checks the jerk limits; with the samples' ``times`` the collision margin
    holds between the samples too, and with ``motion(t) -> (q, qd, qdd)`` the intervals that
    need it are sampled more densely (:func:`.collision.guaranteed`)."""
    lim, m = problem.limits, problem.mechanism
    half = (lim.upper - lim.lower) / 2
    margins = {
        "position": float(np.min(np.minimum(q - lim.lower, lim.upper - q) - safety * half)),
        "velocity": float(np.min((1 - safety) * lim.velocity - np.abs(qd))),
        "acceleration": float(np.min((1 - safety) * lim.acceleration - np.abs(qdd))),
    }
    if jerk is not None and np.any(np.isfinite(lim.jerk)):
        margins["jerk"] = float(np.min((1 - safety) * lim.jerk - np.abs(jerk)))
    collision = None
    if problem.scene is not None and problem.scene.checks:
        margins["collision"], collision = collision_margin(problem, q, qd, qdd, times, motion)
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
                 feasible, f"outside the {', '.join(bad)} limits" if bad else "", collision)


def collision_margin(problem: Problem, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                     times: np.ndarray | None, motion: Any = None) -> tuple[float, dict[str, Any]]:
    """(smallest slack, details): each item's distance less what it must keep, at the
    samples, or with ``times`` guaranteed between them. Details: the smallest distance at
    the samples and where, the smallest height above each keep-out plane, and the smallest
    distance guaranteed between samples."""
    from baseparams.excite.collision import guaranteed
    scene = problem.scene
    if times is None or len(times) < 2:
        at, _, labels = scene.distances(q)
        low = at
    else:
        at, labels, low = guaranteed(scene, times, q, qd, qdd, motion)
    n, k = np.unravel_index(int(np.argmin(at)), at.shape)
    pairs = len(scene.pair_names)
    planes = {}
    for p in range(len(scene.spec.planes)):
        cols = [pairs + i for i, (pp, _) in enumerate(scene.plane_items) if pp == p]
        if cols:
            planes[f"plane {p}"] = float(np.min(at[:, cols]))
    details = {"clearance": scene.spec.clearance, "smallest_distance": float(at[n, k]), "where": labels[k],
               "sample": int(n), "self_collision_checked": scene.self_checked,
               "self_smallest_distance": float(np.min(at[:, :pairs])) if pairs else None,
               "above_planes": planes, "pairs": pairs, "plane_items": len(scene.plane_items)}
    if times is not None and len(times) >= 2:
        details["guaranteed_between_samples"] = float(np.min(low))
        details["spacing_s"] = float(np.max(np.diff(times)))
    return float(np.min(slack(scene, low))), details


def start(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """The start of one optimisation: a random motion (:func:`random_start`); for a
    derivative-free run (closed loops), the best feasible of CANDIDATES random motions
    filling LOOP_FILL of their limits (a random motion there is often numerically rank
    deficient, where the criterion is flat)."""
    if problem.model.differentiable and not problem.mechanism.loops:
        return clear_start(problem, random_start(problem, rng))
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


def clear_start(problem: Problem, x: np.ndarray) -> np.ndarray:
    """``x`` with the largest oscillation (a factor in [0, 1], by bisection) that keeps the
    clearance and the optimiser's reserve at every sample: a start in collision leaves SLSQP
    restoring feasibility through nonsmooth minima instead of optimising."""
    scene = problem.scene
    if scene is None or not scene.checks:
        return x
    def clear(factor: float) -> bool:
        q = problem.form.motion(shrink(problem, x, factor), problem.times())[0]
        return bool(np.min(slack(scene, scene.distances(q)[0])) >= problem.buffer)

    if clear(1.0):
        return x
    lo, hi = 0.0, 1.0
    for _ in range(8):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if clear(mid) else (lo, mid)
    return shrink(problem, x, lo)


def random_start(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """A random motion at rest at both ends, centred in the ranges, filling START_FILL of
    its tightest limit."""
    form, lim = problem.form, problem.limits
    L = form.harmonics
    f = len(form.names)
    coefficients = np.zeros((f, 2 * L + 1))
    coefficients[:, 0] = clear_centre(problem, rng)
    decay = 1.0 / np.arange(1, L + 1)
    coefficients[:, 1:L + 1] = rng.standard_normal((f, L)) * decay
    coefficients[:, L + 1:] = rng.standard_normal((f, L)) * decay
    x = form.variables(coefficients)
    return scale_to_limits(problem, x, START_FILL)


CENTRE_CANDIDATES = 64       # configurations tried for a start's centre when collisions are checked
ROOM = 0.3                   # m of distance a start's centre needs, no more


def clear_centre(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """A start's centre: the centre of the ranges, or with collisions checked the
    configuration (of CENTRE_CANDIDATES random ones in the middle half of the ranges, and the
    centre) farthest from any collision, up to ROOM (of those, the nearest the centre): a
    UR5 at zero has its wrist at the floor, and a start needs room to move."""
    lim = problem.limits
    centre = (lim.lower + lim.upper) / 2
    scene = problem.scene
    if scene is None or not scene.checks:
        return centre
    half = (lim.upper - lim.lower) / 4
    candidates = np.vstack([centre, centre + rng.uniform(-1, 1, (CENTRE_CANDIDATES, len(centre))) * half])
    distance = np.minimum(slack(scene, scene.distances(candidates)[0]), ROOM)
    best = distance >= np.max(distance) - 1e-9
    gap = np.linalg.norm((candidates - centre) / np.maximum(half, 1e-12), axis=1)
    return candidates[int(np.argmin(np.where(best, gap, np.inf)))]


def scale_to_limits(problem: Problem, x: np.ndarray, fill: float) -> np.ndarray:
    """``x`` with its oscillation scaled so that position, velocity and acceleration use at
    most ``fill`` of their limits (the centre kept)."""
    form, lim = problem.form, problem.limits
    coefficients = form.coefficients(x)
    centre = coefficients[:, 0]
    q, qd, qdd = form.motion(x, problem.times())
    ratios = [np.max(np.abs(q - centre), axis=0) / np.minimum(centre - lim.lower, lim.upper - centre),
              np.max(np.abs(qd), axis=0) / lim.velocity, np.max(np.abs(qdd), axis=0) / lim.acceleration,
              np.max(np.abs(form.jerk(x, problem.times())), axis=0) / lim.jerk]
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
    """(G, h): position, velocity, acceleration and jerk limits (shrunk by SAFETY) as
    G x + h >= 0; a limit that is not given (inf) has no rows."""
    form, lim = problem.form, problem.limits
    rows = form.rows(problem.times()) + (form.jerk_rows(problem.times()),)
    f, m = len(form.names), form.per_coordinate
    half = (lim.upper - lim.lower) / 2
    blocks, offsets = [], []
    bounds = [(lim.upper - SAFETY * half, lim.lower + SAFETY * half),
              ((1 - SAFETY) * lim.velocity, -(1 - SAFETY) * lim.velocity),
              ((1 - SAFETY) * lim.acceleration, -(1 - SAFETY) * lim.acceleration),
              ((1 - SAFETY) * lim.jerk, -(1 - SAFETY) * lim.jerk)]
    for phi, (upper, lower) in zip(rows, bounds):
        for j in range(f):
            if not (math.isfinite(upper[j]) and math.isfinite(lower[j])):
                continue
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


FAR = 3.0                    # a trial this many ranges or velocity limits out is not evaluated


def far_outside(lim: Limits, q: np.ndarray, qd: np.ndarray) -> bool:
    """A trial point far outside the position ranges or velocity limits: SLSQP's line search
    may probe one, and a closed loop's Newton on it can take minutes and gigabytes."""
    half = (lim.upper - lim.lower) / 2
    centre = (lim.upper + lim.lower) / 2
    return bool(np.any(np.abs(q - centre) > FAR * half) or np.any(np.abs(qd) > FAR * lim.velocity))


Report = Callable[[int, float], None]
REPORT_EVERY = 10            # iterations between two progress reports of a start


def optimise(problem: Problem, x0: np.ndarray, report: Report | None = None) -> Outcome:
    """One local optimisation from ``x0``: SLSQP with gradients (open chains) or COBYLA.
    ``report(iteration, criterion)``: called at the first iteration and every REPORT_EVERY."""
    if problem.model.differentiable:
        return _slsqp(problem, x0, report)
    return _cobyla(problem, x0, report)


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


def _slsqp(problem: Problem, x0: np.ndarray, report: Report | None = None) -> Outcome:
    form, lim, model = problem.form, problem.limits, problem.model
    t = problem.times()
    rows = form.rows(t)
    G, h = _linear_constraints(problem)
    torque_limited = model.phi is not None and np.any(np.isfinite(lim.torque))

    def evaluate(x: np.ndarray) -> dict[str, Any]:
        q, qd, qdd = form.motion(x, t)
        if far_outside(lim, q, qd):        # a line search's wild trial: not worth evaluating
            return dict(f=PENALTY, g=np.zeros_like(x), columns=None)
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

    groups = G.shape[0] // len(t)
    Gg = G.reshape(groups, len(t), -1)

    def linear(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _block_min((G @ x + h).reshape(groups, len(t)), Gg)

    linear_at = _LastPoint(linear)
    constraints: list[dict[str, Any]] = [{"type": "ineq", "fun": lambda x: linear_at(x)[0],
                                          "jac": lambda x: linear_at(x)[1]}] if groups else []
    if torque_limited:
        finite = np.isfinite(lim.torque)
        bound = (1 - SAFETY) * lim.torque[finite]

        def torque_both(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            columns = evaluate_at(x)["columns"]
            blocks = 2 * int(finite.sum()) * -(-len(t) // BLOCK)
            if columns is None:
                return -np.ones(blocks), np.zeros((blocks, x.size))
            tau = columns.torque[:, finite].T                                     # (fT, N)
            d = _per_sample(problem, columns.torque_tangents, rows)[:, finite].transpose(1, 0, 2)
            values = np.concatenate([bound[:, None] - tau, bound[:, None] + tau])
            return _block_min(values, np.concatenate([-d, d]))

        torque_at = _LastPoint(torque_both)
        constraints.append({"type": "ineq", "fun": lambda x: torque_at(x)[0], "jac": lambda x: torque_at(x)[1]})
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
    if problem.scene is not None and problem.scene.checks:
        constraints.append(_collision_constraint(problem, rows[0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = scipy.optimize.minimize(objective, x0, jac=True, method="SLSQP", constraints=constraints,
                                         options={"maxiter": problem.maxiter, "ftol": FTOL},
                                         callback=_callback(report, lambda x: evaluate_at(x)["f"]))
    x = result.x
    q, qd, qdd = form.motion(x, t)
    final = check(problem, q, qd, qdd)
    return Outcome(x, final.value, final.feasible, bool(result.success), str(result.message),
                   int(getattr(result, "nit", 0)), evaluate_at.count)


FTOL = 1e-4
BLOCK = 5                    # a limit's constraint is its smallest margin over this many samples


def _block_min(values: np.ndarray, jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per group (rows of ``values`` (g, N)) the smallest value over each BLOCK consecutive
    samples, and its row of ``jac`` (g, N, n): SLSQP's subproblem grows with the number of
    constraints, and neighbouring samples of a smooth motion are rarely both active."""
    g, count = values.shape
    blocks = -(-count // BLOCK)
    padded = np.full((g, blocks * BLOCK), np.inf)
    padded[:, :count] = values
    index = np.argmin(padded.reshape(g, blocks, BLOCK), axis=2) + np.arange(blocks) * BLOCK
    rows = np.arange(g)[:, None]
    return values[rows, index].ravel(), jac[rows, index].reshape(g * blocks, -1)


def _callback(report: Report | None, value: Callable[[np.ndarray], float]) -> Callable[[np.ndarray], None] | None:
    """scipy's per-iteration callback, reporting the first iteration and every REPORT_EVERY."""
    if report is None:
        return None
    count = [0]

    def callback(x: np.ndarray) -> None:
        count[0] += 1
        if count[0] == 1 or count[0] % REPORT_EVERY == 0:
            report(count[0], float(value(x)))
    return callback


def _collision_constraint(problem: Problem, phi_q: np.ndarray) -> dict[str, Any]:
    """Per sample: the smallest distance (self, boxes, planes) minus the clearance and the
    buffer, >= 0, with its Jacobian (the active item's gradient through the form)."""
    scene, t = problem.scene, problem.times()
    f, m = len(problem.form.names), problem.form.per_coordinate

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = problem.form.motion(x, t)[0]
        at, grad, _ = scene.distances(q, gradient=True)
        jac = (grad[:, :, None] * phi_q[:, None, :]).reshape(len(t), f * m)
        return slack(scene, at) - problem.buffer, jac

    at = _LastPoint(evaluate)
    return {"type": "ineq", "fun": lambda x: at(x)[0], "jac": lambda x: at(x)[1]}


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


def _cobyla(problem: Problem, x0: np.ndarray, report: Report | None = None) -> Outcome:
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
        extra = [v for k, v in result.margins.items() if k in ("singularity", "torque", "collision")]
        return np.array(extra or [1.0])

    constraints = [{"type": "ineq", "fun": lambda x: G @ x + h}, {"type": "ineq", "fun": nonlinear}]
    scale = float(np.max(np.abs(problem.form.coefficients(x0)[:, 1:]))) or 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = scipy.optimize.minimize(objective, x0, method="COBYLA", constraints=constraints,
                                         options={"maxiter": problem.maxiter * 5, "rhobeg": 0.2 * scale,
                                                  "tol": 1e-6},
                                         callback=_callback(report, objective))
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
    # without an acceleration limit: the largest the form reaches at the velocity limit
    peak = np.where(np.isfinite(lim.acceleration), lim.acceleration,
                    problem.form.omega * problem.form.harmonics * lim.velocity)
    qdd = rng.uniform(-peak, peak, size=(count, f))
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
