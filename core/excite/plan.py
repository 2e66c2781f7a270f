"""The planner: multistart optimisations, then the written motion verified and reported.

Each start is a job (:class:`ExciteJob`) that ``validate``'s runners run: in this process,
in local worker processes (``--workers``) or on a Dask cluster (``--scheduler``). A job
carries the mechanism file's text, the base model's matrix, the limits and the settings,
so a worker needs nothing else. The best feasible result wins; the written motion (its
coefficients rounded to exact rationals) is checked on a grid ten times finer than the
optimisation's, and its amplitude shrunk until every limit holds there: the planner never
returns a motion that breaks a limit, and says so when no start converged.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol
from fractions import Fraction
from pathlib import Path

import numpy as np

from baseparams.errors import BaseparamsError, InputError, KinematicsError
from baseparams.excite import design
from baseparams.excite.criterion import Model
from baseparams.excite.fourier import FourierForm
from baseparams.excite.limits import Limits
from baseparams.identify.base import BaseModel
from baseparams.dynamics.forces import standard_parameters
from baseparams.model.mechanism import EffectSpec, Mechanism, TrajectorySpec
from baseparams.orchestrate.jobs import ERROR, INTERNAL, OK, MechanismText, Outcome, load
from baseparams.orchestrate.runners import InProcess, Progress

FINER = 10                   # the verification grid is this many times finer
SHRINK = 0.98                # amplitude factor per verification step
SHRINK_STEPS = 400


@dataclass(frozen=True)
class Settings:
    """The planner's options (JSON-able, so a job carries them)."""
    harmonics: int = 5
    period: float = 10.0
    samples: int = 100
    criterion: str = "condition"
    effects: tuple = ()              # ((kind, coordinate), ...) identified with the base parameters
    separate: tuple = ()             # ((kind, coordinate), ...) to tell apart
    margin: float = 0.0
    maxiter: int = 200
    weights: tuple | None = None


def problem_of(mechanism: Mechanism, base: BaseModel, limits: Limits, settings: Settings) -> design.Problem:
    """The optimisation problem of ``settings`` (effects to separate are identified too)."""
    effects = [EffectSpec(k, c) for k, c in settings.effects]
    for kind, coordinate in settings.separate:
        if (kind, coordinate) not in settings.effects:
            effects.append(EffectSpec(kind, coordinate))
    try:
        phi = standard_parameters(mechanism)
    except InputError:
        phi = None
        if np.any(np.isfinite(limits.torque)):
            raise InputError("torque limits need the bodies' inertias, and the file gives none for some "
                             "bodies", file=mechanism.path, key="--max-torque") from None
    weights = None if settings.weights is None else np.array(settings.weights, dtype=float)
    model = Model(mechanism, base, tuple(effects), weights, phi)
    names = model.names
    separate: tuple[int, ...] = ()
    if settings.separate:
        from baseparams import registry
        chosen = set()
        for kind, coordinate in settings.separate:
            chosen |= set(registry.effects()[kind].item.coefficient_names(coordinate))
        separate = tuple(k for k, name in enumerate(names) if name in chosen)
    form = FourierForm(tuple(limits.names), settings.harmonics, settings.period)
    return design.Problem(model, limits, form, settings.samples, settings.criterion, separate,
                          settings.margin, settings.maxiter)


@dataclass(frozen=True)
class ExciteJob:
    """One start of the multistart, as plain data (run by ``validate``'s runners)."""
    mechanism: MechanismText
    base: BaseModel
    limits: Limits
    settings: Settings
    seed: int
    x0: tuple | None = None          # a given start (a later round), else a random one
    solver: str = "excite"

    @property
    def label(self) -> str:
        return f"{self.mechanism.name}/start {self.seed}"

    def execute(self) -> Outcome:
        start = time.perf_counter()
        name = self.mechanism.name
        try:
            problem = problem_of(load(self.mechanism), self.base, self.limits, self.settings)
            x0 = np.array(self.x0) if self.x0 is not None else \
                design.start(problem, np.random.default_rng(self.seed))
            result = design.optimise(problem, x0)
        except BaseparamsError as exc:
            return Outcome(name, self.solver, ERROR, time.perf_counter() - start, message=str(exc))
        except Exception as exc:                                 # a bug: reported, the others go on
            return Outcome(name, self.solver, INTERNAL, time.perf_counter() - start,
                           message=f"{type(exc).__name__}: {exc}")
        return Outcome(name, self.solver, OK, time.perf_counter() - start, result={
            "x": result.x.tolist(), "value": result.value, "feasible": result.feasible,
            "converged": result.converged, "message": result.message, "iterations": result.iterations,
            "evaluations": result.evaluations, "seed": self.seed, "cpu_s": time.process_time()})


