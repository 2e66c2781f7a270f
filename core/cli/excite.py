"""``baseparams excite``: plan the exciting motion (registered on ``main``; docs/excite.md)."""

import json
import math
import sys
from pathlib import Path

import click
import numpy as np

from baseparams.cli.commands import _progress, emit, format_option, get_solver, load, main
from baseparams.errors import InputError
from baseparams.solvers.protocol import check_options, require_applicable


@main.command()
@click.argument("mech")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Mechanism file (TOML) to write: MECH with the planned motion as its [trajectory].")
@click.option("--solver", "solver_name", default="dp", show_default=True,
              help="Solver whose base parameters define the base columns (any registered solver).")
@click.option("--criterion", type=click.Choice(["condition", "d-optimal"]), default="condition",
              show_default=True, help="Minimise the condition number, or maximise log det (D-optimality).")
@click.option("--harmonics", type=click.IntRange(2, 20), default=5, show_default=True,
              help="Harmonics of the Fourier series per coordinate.")
@click.option("--period", type=click.FloatRange(0.1, 1e4), default=10.0, show_default=True,
              help="Period of the motion (s): its base frequency is 1/period.")
@click.option("--samples", type=click.IntRange(10, 5000), default=100, show_default=True,
              help="Samples of the period the criterion and the limits are evaluated on while "
                   "optimising (the limits are then verified on ten times as many).")
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD",
              help="An effect identified with the base parameters: its columns join the matrix; repeatable.")
@click.option("--separate", default=None, metavar="KIND:COORD,... | DIAGNOSIS.json",
              help="Effects to tell apart (from each other and from the model), or a `diagnose "
                   "--format json` report whose \"ambiguous\" groups are read; the criterion becomes "
                   "their smallest angle to the other columns.")
@click.option("--position-range", default=None, metavar="LO:HI | COORD=LO:HI,...",
              help="Position range (intersected with the file's limits) [default: the limits, "
                   "else +-pi rad / +-0.5 m; closed loops: the file's trajectory's range].")
@click.option("--max-velocity", default=None, metavar="V | COORD=V,...",
              help="Velocity limit [default: the URDF's; closed loops: the file's trajectory's peak; else 2 "
                   "rad/s / 0.5 m/s].")
@click.option("--max-acceleration", default=None, metavar="A | COORD=A,...",
              help="Acceleration limit [default: closed loops: the file's trajectory's peak; else 4/s x the "
                   "velocity limit].")
@click.option("--max-torque", default=None, metavar="T | COORD=T,...",
              help="Torque (force) limit on the model's inverse dynamics [default: the URDF's effort].")
@click.option("--singularity-margin", type=click.FloatRange(0, 1), default=0.03, show_default=True,
              help="Closed loops: the smallest 1/cond of the closure Jacobian in the dependent "
                   "coordinates the motion may reach (0 at a singular configuration).")
@click.option("--noise", default=None, metavar="SD[,SD...]",
              help="Noise SD of each coordinate's force: rows weighted by 1/SD as identify does "
                   "[default: equal weights].")
@click.option("--starts", type=click.IntRange(1, 1000), default=4, show_default=True,
              help="Random starts of the optimisation (the best feasible result is kept).")
@click.option("--workers", type=click.IntRange(1, 256), default=None,
              help="Run the starts in this many local worker processes.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the starts on a Dask scheduler (tcp://host:8786, or 'local').")
@click.option("--iterations", type=click.IntRange(1, 100000), default=200, show_default=True,
              help="Iterations of each local optimisation.")
@click.option("--seed", type=click.IntRange(0, 2 ** 32 - 1), default=0, show_default=True,
              help="Seed of the first start (start k uses seed + k).")
@click.option("--csv", "csv_path", default=None, type=click.Path(dir_okay=False),
              help="Also write q, qd, qdd of every coordinate at --rate over one period.")
@click.option("--rate", type=click.FloatRange(1, 1e5), default=1000.0, show_default=True,
              help="Controller rate of the CSV (Hz).")
@click.option("--report", "report_path", default=None, type=click.Path(dir_okay=False),
              help="Also write the report as JSON to this file.")
@click.option("--plot", "plot_path", default=None, type=click.Path(dir_okay=False),
              help="Plot of the motion and the singular values (png, pdf or svg).")
