"""``baseparams diagnose``: name the effect missing from a mechanism's model on measured
data, add it, and show the gap shrink (registered on ``main``; the statistics live in
:mod:`baseparams.diagnose.workflow`)."""

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from baseparams.api.render import diagnosis_text as render_text
from baseparams.cli.commands import emit, load, main
from baseparams.cli.options import PathsAfterOptions, Progress, format_option, output_option, quiet_option
from baseparams.cli.plots import _figure, _save

# The statistics (scipy.signal, scipy.stats, statsmodels: slow imports) are imported by
# the verb when it runs, as in identify.py: every other command starts without them.
if TYPE_CHECKING:
    from baseparams.diagnose.change import ChangeDiagnosis
    from baseparams.diagnose.workflow import Diagnosis


class _DiagnoseCommand(PathsAfterOptions):
    """diagnose's parser: ``--baseline`` takes every path after it (``--baseline BASE...``)."""
    greedy = ("--baseline",)


@main.command(cls=_DiagnoseCommand)
@click.argument("mech", metavar="MECH")
@click.argument("data_paths", metavar="DATA...", nargs=-1, required=True)
@click.option("--baseline", "baseline", multiple=True, metavar="BASE...",
              help="Runs of the same robot before a change (CSV or recording descriptions: every path after "
                   "--baseline up to the next option, so DATA goes before it): "
                   "name what changed between them and DATA (a payload on a body, a torque gain, a friction, "
                   "an offset, a delay) instead. One model is shared by both; what both lack cancels between "
                   "samples in the same state. Exit 0 for 'nothing changed' or 'changed' (explained).")
@click.option("--params", "params_source", default=None, metavar="SOURCE",
              help="Hold the inertial parameters as given instead of refitting them: a mechanism file "
                   "(TOML, URDF) of the same robot with its inertias, or the JSON of an earlier "
                   "`identify` (its effects replace the model's own; a change within its covariance is "
                   "its own error). Bodies (once per rigid body), payloads and torque gains become "
                   "candidates.")
@click.option("--urdf-dynamics", is_flag=True, default=False,
              help="Hold a URDF MECH's <dynamics damping friction> as known effects [default: set aside with "
                   "a note, as URDFs often carry placeholders; the diagnosis finds friction itself].")
@click.option("--candidates", "selection", multiple=True, metavar="KIND[:PLACE]",
              help="Candidate effects to test (repeatable); KIND alone: on every place it acts on "
                   "(delay alone: the recording's one delay; delay:COORD one drive's own) "
                   "[default: every registered effect on every coordinate and coupled motor, load_friction, "
                   "delay; with --params also gain, mass, payload and body].")
@click.option("--alpha", type=click.FloatRange(0.0, 1.0, min_open=True, max_open=True), default=0.05,
              show_default=True, help="Family-wise significance level (Holm over the candidates).")
@click.option("--folds", type=click.IntRange(2, 100), default=5, show_default=True,
              help="Blocks of the block cross-validation: each contiguous block predicted from the others.")
@click.option("--holdout", type=click.FloatRange(0.0, 0.9), default=0.0, show_default=True,
              help="Fraction of the samples, the last time block, kept out of everything (a final check).")
@click.option("--max-steps", type=click.IntRange(1, 100000), default=None,
              help="Stop the search after this many steps (each adds one effect or group) [default: no "
                   "limit]; when it stops here with candidates still significant, the report says so.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Residuals before/after per coordinate and the candidates' statistics (png, pdf, svg).")
@click.option("--write", "write_path", type=click.Path(dir_okay=False), default=None, metavar="FILE.toml",
              help="Save the mechanism (a TOML file) with the named effects added as [[effects]] tables.")
@click.option("--verbose", is_flag=True, default=False,
              help="The whole text report: every candidate not named with its reason, the residual's "
                   "statistics and every note (default: at most 25 lines, the verdict, the gap, each named "
                   "effect on one line with its unit, where the gap remains and counts of the rest). "
                   "JSON holds everything either way.")
@output_option(help="Write the report (text, or JSON with --format json) to FILE instead of standard output.")
@format_option()
@quiet_option()
def diagnose(mech: str, data_paths: tuple[str, ...], baseline: tuple[str, ...], params_source: str | None,
             urdf_dynamics: bool, selection: tuple[str, ...],
             alpha: float, folds: int, holdout: float, max_steps: int | None, plot_path: str | None,
             write_path: str | None, verbose: bool, output: str | None, fmt: str, quiet: bool) -> None:
    """Find where MECH's model and measured DATA disagree and name the missing effect.

    DATA: CSV files or recording descriptions (.toml), as for identify.

    The inertial model is fitted to the data (or held as given with --params); every
    candidate effect is tested against the residual (Wald tests, coloured noise whitened,
    Holm-corrected), the most significant is added, and the loop repeats until none is
    significant. A named effect must also be physically plausible, predict held-out blocks
    better (block cross-validation) and keep one coefficient over the recording; the
    others are reported as unsupported, never named. Candidates the data cannot tell apart
    are reported under "ambiguous" with the excitation that would separate them.

    Exit code 0 when the gap closed to the noise level (the motion predicts nothing of the
    residual, whatever its colour; nothing unsupported), 1 when structure remains, 2 for
    bad input. JSON: {"verdict", "effects":
    [{"kind", "coordinate", "value", "std", "shape", "checks"}], "ambiguous", "unsupported",
    "gap": {"before", "after", "cv_before", "cv_after", "cv_blocks", ...}, "where",
    "unexplained"} (`python -m pydoc baseparams.diagnose.workflow`).

    With --baseline BASE: what changed between the BASE runs and DATA (the changed runs).
    JSON: {"mode": "change", "verdict" ("nothing changed", "changed", "partly explained",
    "unexplained"), "effects" (each change: "kind", "coordinate" (a body or a coordinate),
    "value", "std"), "ambiguous", "gap", "common", "pairing", "rest", "notes"}
    (`python -m pydoc baseparams.diagnose.change`).
    """
    from baseparams.api import ChangeDiagnosed, Diagnosed, diagnose as run
    _no_results(data_paths, "DATA")
    _no_results(baseline, "--baseline")
    mechanism = load(mech)
    with Progress("diagnose", steps=2 + bool(baseline) + bool(plot_path), quiet=quiet) as progress:
        result = run(mechanism, list(data_paths), params=params_source, candidates=list(selection) or None,
                     alpha=alpha, folds=folds, holdout=holdout, max_steps=max_steps, write=write_path,
                     baseline=list(baseline) or None, urdf_dynamics=urdf_dynamics, progress=progress)
        if plot_path:
            progress("plotting")
            if isinstance(result, ChangeDiagnosed):
                plot_change(result.diagnosis, plot_path)
            else:
                assert isinstance(result, Diagnosed)
                plot_diagnosis(result.diagnosis, plot_path)
    emit(fmt, result.to_json(), lambda: result.to_text(verbose=verbose), output)
    sys.exit(0 if result.closed else 1)