@dataclass
class Plan:
    """What ``excite`` found: the motion (``x``, the form), its figures before and after, the
    reference figure of independent random states, the starts and notes."""
    mechanism: str
    problem: design.Problem
    x: np.ndarray
    before: design.Check | None
    after: design.Check
    finer: design.Check
    random_states: design.Check
    starts: list
    converged: bool
    shrink: float
    notes: list = field(default_factory=list)
    seconds: float = 0.0
    rounds: int = 1

    @property
    def expressions(self) -> dict:
        return self.problem.form.expressions(self.x)

    def trajectory(self) -> TrajectorySpec:
        period = Fraction(f"{self.problem.form.period:.12g}")
        return TrajectorySpec(self.expressions, Fraction(0), period, self.problem.samples)

    def to_json(self) -> dict:
        p = self.problem
        return {
            "mechanism": self.mechanism,
            "criterion": p.kind,
            "form": {"kind": "fourier", "harmonics": p.form.harmonics, "period": p.form.period,
                     "coefficients": {name: {"c": str(row[0]), "A": [str(v) for v in row[1:p.form.harmonics + 1]],
                                             "B": [str(v) for v in row[p.form.harmonics + 1:]]}
                                      for name, row in zip(p.form.names, p.form.exact(self.x))}},
            "samples": p.samples,
            "columns": list(p.model.names),
            "separate": [p.model.names[k] for k in p.separate],
            "limits": p.limits.to_json(),
            "limit_sources": p.limits.sources,
            "singularity_margin": p.margin if p.mechanism.loops else None,
            "before": None if self.before is None else self.before.to_json(),
            "after": self.after.to_json(),
            "verified": {**self.finer.to_json(), "samples": FINER * (p.samples - 1) + 1},
            "random_states": {"samples": p.samples, **self.random_states.to_json()},
            "converged": self.converged,
            "base_rounds": self.rounds,
            "amplitude_scale": self.shrink,
            "starts": self.starts,
            "notes": list(self.notes),
            "elapsed_s": round(self.seconds, 3),
        }

    def to_text(self) -> str:
        p = self.problem
        lines = [f"{self.mechanism}: {p.form.harmonics}-harmonic Fourier motion over {p.form.period:g} s, "
                 f"{p.samples} samples, criterion {p.kind} on {len(p.model.names)} columns"]

        def figures(label: str, c: design.Check | None) -> str:
            if c is None:
                return f"  {label}: (no trajectory)"
            extra = f", smallest angle {c.angle:.3g} deg" if c.angle is not None else ""
            ok = "" if c.feasible else f" [{c.reason}]"
            return f"  {label}: condition number {c.condition:.4g}{extra}{ok}"

        lines.append(figures("before (the file's trajectory)", self.before))
        lines.append(figures("after", self.after))
        lines.append(figures(f"after, {FINER}x finer sampling", self.finer))
        lines.append(figures(f"{p.samples} independent random states inside the limits", self.random_states))
        lines.append("  margins at the finer sampling (>= 0: the limit holds): " +
                     ", ".join(f"{k} {v:.4g}" for k, v in self.finer.margins.items()))
        first = [s for s in self.starts if s.get("round", 1) == 1]
        lines.append(f"  starts: {len(first)}, rounds on the solver's new base: {self.rounds}, converged: {'yes' if self.converged else 'no'}"
                     + ("" if self.shrink == 1 else f"; amplitude scaled by {self.shrink:.3g} to keep the limits"))
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


class StartRunner(Protocol):
    """What runs the starts: ``validate``'s runners (in process, processes, Dask), which run
    any picklable job with a ``run()`` (orchestrate's ``Runner`` types its jobs as solver
    jobs; ``Any`` here lets a ``Runner`` be passed)."""

    def run(self, jobs: Sequence[Any], timeout: float | None = None,
            progress: Progress | None = None) -> list[Outcome]: ...


