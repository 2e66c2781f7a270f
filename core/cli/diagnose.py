"""``baseparams diagnose``: name the effect missing from a mechanism's model on measured
data, add it, and show the gap shrink (registered on ``main``; the statistics live in
:mod:`baseparams.identify.diagnose`)."""

import sys
from typing import TYPE_CHECKING

import click

from baseparams.cli.commands import emit, format_option, load, main
from baseparams.cli.plots import _figure, _save

# The statistics (scipy.signal, scipy.stats, statsmodels: 2 s of imports) are imported by
# the verb when it runs, as in identify.py: every other command starts without them.
if TYPE_CHECKING:
    from baseparams.identify.diagnose import Diagnosis


@main.command()
@click.argument("mech", metavar="MECH")
@click.argument("data_paths", metavar="DATA...", nargs=-1, required=True)
@click.option("--candidates", "selection", multiple=True, metavar="KIND[:COORD]",
              help="Candidate effects to test (repeatable); KIND alone: on every coordinate "
                   "[default: every registered effect on every tree coordinate].")
@click.option("--alpha", type=click.FloatRange(0.0, 1.0, min_open=True, max_open=True), default=0.05,
              show_default=True, help="Family-wise significance level (Holm over the candidates).")
@click.option("--holdout", type=click.FloatRange(0.0, 0.9), default=0.3, show_default=True,
              help="Fraction of the samples, the last time block, kept out of the fit.")
@click.option("--max-steps", type=click.IntRange(1, 1000), default=12, show_default=True,
              help="At most this many forward steps (each adds one effect or group); when the search "
                   "stops here with candidates still significant, the report says so.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Residuals before/after per coordinate and the candidates' statistics (png, pdf, svg).")
@click.option("--write", "write_path", type=click.Path(dir_okay=False), default=None, metavar="FILE.toml",
              help="Save the mechanism with the named effects added as [[effects]] tables.")
@format_option
def diagnose(mech, data_paths, selection, alpha, holdout, max_steps, plot_path, write_path, fmt):
    """Find where MECH's model and measured DATA disagree and name the missing effect.

    DATA: CSV files or recording descriptions (.toml), as for identify.

    The inertial model is fitted on the first part of the data (the last --holdout
    fraction is kept out); every candidate effect is tested against the residual (Wald
    tests with HAC covariance, Holm-corrected), the most significant is added, and the
    loop repeats until none is significant. Candidates the data cannot tell apart are
    reported under "ambiguous" with the excitation that would separate them, never named.

    Exit code 0 when the gap closed to the noise level (white residual), 1 when structure
    remains unexplained, 2 for bad input. JSON: {"effects": [{"kind", "coordinate",
    "value", "std"}], "ambiguous": [...], "gap": {"before", "after", "holdout_before",
    "holdout_after", "holdout_floor", "holdout_noise_floor"}, "unexplained": {...}}
    (docs/diagnosis.md).
    """
    from baseparams.identify.diagnose import diagnose_data, write_fixed
    from baseparams.identify.recording import read_data

    mechanism = load(mech)
    measured, mechanism = read_data(list(data_paths), mechanism)
    data = ", ".join(data_paths)
    result = diagnose_data(mechanism, measured, selection=list(selection) or None, alpha=alpha,
                           holdout=holdout, max_steps=max_steps)
    written = None
    if write_path:
        named = result.named()
        if named:
            write_fixed(mechanism, named, write_path, origin=f"data {data}")
            written = str(write_path)
        else:
            result.notes.append(f"--write: no effect named, {write_path} not written")
    if plot_path:
        plot_diagnosis(result, plot_path)
    payload = result.to_json()
    payload["written"] = written
    emit(fmt, payload, lambda: render_text(result, written))
    sys.exit(0 if result.closed else 1)


def _value_text(entry: dict) -> str:
    return ", ".join(f"{name} = {c['value']:.6g} +- {c['std']:.2g}" for name, c in entry["coefficients"].items())


