"""Mechanisms between file formats (``convert``), regressors as Python modules
(``export``), planned motions (``excite``) and the orchestrator's cross-validation
(``validate``): the functions behind those verbs."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

from baseparams import registry
from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism

from .solving import (DEFAULT_SOLVER, MechanismLike, Progress, check_solver_options, chosen_options, get_solver, load,
                      run_solver)

if TYPE_CHECKING:
    from baseparams.formats import Writer

    from .results import Conversion, Excitation, Export, Validation

PathText = Union[str, "PathLike[str]"]
StepProgress = Callable[[int, int, str], None]
READER_OPTIONS = ("merge_fixed", "keep_fixed", "floating_base")
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


def load_physical(path: Any) -> dict[str, str]:
    """The ``"physical"`` table of an identify JSON file (or of the identify result itself, as
    the API takes it wherever the command line takes a result file): parameter name -> decimal
    string."""
    from .data import result_json
    given = result_json(path)
    if given is not None:
        physical = given.get("physical")
        if not isinstance(physical, dict):
            raise InputError("the result has no physical parameters: identify with physical=True (--physical)",
                             key="inertia")
        return physical
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
    (to 1e-9 of its trace). Names in either form: the mechanism's (``m_forearm``) or the
    body label's (``m3``)."""
    from baseparams.model.expressions import ExpressionError, parse_decimal
    from baseparams.model.params import split_name
    given: dict[str, str] = {}
    for name, value in physical.items():
        try:
            _, key = split_name(name)
        except ValueError:
            continue                                 # other identified quantities (friction ...)
        try:
            given[mech.parameter(name)] = value
        except ValueError:
            raise InputError(f"body {key} is not a body of {mech.name} (bodies: "
                             f"{', '.join(map(str, mech.body_keys))})", file=path, key=f"physical.{name}") from None
    bodies = []
    for body in mech.bodies:
        values = []
        for name in mech.body_parameters(body.label):
            if name not in given:
                raise InputError("missing: every body needs its ten parameters", file=path, key=f"physical.{name}")
            try:
                values.append(parse_decimal(given[name]))
            except ExpressionError as exc:
                raise InputError(str(exc), file=path, key=f"physical.{name}") from None
        problem = consistency_problem(values)
        if problem:
            raise InputError(f"body {mech.body_key(body.label)} is not physically consistent: {problem}",
                             file=path, key=f"physical.{mech.body_parameters(body.label)[0]}")
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
            inertia: Any = None, keep_fixed: bool = False) -> "Conversion":
    """Write ``mech`` (a registered name or a file) to ``output`` in the format its suffix
    names (``.toml``, ``.urdf``, a plugin's), atomically. Reader options for URDF:
    ``keep_fixed`` (fixed links stay bodies; by default they are lumped into their parents,
    which ``merge_fixed``, kept for older scripts, also says), ``floating_base``.
    ``inertia``: an ``identify --physical`` JSON whose parameters replace the bodies' (each body checked to be physically consistent)."""
    from baseparams.io.atomic import atomic_path

    from .results import Conversion
    options = {name: True for name, on in (("merge_fixed", merge_fixed), ("keep_fixed", keep_fixed),
                                           ("floating_base", floating_base)) if on}
    if isinstance(mech, Mechanism):
        mechanism, notes = mech, list(mech.warnings)
    else:
        mechanism, notes = read(mech, options)
    if inertia is not None:
        mechanism = with_inertia(mechanism, load_physical(inertia),
                                 inertia if isinstance(inertia, (str, PathLike)) else "the identify result")
    writer = writer_for(output)
    # every writer (a plugin's too) writes to a temporary file renamed over OUTPUT when it
    # is complete: a missing folder, a full disk or a kill never leaves a partial file
    with atomic_path(output) as temporary:
        notes += writer.write(mechanism, str(temporary)) or []
    return Conversion(mechanism, str(output), writer.name, notes)


# ----- export ----------------------------------------------------------------------------
def export(mech: MechanismLike, *, to: str = "python", output: PathText | None = None,
           solver: str = DEFAULT_SOLVER, solver_options: Mapping[str, Any] | None = None,
           common: Mapping[str, Any] | None = None, progress: Progress | None = None, **options: Any) -> "Export":
    """``mech``'s regressor as a standalone numpy module: ``regressor(q, qd, qdd)`` and
    ``base_regressor`` (the columns of ``solver``'s base parameters; ``solver_options`` are the
    solver's, as keyword arguments deprecated; ``common``: ``samples``/``digits``/``seed`` for
    the solvers that declare them; ``progress``: the solver's messages). Written to ``output``
    (atomically) when given; ``.source`` holds the text."""
    from baseparams.dynamics.codegen import export_source
    from baseparams.io.atomic import atomic_write

    from .results import Export, Solution
    if to != "python":
        raise InputError(f"unknown export target {to!r}; known: python", key="--to")
    options = chosen_options(solver_options, options, "export")
    chosen = get_solver(solver)
    check_solver_options(chosen, options, common)
    mechanism = load(mech)
    result = run_solver(chosen, mechanism, options, common=common, progress=progress)
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
           max_torque: str | None = None, max_jerk: str | None = None, velocity_margin: float | None = None,
           singularity_margin: float = 0.03, noise: str | None = None,
           starts: int = 2, workers: int | None = None, scheduler: str | None = None, iterations: int = 200,
           seed: int = 0, csv: PathText | None = None, rate: float = 1000.0, report: PathText | None = None,
           plot: PathText | None = None, collision: bool | None = None, collision_model: str | None = None,
           srdf: str | None = None, package_dirs: Sequence[str] = (), clearance: float | None = None,
           keep_out: Sequence[str] = (), floor: bool = True, progress: StepProgress | None = None,
           say: Progress | None = None, verbose: bool = False) -> "Excitation":
    """Plan a periodic motion of ``mech`` (a finite Fourier series per independent
    coordinate) that minimises the condition number (``criterion="d-optimal"``: maximises
    log det) of the observation matrix on ``solver``'s base columns and the ``effects``'
    columns, under the limits (texts as the command line's options) and, for a URDF with
    Pinocchio installed, away from collisions (``clearance`` m, ``keep_out`` planes and
    boxes, the base plane a floor unless ``floor=False``); ``separate``: effects to tell
    apart instead. ``output``: ``.toml`` writes the mechanism with the motion as its
    ``[trajectory]`` (``result.toml()`` gives the text), ``.csv`` the motion at ``rate``;
    also ``csv``, ``report``, ``plot``. ``result.plan.improved`` is false when the start is
    returned (the optimised motion was not better). ``progress(done, total, label)`` follows
    the starts; ``say`` receives messages, iterations within a start included;
    ``verbose=True``: those messages on stderr (docs/excite.md)."""
    from .planning import excite as run
    return run(mech, output=output, solver=solver, solver_options=solver_options, criterion=criterion,
               harmonics=harmonics, period=period, samples=samples, effects=effects, separate=separate,
               position_range=position_range, max_velocity=max_velocity, max_acceleration=max_acceleration,
               max_torque=max_torque, max_jerk=max_jerk, velocity_margin=velocity_margin,
               singularity_margin=singularity_margin, noise=noise, starts=starts, workers=workers,
               scheduler=scheduler, iterations=iterations, seed=seed, csv=csv, rate=rate, report=report, plot=plot,
               collision=collision, collision_model=collision_model, srdf=srdf, package_dirs=package_dirs,
               clearance=clearance, keep_out=keep_out, floor=floor, progress=progress, say=say, verbose=verbose)


def _is_number(text: str) -> bool:
    try:
        return float(text) == float(text)
    except ValueError:
        return False