def default_motion(mechanism: Mechanism, problem: design.Problem) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(q, qd, qdd) of the file's own trajectory at its samples, or None."""
    if mechanism.trajectory is None:
        return None
    from baseparams.recordings.simulate import trajectory_motion
    motion = trajectory_motion(mechanism)
    return motion.q, motion.qd, motion.qdd


def plan(mechanism: Mechanism, text: MechanismText, base: BaseModel, limits: Limits, settings: Settings,
         starts: int = 4, runner: StartRunner | None = None, progress: Progress | None = None,
         seed: int = 0, rebase: Callable[[Mechanism], BaseModel] | None = None, rounds: int = 3) -> Plan:
    """Run ``starts`` optimisations on ``runner`` and verify the best feasible one.

    ``rebase(mechanism)``: the base model the solver gives for a mechanism (with the planned
    trajectory). A solver that picks its base parameters from the trajectory's W (dp's
    pivoted QR) may pick other ones on the new motion, and the condition number identify
    reports depends on that choice; so the plan is refined from its best motion on the new
    base, up to ``rounds`` times, until the solver's choice no longer changes, and the figures
    are reported on the base the solver gives for the written file."""
    began = time.perf_counter()
    original = base
    problem = problem_of(mechanism, base, limits, settings)
    notes = []
    if problem.separate:
        problem, dropped = _drop_inseparable(problem)
        if dropped:
            notes.append(f"{', '.join(dropped)}: identical to a combination of the other columns on any "
                         "motion (their effect is absorbed, as identify does), left out of the separation")
    summary, converged, x, factor, used = [], False, None, 1.0, 0
    for round_ in range(rounds if rebase else 1):
        used += 1
        if x is None:
            jobs = [ExciteJob(text, base, limits, settings, seed + k) for k in range(starts)]
        else:
            jobs = [ExciteJob(text, base, limits, settings, seed, tuple(map(float, x)))]
        outcomes = (runner or InProcess()).run(jobs, progress=progress)
        results = [o.result for o in outcomes if o.status == OK and o.result]
        failures = [f"start {job.seed}: {o.status}: {o.message}" for job, o in zip(jobs, outcomes)
                    if o.status != OK]
        notes += failures
        feasible = [r for r in results if r["feasible"] and math.isfinite(r["value"])]
        summary += [{"round": round_ + 1, **{k: r[k] for k in ("seed", "feasible", "converged", "message",
                                                                "iterations", "evaluations")},
                     "value": design._finite(r["value"])} for r in results]
        if not feasible:
            if x is not None:
                break
            reasons = "; ".join(failures) or "every start ended outside the limits"
            raise InputError(f"no motion inside the limits was found ({reasons}): widen the limits "
                             "(--max-velocity, --max-acceleration, --max-torque, --position-range) or "
                             "lower --harmonics", file=mechanism.path, key="limits")
        best = min(feasible, key=lambda r: r["value"])
        converged = any(r["converged"] for r in feasible)
        x, factor = _verified(problem, np.array(best["x"]))
        if rebase is None:
            break
        new = rebase(with_x(mechanism, problem, x))
        if new.rank != base.rank:
            notes.append(f"the {new.solver} solver finds rank {new.rank} on the planned motion, {base.rank} on the "
                         "file's: its rank on one of them is wrong (a certified solver, --solver vp, settles "
                         f"it); the plan keeps the base parameters of rank {base.rank}")
            break
        same = new.names == base.names and np.allclose(new.B, base.B, atol=1e-9)
        base = new
        problem = dataclasses.replace(problem, model=dataclasses.replace(problem.model, base=base))
        if same:
            break
    else:
        if rebase is not None:
            notes.append(f"the solver's choice of base parameters still changed after {rounds} rounds: the "
                         "figures are on the base it gives for the written motion")
    if not converged:
        notes.append("no start converged: the best feasible motion found is returned; more --iterations or "
                     "--starts may improve it")
    assert x is not None                   # set by the first round, or no motion was feasible
    form = problem.form
    after = design.check(problem, *form.motion(x, problem.times()))
    finer = design.check(problem, *form.motion(x, problem.times(FINER)))
    before = None
    motion = default_motion(mechanism, problem)
    if motion is not None:
        was = dataclasses.replace(problem, model=dataclasses.replace(problem.model, base=original))
        try:
            before = design.check(was, *motion)
        except KinematicsError as exc:
            notes.append(f"the file's trajectory cannot be evaluated: {exc}")
    reference = design.independent_states(problem, problem.samples, seed)
    if before is not None and "singularity" in before.margins and before.margins["singularity"] < 0 \
            and after.condition > before.condition / 10:
        nearest = before.margins["singularity"] + problem.margin
        notes.append(f"the file's trajectory comes nearer a singular configuration (1/cond of the closure "
                     f"Jacobian {nearest:.3g}) than the margin {problem.margin:g} allows: where the weakest base "
                     "columns are excited only near it, the condition number is bounded by how near the motion "
                     "may come (a smaller --singularity-margin lets it come nearer)")
    out = Plan(mechanism.name, problem, x, before, after, finer, reference, summary, converged, factor,
               notes, time.perf_counter() - began)
    out.rounds = used
    return out


