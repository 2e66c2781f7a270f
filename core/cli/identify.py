"""``baseparams simulate`` and ``baseparams identify`` (registered on ``main``; docs/identification.md)."""

import json
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import click

from baseparams.api.data import same_file
from baseparams.api.effects import parse_effect, parse_effects  # noqa: F401  (their home moved; kept importable)
from baseparams.cli.commands import emit, get_solver, load, main
from baseparams.cli.options import (PathsAfterOptions, Progress, format_option, output_option, quiet_option,
                                    samples_option, seed_option, solver_option, solver_options_option)
from baseparams.errors import InputError
from baseparams.solvers.protocol import options_from_text

if TYPE_CHECKING:
    from baseparams.identify.fit import Prediction

# The identification modules (scipy.signal, scipy.linalg, cvxpy) are imported by the verbs
# that use them, as in commands.py: `baseparams --help` and `list` stay fast.


# ----- simulate ---------------------------------------------------------------------------
@main.command()
@click.argument("mech", metavar="MECH")
@output_option(help="CSV file to write (atomically) [default: standard output, the summary then on stderr].")
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD=VALUE[,VALUE]",
              help="A hidden effect on any joint coordinate (dependent ones too), its coefficients in "
                   "the effect's order, or KIND:COORD:NAME=VALUE[,NAME=VALUE]; repeatable.")
@click.option("--noise", default="0", show_default=True, metavar="SD[,SD...]",
              help="Standard deviation of the Gaussian noise on tau, one for all coordinates or one each.")
@seed_option()
@samples_option()
@click.option("--truth", type=click.Path(dir_okay=False), default=None,
              help="JSON file for the truth (parameters, effects, noise); never in the CSV.")
@click.option("--random-inertia", is_flag=True,
              help="Random physically consistent bodies instead of the file's inertias.")
@click.option("--no-derivatives", is_flag=True,
              help="Write only t, q and tau (identify then estimates qd and qdd).")
@format_option()
@quiet_option()
def simulate(mech: str, output: str | None, effects: tuple[str, ...], noise: str, seed: int, samples: int | None,
             truth: str | None, random_inertia: bool, no_derivatives: bool, fmt: str, quiet: bool) -> None:
    """Synthetic measured data for MECH along its exciting trajectory.

    tau = K phi + the effects' forces + Gaussian noise, with phi the file's inertial
    parameters (or random physically consistent ones), velocities and accelerations the
    trajectory's exact derivatives. The mechanism's own [[effects]] with every value given
    are simulated too. CSV layout: `python -m pydoc baseparams.recordings.data`; files are
    written atomically.
    """
    from baseparams.api import simulate as run
    mechanism = load(mech)
    with Progress("simulate", steps=2, quiet=quiet) as progress:
        if output is not None:
            result = run(mechanism, output=output, effects=effects, noise=noise, seed=seed, samples=samples,
                         truth=truth, random_inertia=random_inertia, derivatives=not no_derivatives,
                         progress=progress)
        else:
            with tempfile.TemporaryDirectory(prefix="baseparams-simulate-") as folder:
                path = Path(folder) / "data.csv"
                result = run(mechanism, output=path, effects=effects, noise=noise, seed=seed, samples=samples,
                             truth=truth, random_inertia=random_inertia, derivatives=not no_derivatives,
                             progress=progress)
                result.output = None
                click.echo(path.read_text(encoding="utf-8"), nl=False)
    if output is None:                       # the CSV is on stdout: the summary goes beside it
        text = result.to_text() if fmt == "text" else json.dumps(result.to_json(), indent=2)
        click.echo(text, err=True)
        return
    emit(fmt, result.to_json(), result.to_text)


# ----- identify ---------------------------------------------------------------------------
class _IdentifyCommand(PathsAfterOptions):
    """identify's parser: ``--validate`` takes every path after it (``--validate OTHER...``)."""
    greedy = ("--validate",)


@main.command(cls=_IdentifyCommand)
@click.argument("mech", metavar="MECH")
@click.argument("data_paths", metavar="DATA...", nargs=-1, required=True)
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD",
              help="An effect to identify with the inertial parameters, on a joint coordinate or a "
                   "motor; KIND:* on every independent coordinate that moves in the data (one held still "
                   "is left out, with a note); repeatable.")
@solver_option(help="The solver whose base parameters are fitted (dp is faster; its coefficients may "
                    "carry too few digits on badly conditioned mechanisms, which the result notes).")