@click.option("--quiet", is_flag=True, help="No progress messages.")
@format_option
def excite(mech, output, solver_name, criterion, harmonics, period, samples, effects, separate,
           position_range, max_velocity, max_acceleration, max_torque, singularity_margin, noise,
           starts, workers, scheduler, iterations, seed, csv_path, rate, report_path, plot_path, quiet, fmt):
    """Plan a periodic motion of MECH that identifies its base parameters.

    A finite Fourier series per independent coordinate, at rest at both ends, that
    minimises the condition number (or maximises log det) of the base-parameter
    observation matrix as identify builds it (rows weighted per coordinate, columns scaled
    to unit norm), on the base columns of --solver plus the --effect columns, under the
    position, velocity, acceleration and torque limits (closed loops: inside the reachable
    range and away from singular configurations). With --separate, the motion instead
    tells the listed effects apart. Writes MECH with the motion as its [trajectory]
    (solve, simulate and identify use it), and reports the criterion before and after and
    the limits' margins on a sampling ten times finer. Exit 0, or 2 for bad input or
    limits no motion satisfies.
    """
    from baseparams.excite import plan as planner
    from baseparams.excite.limits import limits_of
    from baseparams.identify.base import BaseModel
    from baseparams.identify.model import independent_names
    from baseparams.io.atomic import atomic_write
    from baseparams.io.toml_writer import mechanism_toml
    from baseparams.orchestrate.jobs import MechanismText
    from baseparams.orchestrate.runners import make_runner
    mechanism = load(mech)
    if not mechanism.path:
        raise InputError("the mechanism has no file to plan for", key="MECH")
    names = independent_names(mechanism)
    parsed_effects = []
    for text in effects:
        from baseparams.cli.identify import parse_effect
        spec = parse_effect(text, mechanism, values=False)
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
    solver = get_solver(solver_name)
    require_applicable(solver, mechanism)
    say = (lambda message: None) if quiet else _progress
    result = solver.solve(mechanism, progress=say, **check_options(solver, {}))
    base = BaseModel.from_result(result, mechanism)
    settings = planner.Settings(harmonics=harmonics, period=period, samples=samples,
                                criterion="separation" if pairs else criterion, effects=tuple(parsed_effects),
                                separate=pairs, margin=singularity_margin if mechanism.loops else 0.0,
                                maxiter=iterations, weights=weights)
    text = MechanismText.read(mechanism.name, Path(mechanism.path))
    runner = make_runner(workers, scheduler)

    def rebase(planned):
        return BaseModel.from_result(solver.solve(planned, **check_options(solver, {})), planned)

    def run(progress):
        return planner.plan(mechanism, text, base, limits, settings, starts=starts, runner=runner,
                            progress=progress, seed=seed, rebase=rebase)

    try:
        if quiet:
            found = run(None)
        elif sys.stderr.isatty():
            with click.progressbar(length=starts, label="excite", file=sys.stderr, show_eta=True, show_pos=True,
                                   item_show_func=lambda label: label) as bar:
                def progress(done, total, label):      # later rounds (one job each) only relabel
                    bar.update(1 if bar.pos < bar.length else 0, label)
                found = run(progress)
        else:
            found = run(lambda done, total, label: click.echo(f"excite: {done}/{total} starts done ({label})",
                                                              err=True))
    finally:
        close = getattr(runner, "close", None)
        if close:
            close()
    atomic_write(output, mechanism_toml(planner.with_trajectory(mechanism, found)), "the planned mechanism file")
    out = found.to_json()
    out["output"] = str(output)
    if csv_path:
        out["csv"] = {"path": str(csv_path), "rate": rate,
                      "rows": planner.write_csv(csv_path, found.problem, found.x, rate)}
    if report_path:
        atomic_write(report_path, json.dumps(out, indent=2) + "\n", "the report")
    if plot_path:
        from baseparams.excite.plot import plot_plan
        plot_plan(found, plot_path)

    def text_report():
        lines = [found.to_text(), f"wrote {output}"]
        lines += [f"wrote {p}" for p in (csv_path, report_path, plot_path) if p]
        return "\n".join(lines)

    emit(fmt, out, text_report)
    sys.exit(0)


def _is_number(text: str) -> bool:
    try:
        return float(text) == float(text)
    except ValueError:
        return False


def _trajectory_limits(mechanism, names) -> tuple[str, str, str]:
    """Closed loops: the position range, peak velocity and peak acceleration of the file's
    trajectory (its positions are known to close), as option texts."""
    from baseparams.identify.simulate import trajectory_motion
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
