"""``baseparams simulate`` and ``baseparams identify`` (registered on ``main``; docs/identification.md)."""

import json
from fractions import Fraction
from pathlib import Path

import click

from baseparams.cli.commands import _progress, emit, format_option, get_solver, load, main
from baseparams.errors import InputError
from baseparams.model.mechanism import EffectSpec, Mechanism
from baseparams.solvers.protocol import check_options, require_applicable

# The identification modules (scipy.signal, scipy.linalg, cvxpy) are imported by the verbs
# that use them, as in commands.py: `baseparams --help` and `list` stay fast.


def _same_file(a: str | None, b: str | None) -> bool:
    return bool(a and b) and Path(a).resolve() == Path(b).resolve()


# ----- simulate ---------------------------------------------------------------------------
@main.command()
@click.argument("mech", metavar="MECH")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="CSV file to write.")
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD=VALUE[,VALUE]",
              help="A hidden effect on any joint coordinate (dependent ones too), its coefficients in "
                   "the effect's order, or KIND:COORD:NAME=VALUE[,NAME=VALUE]; repeatable.")
@click.option("--noise", default="0", show_default=True, metavar="SD[,SD...]",
              help="Standard deviation of the Gaussian noise on tau, one for all coordinates or one each.")
@click.option("--seed", type=click.IntRange(0, 2 ** 32 - 1), default=0, show_default=True,
              help="Seed of the random numbers (0 to 2^32 - 1).")
@click.option("--samples", type=click.IntRange(2, 10_000_000), default=None,
              help="Samples of the exciting trajectory [default: the mechanism file's].")
@click.option("--truth", type=click.Path(dir_okay=False), default=None,
              help="JSON file for the truth (parameters, effects, noise); never in the CSV.")
@click.option("--random-inertia", is_flag=True,
              help="Random physically consistent bodies instead of the file's inertias.")
@click.option("--no-derivatives", is_flag=True,
              help="Write only t, q and tau (identify then estimates qd and qdd).")
@format_option
def simulate(mech, output, effects, noise, seed, samples, truth, random_inertia, no_derivatives, fmt):
    """Synthetic measured data for MECH along its exciting trajectory.

    tau = K phi + the effects' forces + Gaussian noise, with phi the file's inertial
    parameters (or random physically consistent ones), velocities and accelerations the
    trajectory's exact derivatives. The mechanism's own [[effects]] with every value given
    are simulated too. CSV layout: docs/design.md; files are written atomically.
    """
    from baseparams.identify.data import MIN_SAMPLES, write_measured
    from baseparams.io.atomic import atomic_write
    from baseparams.identify.fit import split_effects
    from baseparams.identify.simulate import simulate as run_simulation
    if samples is not None and samples < MIN_SAMPLES:
        raise InputError(f"{samples} samples: at least {MIN_SAMPLES} are needed", key="--samples")
    mechanism = load(mech)
    named = [parse_effect(text, mechanism, values=True) for text in effects]
    keys = {(s.kind, s.coordinate) for s in named}
    if len(keys) < len(named):
        raise InputError("an effect is named twice (same kind and coordinate)", key="--effect")
    _, known = split_effects(mechanism, [])
    hidden = [s for s in known if (s.kind, s.coordinate) not in keys] + named
    for path in (output, truth):
        if _same_file(path, mechanism.path):
            raise InputError("would overwrite the mechanism file", file=path)
    if truth and _same_file(truth, output):
        raise InputError("the truth and the data would be the same file", file=truth)
    data, truth_data = run_simulation(mechanism, samples=samples, noise_sd=_noise(noise), seed=seed,
                                      effects=hidden, random_inertia=random_inertia)
    write_measured(output, data, derivatives=not no_derivatives)
    if truth:
        atomic_write(truth, json.dumps(truth_data, indent=2) + "\n")
    summary = {"output": str(output), "truth": truth, "samples": data.count,
               "coordinates": list(data.coordinates), "effects": len(hidden)}
    emit(fmt, summary, f"wrote {output} ({data.count} samples, coordinates {', '.join(data.coordinates)}, "
                       f"{len(hidden)} hidden effects)" + (f"; truth in {truth}" if truth else ""))


# ----- identify ---------------------------------------------------------------------------
@main.command()
@click.argument("mech", metavar="MECH")
@click.argument("data_paths", metavar="DATA...", nargs=-1, required=True)
@click.option("--effect", "effects", multiple=True, metavar="KIND:COORD",
              help="An effect to identify with the inertial parameters, on a joint coordinate or a "
                   "motor; KIND:* on every independent coordinate; repeatable.")
@click.option("--solver", "solver_name", default="vp", show_default=True, metavar="NAME",
              help="The solver whose base parameters are fitted (dp is faster; its coefficients may "
                   "carry too few digits on badly conditioned mechanisms, which the result notes).")
@click.option("--validate", "validate_paths", multiple=True, metavar="OTHER",
              help="Predict this recording (CSV or description) with the identified model and print "
                   "the error per coordinate; repeatable.")
