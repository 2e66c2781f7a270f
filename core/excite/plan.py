"""The planner: multistart optimisations, then the written motion verified and reported.

Each start is a job (:class:`ExciteJob`) that ``validate``'s runners run: in this process,
in local worker processes (``--workers``) or on a Dask cluster (``--scheduler``). A job
carries the mechanism file's text, the base model's matrix, the limits and the settings,
so a worker needs nothing else. The best feasible result wins; the written motion (its
coefficients rounded to exact rationals) is checked on a grid ten times finer than the
optimisation's, and its amplitude shrunk until every limit holds there; collisions are
checked there with a bound on what happens between samples, and a plan that comes too near
is optimised again with a larger distance in reserve. The planner never returns a motion
that breaks a limit, never one worse than where it started (the file's trajectory, else
the best start): then it returns that start and says so (``Plan.kept``; the verb exits 1).
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
from baseparams.excite.collision import SceneSpec, build
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
REPAIRS = 3                  # re-optimisations with more distance in reserve after a near collision
BUFFER = 0.01                # m the optimiser keeps beyond the clearance at first

# In this process: where a start reports its iterations (set by :func:`plan` around an
# in-process run; worker processes and Dask report per start only).
_say: Callable[[str], None] | None = None


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
    scene: SceneSpec | None = None   # collision geometry and keep-out, or None: not checked
    buffer: float = BUFFER


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
    scene = None
    if settings.scene is not None:
        scene = build(settings.scene, mechanism, tuple(limits.names), (limits.lower + limits.upper) / 2)
    return design.Problem(model, limits, form, settings.samples, settings.criterion, separate,
                          settings.margin, settings.maxiter, scene, settings.buffer if scene is not None else 0.0)


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
            first = design.check(problem, *problem.form.motion(x0, problem.times()))
            say = _say
            report = None
            if say is not None:
                kind, total = problem.kind, problem.maxiter

                def report(iteration: int, value: float) -> None:
                    figure = f"condition number {math.exp(value):.4g}" if kind == "condition" and value < 700 \
                        else f"criterion {value:.4g}"
                    say(f"{self.label}: iteration {iteration}/{total}, {figure}")
            result = design.optimise(problem, x0, report)
            if first.feasible and (not result.feasible or not result.value < first.value):
                # the local optimiser ended no better than where it started: the start it is
                result = design.Outcome(x0, first.value, True, result.converged,
                                        f"{result.message} (no better than the start: the start is kept)",
                                        result.iterations, result.evaluations)
        except BaseparamsError as exc:
            return Outcome(name, self.solver, ERROR, time.perf_counter() - start, message=str(exc))
        except Exception as exc:                                 # a bug: reported, the others go on
            return Outcome(name, self.solver, INTERNAL, time.perf_counter() - start,
                           message=f"{type(exc).__name__}: {exc}")
        return Outcome(name, self.solver, OK, time.perf_counter() - start, result={
            "x": result.x.tolist(), "value": result.value, "feasible": result.feasible,
            "converged": result.converged, "message": result.message, "iterations": result.iterations,
            "evaluations": result.evaluations, "seed": self.seed, "cpu_s": time.process_time(),
            "x0": x0.tolist(), "start_value": design._finite(first.value) if first.feasible else None})


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
    solver: str = ""                 # whose base the figures are on
    kept: str | None = None          # the start returned instead of a motion not better than it
    assumptions: list = field(default_factory=list)

    @property
    def improved(self) -> bool:
        """The returned motion is the optimised one, better than where it started."""
        return self.kept is None

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
            "solver": self.solver,
            "criterion": p.kind,
            "improved": self.improved,
            "kept": self.kept,
            "assumptions": list(self.assumptions),
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

        on = f" on the {self.solver} solver's base" if self.solver else ""
        lines[0] += on
        lines.append(figures("before (the file's trajectory)", self.before))
        lines.append(figures("after" + (f" (optimised; {self.kept} is returned)" if self.kept else ""), self.after))
        lines.append(figures(f"after, {FINER}x finer sampling", self.finer))
        lines.append(figures(f"{p.samples} independent random states inside the limits", self.random_states))
        lines.append("  margins at the finer sampling (>= 0: the limit holds): " +
                     ", ".join(f"{k} {v:.4g}" for k, v in self.finer.margins.items()))
        c = self.finer.collision
        if c is not None:
            planes = ", ".join(f"{k} {v:.3g} m" for k, v in c["above_planes"].items())
            self_part = (f"between links {c['self_smallest_distance']:.3g} m" if c["self_smallest_distance"] is not None
                         else "self-collision not checked (no collision geometry)")
            lines.append(f"  collisions ({c['pairs']} link pairs, {c['plane_items']} link-plane checks, clearance "
                         f"{c['clearance']:g} m): smallest distance {c['smallest_distance']:.3g} m ({c['where']}), "
                         f"{self_part}; above the planes {planes or '-'}; guaranteed between samples "
                         f"{c['guaranteed_between_samples']:.3g} m")
        else:
            lines.append("  collisions: not checked")
        lines += [f"  assumed: {a}" for a in self.assumptions]
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
         seed: int = 0, rebase: Callable[[Mechanism], BaseModel] | None = None, rounds: int = 3,
         say: Callable[[str], None] | None = None, solver: str = "") -> Plan:
    """Run ``starts`` optimisations on ``runner`` and verify the best feasible one.

    ``rebase(mechanism)``: the base model the solver gives for a mechanism (with the planned
    trajectory). A solver that picks its base parameters from the trajectory's W (dp's
    pivoted QR) may pick other ones on the new motion, and the condition number identify
    reports depends on that choice; so the plan is refined from its best motion on the new
    base, up to ``rounds`` times, until the solver's choice no longer changes, and the figures
    are reported on the base the solver gives for the written file. ``say(message)``: progress
    within each start (in-process runs) and of the verification."""
    global _say
    began = time.perf_counter()
    original = base
    problem, notes = _prepared(mechanism, base, limits, settings)
    summary: list[dict[str, Any]] = []
    converged, x, factor, used = False, None, 1.0, 0
    runner = runner or InProcess()
    best_start: tuple[float, np.ndarray] | None = None
    previous = _say
    _say = say if isinstance(runner, InProcess) else None
    try:
        for round_ in range(rounds if rebase else 1):
            used += 1
            if x is None:
                jobs = [ExciteJob(text, base, limits, settings, seed + k) for k in range(starts)]
            else:
                jobs = [ExciteJob(text, base, limits, settings, seed, tuple(map(float, x)))]
            results, failures = _run(runner, jobs, progress)
            notes += failures
            for r in results:
                if x is None and r.get("start_value") is not None and \
                        (best_start is None or r["start_value"] < best_start[0]):
                    best_start = (r["start_value"], np.array(r["x0"]))
            feasible = [r for r in results if r["feasible"] and math.isfinite(r["value"])]
            summary += [{"round": round_ + 1, **{k: r[k] for k in ("seed", "feasible", "converged", "message",
                                                                    "iterations", "evaluations")},
                         "value": design._finite(r["value"]), "start_value": r.get("start_value")} for r in results]
            if not feasible:
                if x is not None:
                    break
                raise _infeasible(mechanism, bool(results), failures)
            best = min(feasible, key=lambda r: r["value"])
            converged = any(r["converged"] for r in feasible)
            if say:
                say("verifying the best motion on a grid ten times finer")
            x, factor, settings, problem = _verified_clear(problem, np.array(best["x"]), settings, text, base, limits,
                                                           runner, notes, say)
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
    finally:
        _say = previous
    if not converged:
        notes.append("no start converged: the best feasible motion found is returned; more --iterations or "
                     "--starts may improve it")
    assert x is not None                   # set by the first round, or no motion was feasible
    form = problem.form
    after = design.check(problem, *form.motion(x, problem.times()), jerk=form.jerk(x, problem.times()))
    finer = _finer(problem, x)
    was = dataclasses.replace(problem, model=dataclasses.replace(problem.model, base=original))
    before = _file_check(mechanism, problem, was, notes)
    reference = design.independent_states(problem, problem.samples, seed)
    _note_singularity(problem, before, after, notes)
    kept = None
    if before is not None and math.isfinite(before.value) and not after.value < before.value:
        kept = "the file's trajectory"
        notes.append(f"the optimised motion ({_figure(problem, after)}) is not better than the file's own "
                     f"trajectory ({_figure(problem, before)}) on the {solver or 'chosen'} solver's base: the file's "
                     "trajectory is returned unchanged" + ("" if before.feasible else
                                                           f", although it is {before.reason}"))
    elif before is None and best_start is not None and not after.value < best_start[0]:
        start = _better_start(problem, was, best_start[1], after, notes)
        if start is not None:
            kept = "the best start"
            x, problem, after, finer = start
    out = Plan(mechanism.name, problem, x, before, after, finer, reference, summary, converged, factor,
               notes, time.perf_counter() - began)
    out.rounds, out.solver, out.kept = used, solver, kept
    out.assumptions = limits.assumptions()
    return out


def _prepared(mechanism: Mechanism, base: BaseModel, limits: Limits,
              settings: Settings) -> tuple[design.Problem, list[str]]:
    """The problem to optimise and the notes it starts with: the scene's, and which columns a
    separation leaves out because no motion can tell them from the others."""
    problem = problem_of(mechanism, base, limits, settings)
    notes: list[str] = []
    if problem.scene is not None:
        notes += problem.scene.notes
    if problem.separate:
        problem, dropped = _drop_inseparable(problem)
        if dropped:
            notes.append(f"{', '.join(dropped)}: identical to a combination of the other columns on any "
                         "motion (their effect is absorbed, as identify does), left out of the separation")
    return problem, notes


def _infeasible(mechanism: Mechanism, ran: bool, failures: list[str]) -> InputError:
    """Why the first round found no feasible motion: no start ran to its end (``ran`` false:
    the limits are not the cause, issue 46), or every start ended outside the limits."""
    if not ran:
        return InputError(f"no start of the optimisation ran to its end ({'; '.join(failures)}): "
                          "not a matter of the limits", file=mechanism.path, key="--starts")
    reasons = "; ".join(failures) or "every start ended outside the limits"
    return InputError(f"no motion inside the limits was found ({reasons}): widen the limits "
                      "(--max-velocity, --max-acceleration, --max-torque, --position-range, "
                      "--clearance, --keep-out) or lower --harmonics", file=mechanism.path, key="limits")


def _file_check(mechanism: Mechanism, problem: design.Problem, was: design.Problem,
                notes: list[str]) -> design.Check | None:
    """The file's own trajectory checked on the file's base (``was``), to compare the plan
    with; None if the file has none or it cannot be evaluated (then a note says why)."""
    motion = default_motion(mechanism, problem)
    if motion is None:
        return None
    try:
        return design.check(was, *motion)
    except KinematicsError as exc:
        notes.append(f"the file's trajectory cannot be evaluated: {exc}")
        return None


def _note_singularity(problem: design.Problem, before: design.Check | None, after: design.Check,
                      notes: list[str]) -> None:
    """Say so when the file's trajectory beats the plan's condition number by coming nearer a
    singular configuration than the margin allows the plan to."""
    if before is not None and "singularity" in before.margins and before.margins["singularity"] < 0 \
            and after.condition > before.condition / 10:
        nearest = before.margins["singularity"] + problem.margin
        notes.append(f"the file's trajectory comes nearer a singular configuration (1/cond of the closure "
                     f"Jacobian {nearest:.3g}) than the margin {problem.margin:g} allows: where the weakest base "
                     "columns are excited only near it, the condition number is bounded by how near the motion "
                     "may come (a smaller --singularity-margin lets it come nearer)")


def _better_start(problem: design.Problem, was: design.Problem, best_start: np.ndarray, after: design.Check,
                  notes: list[str]) -> tuple[np.ndarray, design.Problem, design.Check, design.Check] | None:
    """The best start (x, its problem, check and finer check) if it is at least as good as the
    optimised motion and feasible on the finer grid, else None: an optimiser that ends worse
    than where it began should not be trusted over its start."""
    form = problem.form
    start_x = form.rounded(best_start)
    start_check = design.check(was, *form.motion(start_x, problem.times()))
    if not (start_check.value <= after.value and _finer(was, start_x).feasible):
        return None
    notes.append(f"the optimised motion ({_figure(problem, after)}) is not better than the best start "
                 f"({_figure(problem, start_check)}): that start is returned")
    return start_x, was, start_check, _finer(was, start_x)


def _figure(problem: design.Problem, c: design.Check) -> str:
    if problem.kind == "condition" or problem.kind == "d-optimal":
        return f"condition number {c.condition:.4g}" + ("" if problem.kind == "condition" else
                                                        f", criterion {c.value:.4g}")
    return f"criterion {c.value:.4g}"


def _run(runner: StartRunner, jobs: list[ExciteJob], progress: Progress | None) -> tuple[list[dict], list[str]]:
    outcomes = runner.run(jobs, progress=progress)
    results = [o.result for o in outcomes if o.status == OK and o.result]
    failures = [f"start {job.seed}: {o.status}: {o.message}" for job, o in zip(jobs, outcomes) if o.status != OK]
    return results, failures


def _finer(problem: design.Problem, x: np.ndarray) -> design.Check:
    """The checks on the grid FINER times the optimisation's, collisions between samples too."""
    t = problem.times(FINER)
    return design.check(problem, *problem.form.motion(x, t), jerk=problem.form.jerk(x, t), times=t,
                        motion=lambda times: problem.form.motion(x, times))


