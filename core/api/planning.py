"""``excite`` end to end (the functions behind ``bp.excite`` and the verb, ``--check`` too;
the API's floor, above :mod:`baseparams.excite`): the options read
into limits, the collision scene and the planner's settings; the plan run; the output
written by its suffix (``.toml``: the mechanism with its ``[trajectory]``; ``.csv``: the
motion at ``rate``)."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism

from .effects import parse_effect, parse_separate
from .results import Excitation
from .solving import check_solver_options, get_solver, load, run_solver

if TYPE_CHECKING:
    from baseparams.excite.collision import SceneSpec

OUTPUT_SUFFIXES = (".toml", ".csv")


def output_kind(output: str | None) -> str | None:
    """``toml`` or ``csv`` from the output's suffix (as ``convert -o`` picks its writer);
    another suffix is an input error."""
    if output is None:
        return None
    suffix = Path(str(output)).suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise InputError(f"{suffix or 'no suffix'}: excite writes .toml (the mechanism with the motion as its "
                         "[trajectory]) or .csv (t, q_, qd_, qdd_ at --rate)", file=str(output), key="-o")
    return suffix[1:]


def stderr_say(message: str) -> None:
    """Progress for the Python API's ``verbose=True``: one line on stderr."""
    print(f"excite: {message}", file=sys.stderr, flush=True)


def scene_spec(mechanism: Mechanism, *, collision: bool | None, collision_model: str | None, srdf: str | None,
               package_dirs: Sequence[str], clearance: float, keep_out: Sequence[str], floor: bool,
               notes: list[str]) -> "SceneSpec | None":
    """The collision scene's description, or None (said in ``notes``): checked by default
    when the geometry's URDF is known (MECH itself, or ``collision_model``) and Pinocchio is
    installed; ``collision=True`` makes a missing one an error."""
    from baseparams.excite.collision import SceneSpec, available, parse_keep_out
    if not (clearance >= 0 and math.isfinite(clearance)):
        raise InputError(f"{clearance!r}: a distance >= 0 in metres", key="--clearance")
    planes, boxes = parse_keep_out(keep_out, floor)
    for path, key in ((srdf, "--srdf"), (collision_model, "--collision-model")):
        if path is not None and not Path(path).is_file():
            raise InputError("no such file", file=str(path), key=key)
    urdf = collision_model or (mechanism.path if mechanism.path and str(mechanism.path).lower().endswith(".urdf")
                               else None)
    if collision is False:
        notes.append("collisions not checked (--no-collision)")
        return None
    if urdf is None:
        reason = ("MECH is not a URDF and no --collision-model names the robot's URDF: collisions and the "
                  "keep-out geometry are not checked")
        if collision:
            raise InputError(reason, file=mechanism.path, key="--collision")
        notes.append(reason)
        return None
    missing = available()
    if missing is not None:
        if collision:
            raise InputError(missing, key="--collision")
        notes.append(f"{missing}: collisions are not checked")
        return None
    if mechanism.loops:
        notes.append("closed loops: the collision check is not supported, collisions are not checked")
        return None
    if srdf is None:
        from baseparams.excite.collision import find_srdf
        srdf = find_srdf(str(urdf))
        if srdf is not None:
            notes.append(f"the SRDF found beside the URDF is used for the disabled pairs: {srdf} (--srdf chooses another)")
    return SceneSpec(str(urdf), None if srdf is None else str(srdf), tuple(map(str, package_dirs)), float(clearance),
                     planes, boxes)


