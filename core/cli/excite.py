"""``baseparams excite``: plan the exciting motion (registered on ``main``; docs/excite.md)."""

import json
import sys

import click

from baseparams.api.effects import parse_separate  # noqa: F401  (its home moved; kept importable)
from baseparams.cli.commands import emit, format_option, get_solver, load, main
from baseparams.cli.options import (Progress, output_option, quiet_option, samples_option, seed_option,
                                    solver_option, solver_options_option)
from baseparams.solvers.protocol import options_from_text


@main.command()
@click.argument("mech")
@output_option(help="Mechanism file (TOML) to write: MECH with the planned motion as its [trajectory] "
                    "[default: standard output, the report then on stderr].")
@solver_option(help="Solver whose base parameters define the base columns (any registered solver).")
@solver_options_option()
@click.option("--criterion", type=click.Choice(["condition", "d-optimal"]), default="condition",
              show_default=True, help="Minimise the condition number, or maximise log det (D-optimality).")
@click.option("--harmonics", type=click.IntRange(2, 20), default=5, show_default=True,
              help="Harmonics of the Fourier series per coordinate.")
@click.option("--period", type=click.FloatRange(0.1, 1e4), default=10.0, show_default=True,
              help="Period of the motion (s): its base frequency is 1/period.")
@samples_option(help="Samples of the period the criterion and the limits are evaluated on while optimising "
                     "(the limits are then verified on ten times as many); at least 10.", default=100)
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
@seed_option(help="Seed of the first start (start k uses seed + k).")
@click.option("--csv", "csv_path", default=None, type=click.Path(dir_okay=False),
              help="Also write q, qd, qdd of every coordinate at --rate over one period.")
@click.option("--rate", type=click.FloatRange(1, 1e5), default=1000.0, show_default=True,
              help="Controller rate of the CSV (Hz).")
@click.option("--report", "report_path", default=None, type=click.Path(dir_okay=False),
              help="Also write the report as JSON to this file.")
@click.option("--plot", "plot_path", default=None, type=click.Path(dir_okay=False),
              help="Plot of the motion and the singular values (png, pdf or svg).")
@quiet_option()
@format_option
def excite(mech: str, output: str | None, solver_name: str, extra: tuple[str, ...], criterion: str, harmonics: int,
           period: float, samples: int, effects: tuple[str, ...], separate: str | None, position_range: str | None,
           max_velocity: str | None, max_acceleration: str | None, max_torque: str | None,
           singularity_margin: float, noise: str | None, starts: int, workers: int | None, scheduler: str | None,
           iterations: int, seed: int, csv_path: str | None, rate: float, report_path: str | None,
           plot_path: str | None, quiet: bool, fmt: str) -> None:
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
    from baseparams.api import excite as run
    options = options_from_text(get_solver(solver_name), extra)
    mechanism = load(mech)
    with Progress("excite", quiet=quiet) as progress:
        result = run(mechanism, output=output, solver=solver_name, solver_options=options, criterion=criterion,
                     harmonics=harmonics, period=period, samples=samples, effects=effects, separate=separate,
                     position_range=position_range, max_velocity=max_velocity, max_acceleration=max_acceleration,
                     max_torque=max_torque, singularity_margin=singularity_margin, noise=noise, starts=starts,
                     workers=workers, scheduler=scheduler, iterations=iterations, seed=seed, csv=csv_path,
                     rate=rate, report=report_path, plot=plot_path, progress=progress.counted, say=progress)
    if output is None:              # the mechanism file is on stdout: the report goes beside it
        click.echo(result.toml(), nl=False)
        click.echo(result.to_text() if fmt == "text" else json.dumps(result.to_json(), indent=2), err=True)
        sys.exit(0)
    emit(fmt, result.to_json(), result.to_text)
    sys.exit(0)