def _no_results(paths: tuple[str, ...], option: str) -> None:
    """Refuse a JSON file among recordings (DATA, --baseline): a result is held with --params,
    never read as runs (it was "row 2: 2 fields, the header has 1": true, and no help)."""
    from baseparams.errors import InputError
    for path in paths:
        if Path(path).suffix.lower() == ".json":
            raise InputError(f"a JSON file, not runs: {option} takes recordings (CSV files or recording "
                             "descriptions); a result of `baseparams identify` is held as given with --params",
                             file=path, key=option)


def plot_diagnosis(result: "Diagnosis", path: str, fmt: str | None = None) -> Path:
    """Residuals before and after per coordinate (the before trace drawn over the after one,
    dashed, so it shows where the two coincide; the held-out part shaded), and the first
    step's candidate statistics (normal-equivalent z) with the significant ones marked."""
    f = len(result.coordinates)
    fig = _figure(figsize=(10, 2.4 * f + 3.2))
    t = result.t
    split = t[result.training] if result.held_out else None
    named = ", ".join(f"{e['kind']}:{e['coordinate']}" for e in result.effects[:4]) or "none"
    if len(result.effects) > 4:
        named += f" and {len(result.effects) - 4} more"
    gap = result.gap
    fig.suptitle(f"{result.mechanism}: {result.verdict}; gap (cross-validated NRMS) {gap['cv_before']:.3g} -> "
                 f"{gap['cv_after']:.3g}\nnamed: {named}", fontsize=9)
    for j, c in enumerate(result.coordinates):
        ax = fig.add_subplot(f + 1, 1, j + 1)
        ax.plot(t, result.residual_after[:, j], lw=0.7, color="tab:blue", label="after")
        ax.plot(t, result.residual_before[:, j], lw=0.7, color="tab:red", ls="--", alpha=0.8, label="before")
        if split is not None:
            ax.axvspan(split, t[-1], color="0.9", label="kept out")
        ax.set_ylabel(f"residual\n{c}", fontsize=8)
        ax.legend(loc="upper right", fontsize=7, ncol=3)
    ax = fig.add_subplot(f + 1, 1, f + 1)
    tests = result.steps[0]["tests"][:15]
    z = [d["z"] for d in tests]
    colours = ["tab:green" if d["pvalue_holm"] <= result.alpha else "0.6" for d in tests]
    ax.barh(range(len(tests)), z, color=colours)
    ax.set_yticks(range(len(tests)), [d["candidate"] for d in tests], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("z against the model alone (green: significant after Holm)", fontsize=8)
    fig.axes[f - 1].set_xlabel("t (s)")
    fig.tight_layout()
    return _save(fig, path, fmt)


def plot_change(result: "ChangeDiagnosis", path: str, fmt: str | None = None) -> Path:
    """The difference between the changed runs and the baseline at paired samples, per
    coordinate, before the named changes (dashed) and after them."""
    f = len(result.coordinates)
    fig = _figure(figsize=(10, 2.2 * f + 1.0))
    named = ", ".join(f"{e['kind']}:{e['coordinate']}" for e in result.changes[:4]) or "none"
    gap = result.gap
    fig.suptitle(f"{result.mechanism}: {result.verdict}; difference from the baseline (NRMS) {gap['before']:.3g} -> "
                 f"{gap['after']:.3g}\nchanges: {named}", fontsize=9)
    x = result.t if len(result.t) == len(result.difference_before) else range(len(result.difference_before))
    for j, c in enumerate(result.coordinates):
        ax = fig.add_subplot(f, 1, j + 1)
        ax.plot(x, result.difference_after[:, j], lw=0.7, color="tab:blue", label="after the changes")
        ax.plot(x, result.difference_before[:, j], lw=0.7, color="tab:red", ls="--", alpha=0.8, label="before")
        ax.set_ylabel(f"changed - baseline\n{c}", fontsize=8)
        ax.legend(loc="upper right", fontsize=7, ncol=2)
    fig.axes[-1].set_xlabel("t (s) of the changed runs" if x is result.t else "paired sample")
    fig.tight_layout()
    return _save(fig, path, fmt)


__all__ = ["diagnose", "render_text", "plot_diagnosis", "plot_change"]