def excite(mech: Any, *, output: Any = None, solver: str = "vp", solver_options: Mapping[str, Any] | None = None,
           criterion: str = "condition", harmonics: int = 5, period: float = 10.0, samples: int = 100,
           effects: Sequence[str] = (), separate: str | None = None, position_range: str | None = None,
           max_velocity: str | None = None, max_acceleration: str | None = None, max_torque: str | None = None,
           max_jerk: str | None = None, velocity_margin: float | None = None, singularity_margin: float = 0.03,
           noise: str | None = None, starts: int = 2, workers: int | None = None, scheduler: str | None = None,
           iterations: int = 200, seed: int = 0, csv: Any = None, rate: float = 1000.0, report: Any = None,
           plot: Any = None, collision: bool | None = None, collision_model: str | None = None,
           srdf: str | None = None, package_dirs: Sequence[str] = (), clearance: float | None = None,
           keep_out: Sequence[str] = (), floor: bool = True, progress: Callable[[int, int, str], None] | None = None,
           say: Callable[[str], None] | None = None, verbose: bool = False) -> Excitation:
    """See :func:`baseparams.api.excite` (the options are the verb's)."""
    from baseparams.dynamics.forces import independent_names
    from baseparams.excite import plan as planner
    from baseparams.excite.collision import DEFAULT_CLEARANCE
    from baseparams.excite.limits import VELOCITY_MARGIN, limits_of
    from baseparams.identify.base import BaseModel
    from baseparams.io.atomic import atomic_write
    from baseparams.orchestrate.jobs import MechanismText
    from baseparams.orchestrate.runners import make_runner
    if say is None and verbose:
        say = stderr_say
    kind = output_kind(None if output is None else str(output))
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
    weights = _noise_weights(noise, names)
    margin = VELOCITY_MARGIN if velocity_margin is None else velocity_margin
    if mechanism.loops and mechanism.trajectory is not None:
        # closed loops: the file's trajectory is known to stay in the reachable range
        ranges, velocities, accelerations = _trajectory_limits(mechanism, names)
        position_range = position_range or ranges
        max_velocity = max_velocity or velocities
        max_acceleration = max_acceleration or accelerations
        margin = 0.0 if velocity_margin is None else velocity_margin
    limits = limits_of(mechanism, positions=position_range, velocity=max_velocity, acceleration=max_acceleration,
                       torque=max_torque, jerk=max_jerk, velocity_margin=margin)
    notes: list[str] = []
    scene = scene_spec(mechanism, collision=collision, collision_model=collision_model, srdf=srdf,
                       package_dirs=package_dirs, clearance=DEFAULT_CLEARANCE if clearance is None else clearance,
                       keep_out=keep_out, floor=floor, notes=notes)
    if say is not None:
        say(f"base parameters ({solver})")
    base = BaseModel.from_result(run_solver(chosen, mechanism, solver_options), mechanism)
    settings = planner.Settings(harmonics=harmonics, period=period, samples=samples,
                                criterion="separation" if pairs else criterion, effects=tuple(parsed_effects),
                                separate=pairs, margin=singularity_margin if mechanism.loops else 0.0,
                                maxiter=iterations, weights=weights, scene=scene)
    text = MechanismText.read(mechanism.name, Path(mechanism.path))
    runner = make_runner(workers, scheduler)

    def rebase(planned: Mechanism) -> BaseModel:
        return BaseModel.from_result(run_solver(chosen, planned, solver_options), planned)

    try:
        found = planner.plan(mechanism, text, base, limits, settings, starts=starts, runner=runner,
                             progress=progress, seed=seed, rebase=rebase, say=say, solver=chosen.name)
    finally:
        close = getattr(runner, "close", None)
        if close:
            close()
    found.notes[:0] = notes
    result = Excitation(found, mechanism, None if output is None else str(output))
    if kind == "toml":
        atomic_write(output, result.toml(), "the planned mechanism file")
    elif kind == "csv":
        result.extra["csv"] = {"path": str(output), "rate": rate,
                               "rows": planner.write_csv(Path(output), mechanism, found, rate)}
    if csv:
        result.extra["csv"] = {"path": str(csv), "rate": rate,
                               "rows": planner.write_csv(Path(csv), mechanism, found, rate)}
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


def finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def check_plan(mech: Any, plan_path: str, *, solver: str = "vp", solver_options: Mapping[str, Any] | None = None,
               effects: Sequence[str] = (), position_range: str | None = None, max_velocity: str | None = None,
               max_acceleration: str | None = None, max_torque: str | None = None, max_jerk: str | None = None,
               velocity_margin: float = 0.0, noise: str | None = None, collision: bool | None = None,
               collision_model: str | None = None, srdf: str | None = None, package_dirs: Sequence[str] = (),
               clearance: float | None = None, keep_out: Sequence[str] = (), floor: bool = True) -> Any:
    """``excite --check``: the limits, distances and condition number of the motion in
    ``plan_path`` (:mod:`.checking`); the velocity margin is 0 here (the limit itself)."""
    from baseparams.dynamics.forces import independent_names
    from baseparams.excite import plan as planner
    from baseparams.excite.checking import check_motion, read_motion
    from baseparams.excite.collision import DEFAULT_CLEARANCE
    from baseparams.excite.limits import limits_of
    from baseparams.identify.base import BaseModel
    chosen = get_solver(solver)
    check_solver_options(chosen, solver_options or {})
    mechanism = load(mech)
    names = independent_names(mechanism)
    motion, notes = read_motion(mechanism, str(plan_path), tuple(names))
    limits = limits_of(mechanism, positions=position_range, velocity=max_velocity, acceleration=max_acceleration,
                       torque=max_torque, jerk=max_jerk, velocity_margin=velocity_margin)
    scene_notes: list[str] = []
    scene = scene_spec(mechanism, collision=collision, collision_model=collision_model, srdf=srdf,
                       package_dirs=package_dirs, clearance=DEFAULT_CLEARANCE if clearance is None else clearance,
                       keep_out=keep_out, floor=floor, notes=scene_notes)
    weights = _noise_weights(noise, names)
    parsed = tuple((s.kind, s.coordinate) for s in (parse_effect(e, mechanism, values=False) for e in effects))
    base = BaseModel.from_result(run_solver(chosen, mechanism, solver_options), mechanism)
    settings = planner.Settings(effects=parsed, weights=weights, scene=scene)
    problem = planner.problem_of(mechanism, base, limits, settings)
    if problem.scene is not None:
        scene_notes += problem.scene.notes
    return check_motion(mechanism, problem, str(plan_path), chosen.name, motion, scene_notes + notes)


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


def _noise_weights(noise: str | None, names: Sequence[str]) -> tuple[float, ...] | None:
    """The criterion's row weights 1/SD from ``--noise`` (one SD, or one per coordinate)."""
    if noise is None:
        return None
    sd = [float(v) for v in noise.split(",")] if all(_is_number(v) for v in noise.split(",")) else None
    if sd is None or any(v <= 0 for v in sd) or len(sd) not in (1, len(names)):
        raise InputError(f"expected one positive SD or {len(names)} ({', '.join(names)})", key="--noise")
    return tuple(1 / v for v in (sd * len(names) if len(sd) == 1 else sd))