def _verified_clear(problem: design.Problem, x: np.ndarray, settings: Settings, text: MechanismText,
                    base: BaseModel, limits: Limits, runner: StartRunner, notes: list[str],
                    say: Callable[[str], None] | None) -> tuple[np.ndarray, float, Settings, design.Problem]:
    """:func:`_verified`, then the collision check between the finer samples: a motion that
    comes nearer than the clearance there is optimised again from itself with that much
    more distance in reserve (REPAIRS times at most)."""
    x, factor = _verified(problem, x)
    if problem.scene is None or not problem.scene.checks:
        return x, factor, settings, problem
    for attempt in range(REPAIRS + 1):
        finer = _finer(problem, x)
        short = finer.margins.get("collision", 0.0)
        if short >= 0:
            return x, factor, settings, problem
        if attempt == REPAIRS:
            break
        settings = dataclasses.replace(settings, buffer=settings.buffer - short + 0.005)
        notes.append(f"the motion came {-short:.3g} m nearer than the clearance between samples: optimised "
                     f"again with {settings.buffer:.3g} m in reserve")
        if say:
            say(f"re-optimising with {settings.buffer:.3g} m more distance in reserve")
        results, failures = _run(runner, [ExciteJob(text, base, limits, settings, 0, tuple(map(float, x)))], None)
        problem = dataclasses.replace(problem, buffer=settings.buffer)
        feasible = [r for r in results if r["feasible"]]
        if not feasible:
            break
        x, factor = _verified(problem, np.array(feasible[0]["x"]))
    raise InputError("no motion found that keeps the clearance to the keep-out geometry and between the links "
                     "on the finer sampling: lower --clearance, move --keep-out, or narrow --position-range",
                     key="--clearance")