@click.option("--physical", is_flag=True,
              help="Also physically consistent standard parameters reproducing the base estimates "
                   "(needs cvxpy: pip install 'baseparams[physical]').")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Measured and predicted forces per coordinate, fit and --validate data (png, pdf, svg).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also write the JSON result to this file (atomically).")
@format_option
def identify(mech, data_paths, effects, solver_name, validate_paths, physical, plot_path, output, fmt):
    """Least squares on MECH's base parameters (and named effects) from measured DATA.

    DATA: CSV files in the project's layout or recording descriptions (.toml: raw logs
    with motor-side channels, gains, time stamps, filtering; docs/identification.md), one
    or several; several runs are fitted together, each filtered on its own. Weighted per
    coordinate (Gautier: each coordinate's noise SD from an ordinary fit, then refitted
    with weights 1/SD). Prints every estimate with its standard deviation and relative
    std (%), the condition number and the NRMS residual per coordinate, and with
    --validate the prediction error on recordings the fit did not see. Effects in the
    mechanism's [[effects]] without values are identified too; those with every value
    are subtracted as known.
    """
    from baseparams.identify.base import BaseModel
    from baseparams.io.atomic import atomic_write
    from baseparams.identify.fit import identify as fit, predict, split_effects
    from baseparams.identify.model import standard_parameters
    from baseparams.identify.recording import read_data
    if physical:
        from baseparams.identify import physical as consistency     # cvxpy: an optional extra
        consistency.require_cvxpy()
    for path in (output, plot_path):
        if path and any(_same_file(path, d) for d in data_paths + validate_paths):
            raise InputError("would overwrite a data file", file=path)
    mechanism = load(mech)
    data, mechanism = read_data(list(data_paths), mechanism)
    others = [read_data([path], mechanism)[0] for path in validate_paths]
    named = parse_effects(effects, mechanism)
    to_identify, known = split_effects(mechanism, named)
    solver = get_solver(solver_name)
    require_applicable(solver, mechanism)
    result = solver.solve(mechanism, progress=_progress, **check_options(solver, {}))
    for warning in result.warnings:
        click.echo(f"warning: {warning}", err=True)
    base = BaseModel.from_result(result, mechanism)
    identification = fit(mechanism, data, effects=to_identify, base=base, known=known)
    if physical:
        prior, source = None, "least-norm parameters B^+ phi_b"
        if all(b.inertia is not None for b in mechanism.bodies):
            from baseparams.model.consistency import require_physical
            require_physical(mechanism, "identify --physical (the file's inertias are its prior)")
            prior, source = standard_parameters(mechanism), "the mechanism file's inertias"
        found = consistency.physical_fit(identification.base_estimates, base,
                                         std=identification.std[:base.rank], prior=prior)
        identification.physical = consistency.physical_json(found, tuple(mechanism.parameters))
        identification.extras["physical_fit"] = {
            "max_deviation_std": found.max_deviation, "prior": source, "solver": found.solver,
            "status": found.status,
            "min_pseudo_inertia_eigenvalue": dict(zip(map(str, mechanism.body_labels),
                                                      map(float, found.min_eigenvalues)))}
    fitted = predict(identification, mechanism, data)
    predictions = [predict(identification, mechanism, other) for other in others]
    identification.extras["rms"] = fitted.to_json()["rms"]
    identification.extras["rms_overall"] = fitted.overall_rms
    identification.extras["runs"] = list(data.runs)
    if predictions:
        identification.extras["validation"] = [p.to_json() for p in predictions]
    out = identification.to_json()
    if output:
        atomic_write(output, json.dumps(out, indent=2) + "\n")
    if plot_path:
        plot_predictions([fitted] + predictions, plot_path, title=f"{mechanism.name}: identified model")

    def text():
        lines = [identification.to_text()]
        lines.append(f"  RMS residual overall {fitted.overall_rms:.4g}; per coordinate: "
                     + ", ".join(f"{c} {r:.4g}" for c, r in zip(fitted.coordinates, fitted.rms)))
        if identification.physical is not None:
            info = identification.extras["physical_fit"]
            lines.append(f"  physically consistent parameters (prior: {info['prior']}; the base "
                         f"estimates reproduced within {info['max_deviation_std']:.3g} std):")
            lines += [f"    {k} = {v}" for k, v in identification.physical.items()]
        lines += [p.to_text() for p in predictions]
        if output:
            lines.append(f"wrote {output}")
        if plot_path:
            lines.append(f"wrote {plot_path}")
        return "\n".join(lines)

    emit(fmt, out, text)


def plot_predictions(predictions, path, title: str = "", fmt=None):
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
            ax.set_title(f"{c} ({what}): RMS {p.rms[j]:.3g}, NRMS {p.nrms[j]:.2f}", fontsize=8)
            ax.tick_params(labelsize=7)
            if j == 0 and k == 0:
                ax.legend(loc="upper right", fontsize=7)
            if j == f - 1:
                ax.set_xlabel("t (s)", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path, fmt)
