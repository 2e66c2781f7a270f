"""Mechanisms between file formats (``convert``), regressors as Python modules
(``export``), planned motions (``excite``) and the orchestrator's cross-validation
(``validate``): the functions behind those verbs."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

from baseparams import registry
from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism

from .solving import DEFAULT_SOLVER, MechanismLike, Progress, check_solver_options, get_solver, load, run_solver

if TYPE_CHECKING:
    from baseparams.formats import Writer

    from .results import Conversion, Excitation, Export, Validation

PathText = Union[str, "PathLike[str]"]
StepProgress = Callable[[int, int, str], None]
READER_OPTIONS = ("merge_fixed", "floating_base")
CONSISTENCY_TOLERANCE = 1e-9        # relative to the trace: eigenvalues of the COM inertia above -tol


def read(mech: PathText, options: Mapping[str, bool]) -> tuple[Mechanism, list[str]]:
    """The mechanism (mobility checked) and its reader's notes, with reader options."""
    from baseparams.io.loader import check_mobility, reader_for, resolve
    if not options and not Path(mech).suffix:
        return resolve(mech), []
    mech = str(mech)
    reader = reader_for(mech)
    if not Path(mech).exists():
        raise InputError("no such file", file=mech)
    for name in options:
        if name not in reader.options:
            raise InputError(f"the {reader.name} reader has no --{name.replace('_', '-')} option")
    mechanism, notes = reader.read_notes(mech, **options)
    check_mobility(mechanism)
    return mechanism, list(notes) + list(mechanism.warnings)


def writer_for(path: PathText) -> "Writer":
    """The registered writer of ``path``'s suffix, or an InputError listing the known ones."""
    suffix = Path(path).suffix.lower()
    writers = {s.lower(): reg.item for reg in registry.writers().values() for s in reg.item.suffixes}
    if suffix not in writers:
        raise InputError(f"no writer for files ending in {suffix!r} (known: {', '.join(sorted(writers)) or 'none'})",
                         file=path)
    return writers[suffix]