def with_x(mechanism: Mechanism, problem: design.Problem, x: np.ndarray) -> Mechanism:
    """The mechanism with the motion ``x`` as its ``[trajectory]``."""
    period = Fraction(f"{problem.form.period:.12g}")
    spec = TrajectorySpec(problem.form.expressions(x), Fraction(0), period, problem.samples)
    return dataclasses.replace(mechanism, trajectory=spec)


def _verified(problem: design.Problem, x: np.ndarray) -> tuple[np.ndarray, float]:
    """The rounded motion, its amplitude shrunk until every limit (collisions apart: see
    :func:`_verified_clear`) holds on the finer grid."""
    factor = 1.0
    limits_only = dataclasses.replace(problem, scene=None)
    t = problem.times(FINER)
    for _ in range(SHRINK_STEPS):
        candidate = problem.form.rounded(design.shrink(problem, x, factor))
        if design.check(limits_only, *problem.form.motion(candidate, t), jerk=problem.form.jerk(candidate, t)).feasible:
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


CSV_CHUNK = 50_000          # rows computed and written at a time
CSV_BYTES_PER_VALUE = 25    # "%.17g" and a comma, at most about


def write_csv(path: str | Path, mechanism: Mechanism, plan_: Plan, rate: float) -> int:
    """q, qd, qdd of every coordinate at ``rate`` Hz over one period (simulate's layout
    without tau); returns the number of rows. The rows are computed and written CSV_CHUNK at a
    time, after the file's estimated size is checked against the free disk space and the
    file-size limit. Why (issue 46): --period 10000 --rate 100000 (10^9 rows) was built whole
    in memory, a MemoryError at 7.45 GiB; --period 100 reached 3.5 GB before it."""
    start, count = _sample_times(mechanism, plan_, rate)
    names = plan_.problem.form.names
    header = ["t"] + [f"{k}_{c}" for c in names for k in ("q", "qd", "qdd")]
    _check_csv_size(path, count, len(header), rate)
    from baseparams.io.atomic import atomic_path
    with atomic_path(path, "the motion CSV") as temporary:
        with open(temporary, "w", encoding="utf-8", newline="") as out:
            out.write(",".join(header) + "\n")
            for first in range(0, count, CSV_CHUNK):
                t = start + np.arange(first, min(first + CSV_CHUNK, count)) / rate
                q, qd, qdd = _motion(mechanism, plan_, t)
                columns = [t - start] + [a[:, j] for j in range(len(names)) for a in (q, qd, qdd)]
                out.write("".join(",".join(f"{v:.17g}" for v in row) + "\n" for row in zip(*columns)))
    return count


