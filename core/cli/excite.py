"""``baseparams excite``: plan the exciting motion (registered on ``main``; docs/excite.md)."""

import re
import sys
from typing import Any

import click

from baseparams.api.effects import parse_separate  # noqa: F401  (its home moved; kept importable)
from baseparams.cli.commands import emit, get_solver, load, main
from baseparams.cli.options import (Progress, format_option, output_option, quiet_option, samples_option,
                                    scheduler_option, seed_option, solver_option, solver_options_option,
                                    workers_option)
from baseparams.errors import InputError
from baseparams.solvers.protocol import options_from_text


@main.command()
@click.argument("mech")
@output_option(help="The plan, written by its suffix: .toml (MECH with the motion as its [trajectory]) or .csv "
                    "(t, q_, qd_, qdd_ of every coordinate at --rate); another suffix is refused "
                    "[default: nothing written, the report only].")
@click.option("--check", "check_path", default=None, metavar="PLAN",
              help="Check a motion instead of planning one: a CSV (t, q_ and optionally qd_, qdd_ columns) or a "
                   "recording (description .toml, or CSV with tau_). Reports its limits, distances, collisions and "
                   "condition number; exit 1 when something does not hold.")
@solver_option(help="Solver whose base parameters define the base columns (any registered solver); the figures "
                    "are on the base it gives for the written file, as identify reports them.")
@solver_options_option()
@click.option("--criterion", type=click.Choice(["condition", "d-optimal"]), default="condition",
              show_default=True, help="Minimise the condition number, or maximise log det (D-optimality).")
@click.option("--harmonics", type=click.IntRange(2, 20), default=5, show_default=True,
              help="Harmonics of the Fourier series per coordinate.")
@click.option("--period", type=click.FloatRange(0.1, 1e4), default=10.0, show_default=True,
              help="Period of the motion (s): its base frequency is 1/period.")
@samples_option(help="Samples of the period the criterion, the limits and the distances are evaluated on while "
                     "optimising (then verified on ten times as many); at least 10.", default=100)
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD",
              help="An effect identified with the base parameters: its columns join the matrix; repeatable.")
@click.option("--separate", default=None, metavar="KIND:COORD,... | DIAGNOSIS.json",
              help="Effects to tell apart (from each other and from the model), or a `diagnose "
                   "--format json` report whose \"ambiguous\" groups are read; the criterion becomes "
                   "their smallest angle to the other columns.")
@click.option("--position-range", default=None, metavar="LO:HI | COORD=LO:HI,...",
              help="Position range (intersected with the file's limits) [default: the limits, "
                   "else +-pi rad / +-0.5 m, stated in the report; closed loops: the file's trajectory's range].")
@click.option("--max-velocity", default=None, metavar="V | COORD=V,...",
              help="Velocity limit [default: the URDF's; closed loops: the file's trajectory's peak; else 2 "
                   "rad/s / 0.5 m/s, stated in the report].")
@click.option("--velocity-margin", type=click.FloatRange(0, 1, max_open=True), default=None,
              help="Fraction of each velocity limit kept in reserve [default: 0.05; closed loops and --check: 0].")
@click.option("--max-acceleration", default=None, metavar="A | COORD=A,...",
              help="Acceleration limit [default: none (a URDF gives none), stated in the report; closed loops: "
                   "the file's trajectory's peak].")
@click.option("--max-jerk", default=None, metavar="J | COORD=J,...",
              help="Jerk limit [default: none, stated in the report].")
@click.option("--max-torque", default=None, metavar="T | COORD=T,...",
              help="Torque (force) limit on the model's inverse dynamics with the file's inertial parameters "
                   "[default: the URDF's effort].")
@click.option("--clearance", type=click.FloatRange(0, 10), default=None,
              help="Smallest distance (m) between links and to the keep-out geometry, between samples too "
                   "[default: 0.02].")
@click.option("--keep-out", "keep_out", multiple=True, metavar="plane:NX,NY,NZ,D | box:CX,CY,CZ,HX,HY,HZ",
              help="Keep-out geometry in the base frame (m): a plane (free where n.p >= D) or an axis-aligned box "
                   "(centre, half sides); repeatable.")
@click.option("--no-floor", is_flag=True, help="The base plane (z = 0) is not a floor.")
@click.option("--srdf", default=None, type=click.Path(dir_okay=False),
              help="SRDF whose disabled pairs are not checked for self-collision [default: without one, links "
                   "joined by a joint are not checked against each other].")
@click.option("--collision-model", default=None, type=click.Path(dir_okay=False), metavar="URDF",
              help="URDF with the collision geometry when MECH is not one (a mechanism file written from it).")
@click.option("--package-dir", "package_dirs", multiple=True, type=click.Path(file_okay=False),
              help="Where package:// meshes are looked for (besides the URDF's folder and its parents); repeatable.")
@click.option("--collision/--no-collision", default=None,
              help="Require the collision check (an error when it cannot run), or skip it [default: checked when "
                   "the URDF is known and Pinocchio is installed, else a note].")
@click.option("--singularity-margin", type=click.FloatRange(0, 1), default=0.03, show_default=True,
              help="Closed loops: the smallest 1/cond of the closure Jacobian in the dependent "
                   "coordinates the motion may reach (0 at a singular configuration).")