def render_text(result: "Diagnosis", written: str | None = None) -> str:
    """The diagnosis for a reader."""
    lines = [f"diagnose {result.mechanism}: {result.training} samples fitted, {result.held_out} held out "
             f"(the last block); alpha {result.alpha:g}"]
    gap = result.gap
    line = f"gap (NRMS): fit {gap['before']:.4g} -> {gap['after']:.4g}"
    if gap["holdout_before"] is not None:
        line += (f"; holdout {gap['holdout_before']:.4g} -> {gap['holdout_after']:.4g} (prediction floor "
                 f"{gap['holdout_floor']:.4g}, noise alone {gap['holdout_noise_floor']:.4g})")
    lines.append(line)
    lines.append("named effects:" if result.effects else "named effects: none")
    for e in result.effects:
        lines.append(f"  {e['kind']} on {e['coordinate']}: {_value_text(e)}  (p = {e['test']['pvalue_holm']:.2g}, Holm)")
    for a in result.ambiguous:
        names = " | ".join(f"{c['kind']}:{c['coordinate']}" for c in a["candidates"])
        corr = max((abs(ev["correlation"]) for ev in a["evidence"]), default=float("nan"))
        lines.append(f"ambiguous: {names} (|corr| up to {corr:.3f}; none adds significantly over the others)")
        lines.append(f"  to separate them: {a['separate_by']}")
    un = result.unexplained
    weak = un.get("confusable_with_model", [])
    if weak:
        lines.append(f"nearly collinear with the inertial model ({len(weak)}, cannot be seen on this motion: "
                     f"{weak[0]['separate_by']}): " + ", ".join(w["candidate"] for w in weak))
    ratios = ", ".join(f"{c} {r:.3g}" if r is not None else f"{c} -" for c, r in un["ratio"].items())
    boxes = ", ".join(f"{c} p = {b['pvalue']:.2g}" for c, b in un["ljung_box"].items())
    lines.append(f"residual / noise level (second differences): {ratios}")
    lines.append(f"whiteness (Ljung-Box, {next(iter(un['ljung_box'].values()))['lags']} lags): {boxes}")
    if un.get("significant_candidates_left"):
        lines.append(f"the search stopped at --max-steps {un['max_steps']} with candidates still "
                     "significant: the named effects are incomplete")
    lines.append("gap closed to the noise level" if result.closed else
                 "structure remains unexplained (residual not white, or candidates still significant)")
    if result.untestable:
        lines.append(f"not testable on this data ({len(result.untestable)}): {', '.join(result.untestable)}")
    for note in result.notes:
        lines.append(f"note: {note}")
    if written:
        lines.append(f"written: {written}")
    return "\n".join(lines)


def plot_diagnosis(result: "Diagnosis", path, fmt=None):
    """Residuals before and after per coordinate (holdout shaded), and the first step's
    candidate statistics (normal-equivalent z) with the Holm threshold."""
    f = len(result.coordinates)
    fig = _figure(figsize=(10, 2.6 * (f + 1)))
    t = result.t
    split = t[result.training] if result.held_out else None
    for j, c in enumerate(result.coordinates):
        ax = fig.add_subplot(f + 1, 1, j + 1)
        ax.plot(t, result.residual_before[:, j], lw=0.7, color="tab:red", label="before")
        ax.plot(t, result.residual_after[:, j], lw=0.7, color="tab:blue", label="after")
        if split is not None:
            ax.axvspan(split, t[-1], color="0.9", label="holdout")
        ax.set_ylabel(f"residual {c}")
        ax.legend(loc="upper right", fontsize=7, ncol=3)
    ax = fig.add_subplot(f + 1, 1, f + 1)
    tests = result.steps[0]["tests"][:20]
    z = [d["z"] for d in tests]
    colours = ["tab:green" if d["pvalue_holm"] <= result.alpha else "0.6" for d in tests]
    ax.bar(range(len(tests)), z, color=colours)
    ax.set_xticks(range(len(tests)), [d["candidate"] for d in tests], rotation=60, ha="right", fontsize=6)
    ax.set_ylabel("z (first step)")
    ax.set_title("candidates against the inertial model (green: significant after Holm)", fontsize=8)
    ax.set_xlabel("t (s)" if f == 0 else "")
    fig.axes[f - 1].set_xlabel("t (s)")
    fig.tight_layout()
    return _save(fig, path, fmt)


__all__ = ["diagnose", "render_text", "plot_diagnosis"]