def _check_csv_size(path: str | Path, rows: int, columns: int, rate: float) -> None:
    """Refuse (InputError, with the estimate) a CSV larger than the folder's free space or the
    process's file-size limit, before a row is computed."""
    import shutil
    need = (rows + 1) * columns * CSV_BYTES_PER_VALUE
    folder = Path(path).resolve().parent
    limits = []
    try:
        limits.append((shutil.disk_usage(folder).free, f"the free space in {folder}"))
    except OSError:
        pass
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if soft != resource.RLIM_INFINITY:
            limits.append((soft, "the file-size limit (ulimit -f)"))
    except (ImportError, OSError, ValueError):
        pass
    for limit, what in limits:
        if need > limit:
            raise InputError(f"{rows:,} rows of {columns} columns at {rate:g} Hz: about {need / 1e9:.3g} GB of CSV, "
                             f"more than {what} ({limit / 1e9:.3g} GB): lower --rate or --period",
                             file=str(path))


def _sample_times(mechanism: Mechanism, plan_: Plan, rate: float) -> tuple[float, int]:
    """(the first time, the number of rows) of the motion at ``rate`` Hz over one period."""
    if plan_.kept == "the file's trajectory":
        spec = mechanism.trajectory
        assert spec is not None
        start, end = float(spec.t_start), float(spec.t_end)
        return start, int(math.floor((end - start) * rate + 1e-9)) + 1
    return 0.0, int(math.floor(plan_.problem.form.period * rate + 1e-9)) + 1


