"""``baseparams diagnose``: name the effect missing from a mechanism's model on measured
data, add it, and show the gap shrink (registered on ``main``; the statistics live in
:mod:`baseparams.identify.diagnose`)."""

import sys
from typing import TYPE_CHECKING

import click

from baseparams.cli.commands import emit, format_option, load, main
from baseparams.cli.plots import _figure, _save

# The statistics (scipy.signal, scipy.stats, statsmodels: slow imports) are imported by
# the verb when it runs, as in identify.py: every other command starts without them.
if TYPE_CHECKING:
    from baseparams.identify.diagnose import Diagnosis


@main.command()
@click.argument("mech", metavar="MECH")
@click.argument("data_paths", metavar="DATA...", nargs=-1, required=True)
@click.option("--params", "params_source", default=None, metavar="SOURCE",
              help="Hold the inertial parameters as given instead of refitting them: a mechanism file "
                   "(TOML, URDF) of the same robot with its inertias, or the JSON of an earlier "
                   "`identify`. Bodies, payloads and torque gains become candidates.")
@click.option("--candidates", "selection", multiple=True, metavar="KIND[:PLACE]",
              help="Candidate effects to test (repeatable); KIND alone: on every place it acts on "
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
@format_option
def diagnose(mech, data_paths, params_source, selection, alpha, folds, holdout, max_steps, plot_path,
             write_path, fmt):
    """Find where MECH's model and measured DATA disagree and name the missing effect.

    DATA: CSV files or recording descriptions (.toml), as for identify.

    The inertial model is fitted to the data (or held as given with --params); every
    candidate effect is tested against the residual (Wald tests, coloured noise whitened,
    Holm-corrected), the most significant is added, and the loop repeats until none is
    significant. A named effect must also be physically plausible, predict held-out blocks
    better (block cross-validation) and keep one coefficient over the recording; the
    others are reported as unsupported, never named. Candidates the data cannot tell apart
    are reported under "ambiguous" with the excitation that would separate them.

    Exit code 0 when the gap closed to the noise level (white residual, nothing
    unsupported), 1 when structure remains, 2 for bad input. JSON: {"verdict", "effects":
    [{"kind", "coordinate", "value", "std", "shape", "checks"}], "ambiguous", "unsupported",
    "gap": {"before", "after", "cv_before", "cv_after", "cv_blocks", ...}, "where",
    "unexplained"} (docs/diagnosis.md).
    """
    from dataclasses import replace

    from baseparams.identify.diagnose import check_writable, diagnose_data, write_fixed
    from baseparams.identify.given import given_parameters
    from baseparams.identify.recording import read_data

    mechanism = load(mech)
    if write_path:
        check_writable(mechanism, write_path)          # before the run, not after it
    given = None
    if params_source:
        given, known = given_parameters(mechanism, params_source)
        if known:
            mechanism = replace(mechanism, effects=tuple(mechanism.effects) + tuple(known))
    measured, mechanism = read_data(list(data_paths), mechanism)
    data = ", ".join(data_paths)
    result = diagnose_data(mechanism, measured, selection=list(selection) or None, alpha=alpha, folds=folds,
                           holdout=holdout, max_steps=max_steps, given=given)
    written = None
    if write_path:
        named = result.named()
        if named:
            write_fixed(mechanism, named, write_path, origin=f"data {data}")
            written = str(write_path)
        else:
            result.notes.append(f"--write: no mechanism effect named, {write_path} not written")
    if plot_path:
        plot_diagnosis(result, plot_path)
    payload = result.to_json()
    payload["written"] = written
    emit(fmt, payload, lambda: render_text(result, written))
    sys.exit(0 if result.closed else 1)


def _value_text(entry: dict) -> str:
    return ", ".join(f"{name} = {c['value']:.6g} +- {c['std']:.2g}" for name, c in entry["coefficients"].items())


VERDICTS = {
    "explained": "the named effects close the gap to the noise level",
    "partly explained": "the named effects close part of the gap; structure remains",
    "unexplained": "structure remains and no candidate explains it",
    "nothing missing": "the model matches the data to the noise level",
}


def render_text(result: "Diagnosis", written: str | None = None) -> str:
    """The diagnosis for a reader: the verdict and the gap first."""
    gap = result.gap
    lines = [f"verdict: {result.verdict.upper()}: {VERDICTS.get(result.verdict, '')}",
             f"gap (NRMS, blocks predicted from the others, {gap['cv_folds']} blocks): {gap['cv_before']:.4g} -> "
             f"{gap['cv_after']:.4g}; fitted: {gap['before']:.4g} -> {gap['after']:.4g}"]
    if gap["holdout_before"] is not None:
        lines.append(f"last block kept out: {gap['holdout_before']:.4g} -> {gap['holdout_after']:.4g} "
                     f"(prediction floor {gap['holdout_floor']:.4g}, noise alone {gap['holdout_noise_floor']:.4g})")
    lines.append("named effects:" if result.effects else "named effects: none")
    for e in result.effects:
        shape = "".join(f", {k} = {v:.3g}" for k, v in e.get("shape", {}).items())
        lines.append(f"  {e['kind']} on {e['coordinate']}: {_value_text(e)}{shape}  "
                     f"(p = {e['test']['pvalue_holm']:.2g}, Holm)")
    for a in result.ambiguous:
        names = " | ".join(f"{c['kind']}:{c['coordinate']}" for c in a["candidates"])
        corr = max((abs(ev["correlation"]) for ev in a["evidence"]), default=float("nan"))
        lines.append(f"ambiguous: {names} (|corr| up to {corr:.3f}; none adds significantly over the others)")
        lines.append(f"  to separate them: {a['separate_by']}")
    for u in result.unsupported:
        lines.append(f"not named (unsupported): {u['kind']} on {u['coordinate']}: {u['reason']}")
    un = result.unexplained
    if result.verdict in ("partly explained", "unexplained"):
        lines.append("where the gap remains: " + _where_text(result))
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
    lines.append(f"samples: {result.training} fitted" + (f", {result.held_out} kept out" if result.held_out else "")
                 + f"; alpha {result.alpha:g}")
    if result.untestable:
        lines.append(f"not testable on this data ({len(result.untestable)}): {', '.join(result.untestable)}")
    for note in result.notes:
        lines.append(f"note: {note}")
    if written:
        lines.append(f"written: {written}")
    return "\n".join(lines)


def _where_text(result: "Diagnosis") -> str:
    """Coordinates with the largest residual against their noise level, and the regimes where
    the residual concentrates."""
    ratios = {c: r for c, r in result.unexplained["ratio"].items() if r is not None}
    worst = sorted(ratios, key=lambda c: -ratios[c])[:3]
    parts = ["coordinates " + ", ".join(f"{c} ({ratios[c]:.3g} x noise)" for c in worst)] if worst else []
    concentrated = sorted(result.where.get("concentrated", []), key=lambda d: -d["ratio"])[:4]
    if concentrated:
        parts.append("concentrated at " + ", ".join(f"{d['regime'].replace('_', ' ')} of {d['coordinate']} "
                                                     f"({d['ratio']:.2g} x its RMS)" for d in concentrated))
    blocks = result.where.get("blocks", [])
    if blocks:
        loudest = max(blocks, key=lambda b: max(b["ratio"].values()))
        parts.append(f"largest in t = {loudest['t'][0]:.3g}..{loudest['t'][1]:.3g} s")
    return "; ".join(parts) or "-"


def plot_diagnosis(result: "Diagnosis", path, fmt=None):
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


__all__ = ["diagnose", "render_text", "plot_diagnosis"]
