"""Text renderings of results that the command line prints and the results' ``to_text``
return (one home for each)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from baseparams.identify.diagnose import Diagnosis


def _value_text(entry: dict[str, Any]) -> str:
    """Each coefficient with its std; where some are not identifiable on their own (a changed
    body on a mechanism of low mobility), the combinations the data determine, then what
    they cannot."""
    coefficients = entry["coefficients"]
    absorbed = {name: c["absorbed_into"] for name, c in coefficients.items() if c["value"] is None}
    parts = []
    for name, c in coefficients.items():
        if c["value"] is None:
            continue
        terms = "".join(f" {'-' if into[name] < 0 else '+'} {abs(into[name]):.4g} {other}"
                        for other, into in absorbed.items() if into.get(name))
        parts.append(f"{name}{terms} = {c['value']:.6g} +- {c['std']:.2g}")
    if absorbed:
        parts.append(f"not identifiable on their own here: {', '.join(absorbed)}")
    return ", ".join(parts)


VERDICTS = {
    "explained": "the named effects close the gap to the noise level",
    "partly explained": "the named effects close part of the gap; structure remains",
    "unexplained": "structure remains and no candidate explains it",
    "nothing missing": "the model matches the data to the noise level",
}


def diagnosis_text(result: "Diagnosis", written: str | None = None) -> str:
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
        lines.append(f"  {e['kind']} on {e['coordinate']}: {_value_text(e)}{shape}{_known_text(e)}{_payload_text(e)}  "
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


def _known_text(effect: dict) -> str:
    """What a named effect corrects: the model's own known coefficients, and the total."""
    known = effect.get("known")
    if not known:
        return ""
    from baseparams.identify.diagnose import absent
    values = effect["value"] if isinstance(effect["value"], dict) else {next(iter(known)): effect["value"]}
    gone = all(absent(values[k] + v, v) for k, v in known.items())
    return (" correcting the model's own " + ", ".join(f"{k} = {v:.4g}" for k, v in known.items())
            + " (total " + ", ".join(f"{k} = {values[k] + v:.4g}" for k, v in known.items())
            + (": the model's own is not in the data" if gone else "") + ")")


def _payload_text(effect: dict) -> str:
    """Where a changed body's added mass sits: its centre of mass in the body's axes (the
    first moments over the mass), when the added mass is positive."""
    c = effect["coefficients"]
    if effect["kind"] != "body" or any(c[k]["value"] is None for k in ("m", "mx", "my", "mz")) \
            or c["m"]["value"] <= 0:
        return ""
    m = c["m"]["value"]
    centre = ", ".join(f"{c[k]['value'] / m:.4g}" for k in ("mx", "my", "mz"))
    return f" (added mass {m:.4g} at ({centre}) in {effect['coordinate']}'s axes)"


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