def _motion(mechanism: Mechanism, plan_: Plan, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, qd, qdd) of the returned motion at the times ``t`` (the file's own trajectory's
    expressions when the plan keeps it)."""
    if plan_.kept == "the file's trajectory":
        from baseparams.dynamics.trajectory import values_at
        from baseparams.numeric.backends import Float64
        spec = mechanism.trajectory
        assert spec is not None
        values = [values_at(spec.expressions[name], Float64(), t) for name in plan_.problem.form.names]
        q, qd, qdd = (np.stack([np.broadcast_to(np.asarray(v[k], float), t.shape) for v in values], axis=1)
                      for k in range(3))
        return q, qd, qdd
    q, qd, qdd = plan_.problem.form.motion(plan_.x, t)
    return q, qd, qdd


def with_trajectory(mechanism: Mechanism, plan_: Plan) -> Mechanism:
    """The mechanism with the planned motion as its ``[trajectory]`` (unchanged when the
    plan keeps the file's own trajectory)."""
    if plan_.kept == "the file's trajectory":
        return mechanism
    return with_x(mechanism, plan_.problem, plan_.x)


def motion_at(mechanism: Mechanism, plan_: Plan, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, qd, qdd) of the returned motion at ``rate`` Hz over one period (the file's own
    trajectory's expressions when the plan keeps it), t from 0."""
    start, count = _sample_times(mechanism, plan_, rate)
    t = start + np.arange(count) / rate
    q, qd, qdd = _motion(mechanism, plan_, t)
    return t - start, q, qd, qdd