def with_x(mechanism: Mechanism, problem: design.Problem, x: np.ndarray) -> Mechanism:
    """The mechanism with the motion ``x`` as its ``[trajectory]``."""
    period = Fraction(f"{problem.form.period:.12g}")
    spec = TrajectorySpec(problem.form.expressions(x), Fraction(0), period, problem.samples)
    return dataclasses.replace(mechanism, trajectory=spec)


def _verified(problem: design.Problem, x: np.ndarray) -> tuple[np.ndarray, float]:
    """The rounded motion, its amplitude shrunk until every limit holds on the finer grid."""
    factor = 1.0
    for _ in range(SHRINK_STEPS):
        candidate = problem.form.rounded(design.shrink(problem, x, factor))
        if design.check(problem, *problem.form.motion(candidate, problem.times(FINER))).feasible:
            return candidate, factor
        factor *= SHRINK
    raise InputError("the planned motion could not be made to respect the limits on the finer sampling "
                     "(a limit too tight at the centre of the ranges?)", key="limits")


def _drop_inseparable(problem: design.Problem) -> tuple[design.Problem, list]:
    """Effect columns that are a combination of the columns before them on two unrelated
    random motions (a spring's constant column and an offset) are left out of the model, as
    identify absorbs them, and out of the set to separate."""
    rng = np.random.default_rng(12345)
    model = problem.model
    rank = model.base.rank
    dependent = None
    for _ in range(2):
        x = design.random_start(problem, rng)
        q, qd, qdd = problem.form.motion(x, problem.times())
        matrix = model.columns(q, qd, qdd).matrix
        A = matrix.reshape(-1, matrix.shape[-1])
        A = A / np.maximum(np.linalg.norm(A, axis=0), 1e-300)
        kept, found = list(range(rank)), set()
        for k in range(rank, A.shape[1]):
            coef, *_ = np.linalg.lstsq(A[:, kept], A[:, k], rcond=None)
            if np.linalg.norm(A[:, k] - A[:, kept] @ coef) < 1e-8:
                found.add(k)
            else:
                kept.append(k)
        dependent = found if dependent is None else dependent & found
    if not dependent:
        return problem, []
    names = model.names
    chosen = [names[k] for k in problem.separate]
    new_model = dataclasses.replace(model, drop=tuple(sorted(dependent)))
    separate = tuple(k for k, name in enumerate(new_model.names) if name in chosen)
    if not separate:
        raise InputError("the effects to separate are identical to the other columns on every motion",
                         key="--separate")
    return dataclasses.replace(problem, model=new_model, separate=separate), [names[k] for k in sorted(dependent)]


def write_csv(path: str | Path, problem: design.Problem, x: np.ndarray, rate: float) -> int:
    """q, qd, qdd of every coordinate at ``rate`` Hz over one period (simulate's layout
    without tau); returns the number of rows."""
    period = problem.form.period
    count = int(math.floor(period * rate + 1e-9)) + 1
    t = np.arange(count) / rate
    q, qd, qdd = problem.form.motion(x, t)
    header = ["t"] + [f"{k}_{c}" for c in problem.form.names for k in ("q", "qd", "qdd")]
    columns = [t] + [a[:, j] for j in range(len(problem.form.names)) for a in (q, qd, qdd)]
    from baseparams.io.atomic import atomic_write
    body = "\n".join(",".join(f"{v:.17g}" for v in row) for row in zip(*columns))
    atomic_write(path, ",".join(header) + "\n" + body + "\n", "the motion CSV")
    return count


def with_trajectory(mechanism: Mechanism, plan_: Plan) -> Mechanism:
    """The mechanism with the planned motion as its ``[trajectory]``."""
    return with_x(mechanism, plan_.problem, plan_.x)