def load_physical(path: PathText) -> dict[str, str]:
    """The ``"physical"`` table of an identify JSON file: parameter name -> decimal string."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON file: {exc}", file=path) from None
    physical = data.get("physical") if isinstance(data, dict) else None
    if not isinstance(physical, dict):
        raise InputError("needs a \"physical\" object (parameter name -> decimal string), as "
                         "`baseparams identify ... --physical --format json` writes", file=path, key="physical")
    return physical


def with_inertia(mech: Mechanism, physical: Mapping[str, str], path: PathText) -> Mechanism:
    """``mech`` with every body's ten parameters taken from ``physical`` (exact decimals),
    each set checked: mass >= 0 and the inertia at the centre of mass positive semidefinite
    (to 1e-9 of its trace)."""
    from baseparams.model.expressions import ExpressionError, parse_decimal
    from baseparams.model.params import body_parameter_names, split_name
    labels = set(mech.body_labels)
    for name in physical:
        try:
            _, label = split_name(name)
        except ValueError:
            continue                                 # other identified quantities (friction ...)
        if label not in labels:
            raise InputError(f"body {label} is not a body of {mech.name} (bodies: {sorted(labels)})",
                             file=path, key=f"physical.{name}")
    bodies = []
    for body in mech.bodies:
        values = []
        for name in body_parameter_names(body.label):
            if name not in physical:
                raise InputError("missing: every body needs its ten parameters", file=path, key=f"physical.{name}")
            try:
                values.append(parse_decimal(physical[name]))
            except ExpressionError as exc:
                raise InputError(str(exc), file=path, key=f"physical.{name}") from None
        problem = consistency_problem(values)
        if problem:
            raise InputError(f"body {body.label} is not physically consistent: {problem}", file=path,
                             key=f"physical.m{body.label}")
        bodies.append(dataclasses.replace(body, inertia=tuple(values)))
    return dataclasses.replace(mech, bodies=tuple(bodies))


def consistency_problem(phi: Sequence[Any]) -> str | None:
    """Why ten parameters (about the body origin) are not a physical body, or None."""
    import numpy as np

    from baseparams.model.params import PARAMETER_KINDS
    m, h = phi[0], phi[1:4]
    if m < 0:
        return f"negative mass {float(m):g}"
    if m == 0:
        return "zero mass with a nonzero first moment" if any(h) else None
    kinds = dict(zip(PARAMETER_KINDS, (float(v) for v in phi)))
    c = np.array([float(v / m) for v in h])
    origin = np.array([[kinds["Ixx"], kinds["Ixy"], kinds["Ixz"]], [kinds["Ixy"], kinds["Iyy"], kinds["Iyz"]],
                       [kinds["Ixz"], kinds["Iyz"], kinds["Izz"]]])
    at_com = origin - float(m) * (c @ c * np.eye(3) - np.outer(c, c))
    smallest = np.linalg.eigvalsh(at_com)[0]
    if smallest < -CONSISTENCY_TOLERANCE * max(np.trace(at_com), np.finfo(float).tiny):
        return f"the inertia at the centre of mass has a negative eigenvalue ({smallest:.3g})"
    return None


# ----- convert ---------------------------------------------------------------------------
def convert(mech: MechanismLike, output: PathText, *, merge_fixed: bool = False, floating_base: bool = False,
            inertia: PathText | None = None) -> "Conversion":
    """Write ``mech`` (a registered name or a file) to ``output`` in the format its suffix
    names (``.toml``, ``.urdf``, a plugin's), atomically. Reader options for URDF:
    ``merge_fixed``, ``floating_base``. ``inertia``: an ``identify --physical`` JSON whose
    parameters replace the bodies' (each body checked to be physically consistent)."""
    from baseparams.io.atomic import atomic_path

    from .results import Conversion
    options = {name: True for name, on in (("merge_fixed", merge_fixed), ("floating_base", floating_base)) if on}
    if isinstance(mech, Mechanism):
        mechanism, notes = mech, list(mech.warnings)
    else:
        mechanism, notes = read(mech, options)
    if inertia is not None:
        mechanism = with_inertia(mechanism, load_physical(inertia), inertia)
    writer = writer_for(output)
    # every writer (a plugin's too) writes to a temporary file renamed over OUTPUT when it
    # is complete: a missing folder, a full disk or a kill never leaves a partial file
    with atomic_path(output) as temporary:
        notes += writer.write(mechanism, str(temporary)) or []
    return Conversion(mechanism, str(output), writer.name, notes)


# ----- export ----------------------------------------------------------------------------
def export(mech: MechanismLike, *, to: str = "python", output: PathText | None = None,
           solver: str = DEFAULT_SOLVER, common: Mapping[str, Any] | None = None, **options: Any) -> "Export":
    """``mech``'s regressor as a standalone numpy module: ``regressor(q, qd, qdd)`` and
    ``base_regressor`` (the columns of ``solver``'s base parameters; ``options`` are the
    solver's; ``common``: ``samples``/``digits``/``seed`` for the solvers that declare them). Written to ``output`` (atomically) when given; ``.source`` holds the text."""
    from baseparams.dynamics.codegen import export_source
    from baseparams.io.atomic import atomic_write

    from .results import Export, Solution
    if to != "python":
        raise InputError(f"unknown export target {to!r}; known: python", key="--to")
    chosen = get_solver(solver)
    check_solver_options(chosen, options, common)
    mechanism = load(mech)
    result = run_solver(chosen, mechanism, options, common=common)
    source = export_source(mechanism, result)
    if output is not None:
        atomic_write(output, source)            # a full disk or a kill keeps the old module whole
    return Export(source, Solution(result, mechanism), None if output is None else str(output))


# ----- validate --------------------------------------------------------------------------
def validate(mechs: Sequence[str] = (), *, solvers: Sequence[str] | None = None, workers: int | None = None,
             scheduler: str | None = None, timeout: float | None = None,
             progress: StepProgress | None = None) -> "Validation":
    """Cross-validate ``solvers`` (default: every registered one) on ``mechs`` (registered
    names or files; ``()``: every registered mechanism): every applicable solver runs, the
    model is checked in ball arithmetic, the results are compared. ``result.ok`` is true
    when everything agrees. ``workers``/``scheduler``: local processes or a Dask cluster."""
    from baseparams.orchestrate.runners import make_runner
    from baseparams.orchestrate.validate import mechanism_texts, select_solvers, validate as run_validation

    from .results import Validation
    names = list(mechs) or list(registry.mechanisms())
    chosen = select_solvers(list(solvers) if solvers else None)
    texts = mechanism_texts(names)
    runner = make_runner(workers, scheduler)
    return Validation(run_validation(texts, chosen, runner=runner, timeout=timeout, progress=progress))


# ----- excite ----------------------------------------------------------------------------
def excite(mech: MechanismLike, *, output: PathText | None = None, solver: str = DEFAULT_SOLVER,
           solver_options: Mapping[str, Any] | None = None, criterion: str = "condition", harmonics: int = 5,
           period: float = 10.0, samples: int = 100, effects: Sequence[str] = (), separate: str | None = None,
           position_range: str | None = None, max_velocity: str | None = None, max_acceleration: str | None = None,
           max_torque: str | None = None, singularity_margin: float = 0.03, noise: str | None = None,
           starts: int = 4, workers: int | None = None, scheduler: str | None = None, iterations: int = 200,
           seed: int = 0, csv: PathText | None = None, rate: float = 1000.0, report: PathText | None = None,
           plot: PathText | None = None, progress: StepProgress | None = None,
           say: Progress | None = None) -> "Excitation":
    """Plan a periodic motion of ``mech`` (a finite Fourier series per independent
    coordinate) that minimises the condition number (``criterion="d-optimal"``: maximises
    log det) of the observation matrix on ``solver``'s base columns and the ``effects``'
    columns, under the limits (texts as the command line's options); ``separate``: effects
    to tell apart instead. Writes the mechanism with the motion as its ``[trajectory]`` to
    ``output`` when given (``result.toml()`` gives the text) and ``csv``, ``report``, ``plot``.
    ``progress(done, total, label)`` follows the starts; ``say`` receives messages."""
    from baseparams.excite import plan as planner
    from baseparams.excite.limits import limits_of
    from baseparams.identify.base import BaseModel
    from baseparams.dynamics.forces import independent_names
    from baseparams.io.atomic import atomic_write
    from baseparams.orchestrate.jobs import MechanismText
    from baseparams.orchestrate.runners import make_runner

    from .effects import parse_effect, parse_separate
    from .results import Excitation
    if samples < 10:
        raise InputError(f"{samples} samples: the optimisation needs at least 10 per period", key="--samples")
    chosen = get_solver(solver)
    check_solver_options(chosen, solver_options or {})
    mechanism = load(mech)
    if not mechanism.path:
        raise InputError("the mechanism has no file to plan for", key="MECH")
    names = independent_names(mechanism)
    parsed_effects = []
    for effect in effects:
        spec = parse_effect(effect, mechanism, values=False)
        parsed_effects.append((spec.kind, spec.coordinate))
    pairs = parse_separate(separate, mechanism) if separate else ()
    weights = None
    if noise is not None:
        sd = [float(v) for v in noise.split(",")] if all(_is_number(v) for v in noise.split(",")) else None
        if sd is None or any(v <= 0 for v in sd) or len(sd) not in (1, len(names)):
            raise InputError(f"expected one positive SD or {len(names)} ({', '.join(names)})", key="--noise")
        weights = tuple(1 / v for v in (sd * len(names) if len(sd) == 1 else sd))
    if mechanism.loops and mechanism.trajectory is not None:
        # closed loops: the file's trajectory is known to stay in the reachable range
        ranges, velocities, accelerations = _trajectory_limits(mechanism, names)
        position_range = position_range or ranges
        max_velocity = max_velocity or velocities
        max_acceleration = max_acceleration or accelerations
    limits = limits_of(mechanism, positions=position_range, velocity=max_velocity,
                       acceleration=max_acceleration, torque=max_torque)
    if say is not None:
        say(f"base parameters ({solver})")
    base = BaseModel.from_result(run_solver(chosen, mechanism, solver_options), mechanism)
    settings = planner.Settings(harmonics=harmonics, period=period, samples=samples,
                                criterion="separation" if pairs else criterion, effects=tuple(parsed_effects),
                                separate=pairs, margin=singularity_margin if mechanism.loops else 0.0,
                                maxiter=iterations, weights=weights)
    text = MechanismText.read(mechanism.name, Path(mechanism.path))
    runner = make_runner(workers, scheduler)

    def rebase(planned: Mechanism) -> BaseModel:
        return BaseModel.from_result(run_solver(chosen, planned, solver_options), planned)

    try:
        found = planner.plan(mechanism, text, base, limits, settings, starts=starts, runner=runner,
                             progress=progress, seed=seed, rebase=rebase)
    finally:
        close = getattr(runner, "close", None)
        if close:
            close()
    result = Excitation(found, mechanism, None if output is None else str(output))
    if output is not None:
        atomic_write(output, result.toml(), "the planned mechanism file")
    if csv:
        result.extra["csv"] = {"path": str(csv), "rate": rate,
                               "rows": planner.write_csv(Path(csv), found.problem, found.x, rate)}
        result.written.append(str(csv))
    if report:
        atomic_write(report, json.dumps(result.to_json(), indent=2) + "\n", "the report")
        result.written.append(str(report))
    if plot:
        from baseparams.excite.plot import plot_plan
        plot_plan(found, Path(plot))
        result.written.append(str(plot))
    return result


def _is_number(text: str) -> bool:
    try:
        return float(text) == float(text)
    except ValueError:
        return False


def _trajectory_limits(mechanism: Mechanism, names: Sequence[str]) -> tuple[str | None, str | None, str | None]:
    """Closed loops: the position range, peak velocity and peak acceleration of the file's
    trajectory (its positions are known to close), as option texts."""
    import numpy as np

    from baseparams.recordings.simulate import trajectory_motion
    motion = trajectory_motion(mechanism)
    lo, hi = motion.q.min(axis=0), motion.q.max(axis=0)
    ranges = ",".join(f"{n}={float(a)!r}:{float(b)!r}" for n, a, b in zip(names, lo, hi) if a < b) or None
    peaks = [",".join(f"{n}={_up(v)!r}" for n, v in zip(names, np.max(np.abs(values), axis=0)) if v > 0)
             or None for values in (motion.qd, motion.qdd)]
    return ranges, peaks[0], peaks[1]


def _up(value: float) -> float:
    """``value`` rounded up to two significant digits."""
    scale = 10.0 ** (math.floor(math.log10(value)) - 1)
    return math.ceil(value / scale - 1e-9) * scale