@click.option("--noise", default=None, metavar="SD[,SD...]",
              help="Noise SD of each coordinate's force: rows weighted by 1/SD as identify does "
                   "[default: equal weights].")
@click.option("--starts", type=click.IntRange(1, 1000), default=2, show_default=True,
              help="Random starts of the optimisation (the best feasible result is kept).")
@workers_option(help="Run the starts in this many local worker processes.")
@scheduler_option(help="Run the starts on a Dask scheduler (tcp://host:8786, or 'local').")
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
@format_option()
def excite(mech: str, output: str | None, check_path: str | None, solver_name: str, extra: tuple[str, ...],
           criterion: str, harmonics: int, period: float, samples: int, effects: tuple[str, ...],
           separate: str | None, position_range: str | None, max_velocity: str | None,
           velocity_margin: float | None, max_acceleration: str | None, max_jerk: str | None,
           max_torque: str | None, clearance: float | None, keep_out: tuple[str, ...], no_floor: bool,
           srdf: str | None, collision_model: str | None, package_dirs: tuple[str, ...], collision: bool | None,
           singularity_margin: float, noise: str | None, starts: int, workers: int | None, scheduler: str | None,
           iterations: int, seed: int, csv_path: str | None, rate: float, report_path: str | None,
           plot_path: str | None, quiet: bool, fmt: str) -> None:
    """Plan a periodic motion of MECH that identifies its base parameters.

    A finite Fourier series per independent coordinate, at rest at both ends, that
    minimises the condition number (or maximises log det) of the base-parameter
    observation matrix as identify builds it (rows weighted per coordinate, columns scaled
    to unit norm), on the base columns of --solver plus the --effect columns, under the
    robot's position, velocity and effort limits (acceleration and jerk when given), away
    from self-collision and the keep-out geometry (the base plane a floor) by --clearance
    (closed loops: inside the reachable range and away from singular configurations). With
    --separate, the motion instead tells the listed effects apart. -o writes the plan by its
    suffix. The report gives the criterion before and after, the margins and distances on a
    sampling ten times finer, and every assumption. With --check PLAN, a given motion is
    checked instead. Exit 0; 1 when the optimised motion is not better than the start (the
    start is returned) or a checked motion breaks a limit; 2 for bad input or limits no
    motion satisfies.
    """
    from baseparams.api.planning import check_plan, excite as run, output_kind
    check_noise(noise)
    options = options_from_text(get_solver(solver_name), extra)
    collision_options: dict[str, Any] = dict(collision=collision, collision_model=collision_model, srdf=srdf,
                             package_dirs=package_dirs, clearance=clearance, keep_out=keep_out, floor=not no_floor)
    if check_path is not None:
        if output is not None:
            raise InputError("--check reads a motion and writes nothing: leave out -o", key="-o")
        mechanism = load(mech)
        checked = check_plan(mechanism, check_path, solver=solver_name, solver_options=options, effects=effects,
                             position_range=position_range, max_velocity=max_velocity,
                             max_acceleration=max_acceleration, max_torque=max_torque, max_jerk=max_jerk,
                             velocity_margin=velocity_margin or 0.0, noise=noise, **collision_options)
        emit(fmt, checked.to_json(), checked.to_text)
        sys.exit(0 if checked.ok else 1)
    output_kind(output)                      # a bad suffix is refused before any work
    mechanism = load(mech)
    with Progress("excite", quiet=quiet) as progress:
        result = run(mechanism, output=output, solver=solver_name, solver_options=options, criterion=criterion,
                     harmonics=harmonics, period=period, samples=samples, effects=effects, separate=separate,
                     position_range=position_range, max_velocity=max_velocity, max_acceleration=max_acceleration,
                     max_torque=max_torque, max_jerk=max_jerk, velocity_margin=velocity_margin,
                     singularity_margin=singularity_margin, noise=noise, starts=starts,
                     workers=workers, scheduler=scheduler, iterations=iterations, seed=seed, csv=csv_path,
                     rate=rate, report=report_path, plot=plot_path, progress=progress.counted, say=progress,
                     **collision_options)
    emit(fmt, result.to_json(), result.to_text)
    if not result.plan.improved:
        click.echo(f"warning: {result.plan.kept} is returned: the optimised motion was not better "
                   "(see the notes)", err=True)
        sys.exit(1)
    sys.exit(0)



NOISE_RANGE = (1e-100, 1e100)       # rows are weighted by 1/SD: only the SDs' ratios matter
_SD = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def check_noise(text: str | None) -> None:
    """Each ``--noise`` SD an ASCII number from 1e-100 to 1e100 (InputError naming the option).
    Why (issue 46): 1e-320 made 1/SD infinite, every start failed on NaN, and the message
    advised widening the limits."""
    if text is None:
        return
    for item in text.split(","):
        item = item.strip()
        value = float(item) if _SD.fullmatch(item) else float("nan")
        if not NOISE_RANGE[0] <= value <= NOISE_RANGE[1]:
            raise InputError(f"{item!r}: each SD is a number from {NOISE_RANGE[0]:g} to {NOISE_RANGE[1]:g} (the rows "
                             "are weighted by 1/SD, so only their ratios matter: scale them into that range)",
                             key="--noise")