@solver_options_option()
@click.option("--validate", "validate_paths", multiple=True, metavar="OTHER...",
              help="Predict these recordings (CSV or descriptions: every path after --validate up to the next "
                   "option, so DATA goes before it) with the identified model and print the error per "
                   "coordinate.")
@click.option("--physical", is_flag=True,
              help="Also physically consistent standard parameters reproducing the base estimates "
                   "(needs cvxpy: pip install 'baseparams[physical]'); the text gives the programme's status.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Measured and predicted forces per coordinate, fit and --validate data (png, pdf, svg).")
@output_option(help="Write the result (text, or JSON with --format json) to FILE instead of standard output.")
@format_option()
@quiet_option()
def identify(mech: str, data_paths: tuple[str, ...], effects: tuple[str, ...], solver_name: str,
             extra: tuple[str, ...], validate_paths: tuple[str, ...], physical: bool, plot_path: str | None,
             output: str | None, fmt: str, quiet: bool) -> None:
    """Least squares on MECH's base parameters (and named effects) from measured DATA.

    DATA: CSV files in the project's layout (irregular stamps read as a recording) or
    recording descriptions (.toml: raw logs as robots write them, with or without a header
    row, one value a line, .npz/.mat arrays, ROS 1 and ROS 2 bags; motor-side channels, gains,
    time stamps, filtering; `python -m pydoc
    baseparams.recordings.recording`), one or several; several runs are fitted together,
    each filtered on its own; --validate recordings are filtered with the fit's low-pass.
    NRMS is printed on the fit's band and on the unfiltered torques; a bad setup (a gain
    at or below zero, an ill-conditioned fit) is a warning with its numbers. Weighted per coordinate (Gautier: each coordinate's noise SD
    from an ordinary fit, then refitted with weights 1/SD). Prints every estimate with its
    standard deviation and relative std (%), what each base parameter stands for, the
    condition number and the NRMS residual per coordinate, and with --validate the
    prediction error on recordings the fit did not see. Effects in the mechanism's
    [[effects]] without values are identified too; those with every value are subtracted
    as known.
    """
    from baseparams.api import identify as run
    for path in (output, plot_path):
        if path and any(same_file(path, d) for d in data_paths + validate_paths):
            raise InputError("would overwrite a data file", file=path)
    options = options_from_text(get_solver(solver_name), extra)
    mechanism = load(mech)
    with Progress("identify", steps=4 + physical, quiet=quiet) as progress:
        result = run(mechanism, list(data_paths), effects=effects, solver=solver_name, solver_options=options,
                     validate=validate_paths, physical=physical, progress=progress)
        if plot_path:
            progress("plotting")
            plot_predictions([result.fitted] + result.predictions, plot_path,
                             title=f"{mechanism.name}: identified model")
    for warning in result.warnings:
        click.echo(f"warning: {warning}", err=True)
    if plot_path:
        result.written.append(plot_path)
    emit(fmt, result.to_json(), result.to_text, output)


def plot_predictions(predictions: "list[Prediction]", path: str, title: str = "", fmt: str | None = None) -> Path:
    """Measured and predicted forces per coordinate: one column per recording (the fit's
    data first, then each --validate recording), the RMS error in each panel's title."""
    from baseparams.cli.plots import _figure, _save
    f, columns = len(predictions[0].coordinates), len(predictions)
    fig = _figure(figsize=(5 * columns + 1, 2.2 * f + 0.8))
    for k, p in enumerate(predictions):
        for j, c in enumerate(p.coordinates):
            ax = fig.add_subplot(f, columns, j * columns + k + 1)
            ax.plot(p.t, p.measured[:, j], lw=0.6, color="0.45", label="measured")
            ax.plot(p.t, p.predicted[:, j], lw=0.8, color="tab:blue", label="predicted")
            what = "fit" if k == 0 else "validation"
            nrms = "undefined (force 0)" if c in p.undefined else f"{p.nrms[j]:.2f}"
            ax.set_title(f"{c} ({what}): RMS {p.rms[j]:.3g}, NRMS {nrms}", fontsize=8)
            ax.tick_params(labelsize=7)
            if j == 0 and k == 0:
                ax.legend(loc="upper right", fontsize=7)
            if j == f - 1:
                ax.set_xlabel("t (s)", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path, fmt)
