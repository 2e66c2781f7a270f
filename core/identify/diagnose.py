"""Discrepancy diagnosis: where the model and measured data disagree, which effect is
missing, and how much of the gap it closes.

The inertial model (every standard parameter free, fitted through the column space of the
regressor on the training samples) is fitted on the first part of the data; the last time
block (``holdout``) is kept out to check that what is named also predicts. Candidate
effects (:mod:`.candidates`) are added one at a time by the tests of :mod:`.selection`;
confusable candidates are reported together under ``ambiguous`` with the evidence and the
excitation that would separate them, never named. The report gives each named effect's
coefficients with HAC standard deviations, the gap (NRMS) before and after on the fit and
the holdout (with the holdout's prediction floor, :func:`holdout_floor`: what a correct
model fitted on the training part reaches there), and what remains: a Ljung-Box whiteness
test of the residual and the residual compared with the noise level estimated from its
second differences (which a smooth missing force does not reach).

Effects the mechanism already has (``[[effects]]``): with every coefficient given they are
known forces, subtracted from tau; otherwise their coefficients are fitted with the inertial
model. Neither is a candidate.
"""

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path

import numpy as np
from statsmodels.stats.sandwich_covariance import S_hac_simple

from baseparams import registry
from baseparams.errors import InputError
from baseparams.identify.candidates import library, parse_selection
from baseparams.identify.data import MeasuredData
from baseparams.io.atomic import atomic_write
from baseparams.identify.model import Design, Motion, design, effect_values, evaluate, independent_names
from baseparams.identify.selection import (MAX_STEPS, Candidate, Fit, Rival, Selection, hac_lags,
                                           project_out, holm, select, weighted_fit)
from baseparams.identify.whiteness import monte_carlo_pvalues, replicates
from baseparams.dynamics.evaluator import Sample
from baseparams.io.loader import parse_mechanism
from baseparams.model.mechanism import EffectSpec, Mechanism

LJUNG_BOX_LAGS = 10
# A candidate keeping less than this fraction of its norm once the inertial model is
# projected out is nearly collinear with it (|corr| > 0.9987): a spring or an offset on a
# suspension whose position-only force the gravity terms imitate over the range travelled.
WEAK = 0.05
MODEL_HINT = ("change the pose or travel a wider range: over this motion the inertial model's "
              "gravity-like terms imitate this force")
# The excitation that separates two confusable kinds (either order).
SEPARATE = {
    frozenset({"viscous_friction", "spring"}): "vary the oscillation frequency: a viscous force "
    "scales with speed, a spring's does not",
    frozenset({"viscous_friction", "coulomb_friction"}): "vary the speed amplitude: Coulomb friction "
    "does not grow with speed",
    frozenset({"coulomb_friction", "stribeck_friction"}): "move slowly through zero speed, where the "
    "Stribeck bump lives",
    frozenset({"viscous_friction", "stribeck_friction"}): "move slowly through zero speed",
    frozenset({"offset", "spring"}): "move the coordinate over a wider range or about another mean "
    "position: an offset does not change with position",
    frozenset({"offset", "coulomb_friction"}): "hold the direction of motion for longer in both "
    "directions: an offset does not change sign with the speed",
    frozenset({"spring", "rotor_inertia"}): "vary the oscillation frequency: at one frequency "
    "the acceleration is proportional to the position",
    frozenset({"viscous_friction", "rotor_inertia"}): "vary the oscillation frequency",
    frozenset({"offset", "rotor_inertia"}): "change the pose and the acceleration pattern",
}
SAME_KIND = ("move through a wider range of positions, so that the two coordinates' "
             "transmission ratios (dq/dz) differ")
GENERIC = "a richer excitation: more frequencies, a wider range of positions and speeds"


def separation(kinds: Sequence[str], same_coordinate_kinds: bool) -> str:
    """The excitation that would separate a group of confusable candidates."""
    unique = sorted(set(kinds))
    if len(unique) == 1:
        return SAME_KIND
    hints = [SEPARATE[frozenset({a, b})] for i, a in enumerate(unique) for b in unique[i + 1:]
             if frozenset({a, b}) in SEPARATE]
    return "; ".join(hints) if hints else GENERIC


# ----- what does not depend on tau -------------------------------------------------------
@dataclass
class Problem:
    """The model's columns at the data's samples, computed once (a campaign reuses them
    for many datasets on the same motion): ``inertial`` (N, f, P) plus the mechanism's
    effects with unknown coefficients; ``known`` (N, f) the force of its effects with known
    coefficients; the candidates."""
    mechanism: Mechanism
    coordinates: tuple[str, ...]
    t: np.ndarray
    inertial: np.ndarray
    known: np.ndarray
    candidates: list[Candidate]
    notes: list[str] = field(default_factory=list)


def prepare(mechanism: Mechanism, motion: Motion, sample: Sample | None = None,
            selection: Sequence[str] | None = None, data: MeasuredData | None = None) -> Problem:
    """The inertial and candidate columns along ``motion``; ``selection``: ``KIND[:COORD]``
    strings restricting the candidates (None: every registered effect on every coordinate
    and motor). With measured ``data`` every column is reduced to the fit's rows as its
    torques were (parallel filtering), and its known payloads' forces count as known."""
    sample = sample if sample is not None else evaluate(mechanism, motion)
    pairs = parse_selection(mechanism, selection) if selection else None
    known_specs = [e for e in mechanism.effects if _all_given(e)]
    fitted_specs = [e for e in mechanism.effects if not _all_given(e)]
    inertial, fitted = design(mechanism, motion, fitted_specs, sample)
    _, known_cols = design(mechanism, motion, known_specs, sample)
    known = known_cols.matrix @ effect_values(mechanism, known_specs) if known_specs else \
        np.zeros(inertial.matrix.shape[:2])
    t = np.asarray(motion.t, float)
    reduce = None
    if data is not None:
        if data.payloads:
            known = known + data.payload_force(inertial.matrix)
        reduce, t = data.reduce, data.t
        inertial = Design(inertial.names, data.reduce(inertial.matrix))
        fitted = Design(fitted.names, data.reduce(fitted.matrix))
        known = data.reduce(known)
    candidates, notes = library(mechanism, sample, motion.count, pairs, reduce)
    if known_specs:
        notes.append("known effects subtracted: " + ", ".join(f"{e.kind}:{e.coordinate}" for e in known_specs))
    if fitted_specs:
        notes.append("effects fitted with the inertial model: "
                     + ", ".join(f"{e.kind}:{e.coordinate}" for e in fitted_specs))
    if not candidates:
        raise InputError("no candidate effects left to test (every selected effect is already "
                         "in the mechanism)", key="--candidates")
    model = np.concatenate([inertial.matrix, fitted.matrix], axis=-1)
    return Problem(mechanism, independent_names(mechanism), t, model, known, candidates, notes)


def _all_given(spec: EffectSpec) -> bool:
    return all(name in spec.values for name in registry.effects()[spec.kind].item.coefficients)


# ----- the result ----------------------------------------------------------------------------
@dataclass
class Diagnosis:
    """What :func:`diagnose` found; :meth:`to_json` is the documented JSON object."""
    mechanism: str
    coordinates: tuple[str, ...]
    alpha: float
    training: int
    held_out: int
    effects: list[dict]
    ambiguous: list[dict]
    gap: dict
    unexplained: dict
    steps: list[dict]
    untestable: list[str]
    closed: bool
    notes: list[str]
    t: np.ndarray = field(repr=False)
    residual_before: np.ndarray = field(repr=False)       # (N, f): training then holdout
    residual_after: np.ndarray = field(repr=False)
    added: list[Candidate] = field(default_factory=list, repr=False)

    def to_json(self) -> dict:
        return {"mechanism": self.mechanism, "coordinates": list(self.coordinates),
                "effects": self.effects, "ambiguous": self.ambiguous, "gap": self.gap,
                "unexplained": self.unexplained, "closed": self.closed, "alpha": self.alpha,
                "samples": {"fit": self.training, "holdout": self.held_out},
                "steps": self.steps, "untestable": self.untestable, "notes": self.notes}

    def named(self) -> list[EffectSpec]:
        """The named effects as mechanism effects with their estimated coefficients."""
        return [EffectSpec(e["kind"], e["coordinate"], {k: v["value"] for k, v in e["coefficients"].items()})
                for e in self.effects]


# ----- the loop ------------------------------------------------------------------------------
def diagnose(problem: Problem, tau: np.ndarray, *, alpha: float = 0.05, holdout: float = 0.3,
             max_steps: int = MAX_STEPS) -> Diagnosis:
    """Fit, test, add, repeat (see the module docstring); ``tau`` (N, f) measured forces."""
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha must be in (0, 1), not {alpha}", key="--alpha")
    if not 0.0 <= holdout < 1.0:
        raise InputError(f"holdout must be in [0, 1), not {holdout}", key="--holdout")
    tau = np.asarray(tau, dtype=float)
    n, f = tau.shape
    held = int(round(holdout * n))
    train = n - held
    y = tau - problem.known
    model_rank = np.linalg.matrix_rank(problem.inertial[:train].reshape(train * f, -1))
    if train * f < model_rank + 20 or train < 20:
        raise InputError(f"{train} training samples x {f} coordinates cannot test effects beyond the "
                         f"{model_rank} identifiable inertial parameters: give more samples or a smaller "
                         "--holdout", key="samples")
    rows = slice(0, train)
    candidates = [c.rows(rows) for c in problem.candidates]
    chosen = select(problem.inertial[rows], y[rows], candidates, alpha, max_steps)

    added_full = [problem.candidates[i] for i in chosen.in_model]
    last = chosen.steps[-1]
    remaining = last.chosen is not None         # stopped at max_steps with something significant
    before = _predict(problem.inertial, [], y, chosen.steps[0].fit, train)
    after = _predict(problem.inertial, added_full, y, None if remaining else last.fit, train)
    floor, noise_only = holdout_floor(after.fit, after.model[train:], tau[train:]) if held else (None, None)
    gap = {"before": nrms(before.residual[rows], tau[rows]),
           "after": nrms(after.residual[rows], tau[rows]),
           "holdout_before": nrms(before.residual[train:], tau[train:]) if held else None,
           "holdout_after": nrms(after.residual[train:], tau[train:]) if held else None,
           "holdout_floor": floor, "holdout_noise_floor": noise_only}
    gap["per_coordinate"] = {c: {"before": nrms(before.residual[rows, j:j + 1], tau[rows, j:j + 1]),
                                 "after": nrms(after.residual[rows, j:j + 1], tau[rows, j:j + 1])}
                             for j, c in enumerate(problem.coordinates)}

    ambiguous_idx = set(chosen.ambiguous)
    estimates = coefficients(problem.inertial[rows], candidates, chosen.in_model, y[rows], after.fit.weights)
    effects = []
    for i, (values, stds) in zip(chosen.added, estimates):
        if i in ambiguous_idx:
            continue
        effects.append(_effect_entry(problem.candidates, values, stds, chosen, i))
    ambiguous = [_ambiguous_entry(problem.candidates, chosen, i, estimates[chosen.added.index(i)])
                 for i in chosen.added if i in ambiguous_idx]
    unexplained = _unexplained(after, train, problem.coordinates, alpha)
    closed = bool(unexplained["white"] and not remaining)
    unexplained["significant_candidates_left"] = remaining
    unexplained["max_steps"] = max_steps
    first = chosen.steps[0]
    untestable = [f"{c.label} ({t.reason})" for c, t in zip(candidates, first.tests) if not t.tested]
    unexplained["confusable_with_model"] = _weak(problem.inertial[rows], candidates, first)
    notes = list(problem.notes)
    for old, new in chosen.regrouped:
        notes.append(f"{candidates[old].label} and its rivals were ambiguous when they entered (their "
                     "difference acts on too few samples to test while other effects were missing from "
                     f"the residual); compared again in the complete model: {candidates[new].label} "
                     + ("leads a smaller group" if new in chosen.ambiguous else
                        "is named" if new in chosen.added else "won, and was later taken out"))
    for i, test, bar in chosen.removed:
        given = (f"p = {test.pvalue:.3g} > {bar:.3g}, the bar it entered by" if test.tested else
                 f"nothing testable of it is left ({test.reason})")
        notes.append(f"{candidates[i].label} was named, then taken out: once the effects named after it "
                     f"are in, it adds nothing significant ({given})")
    if remaining:
        notes.insert(0, f"the search stopped at --max-steps {max_steps} with candidates still significant: "
                        "what is named is incomplete; raise --max-steps to go on")
    if untestable:
        notes.append(f"{len(untestable)} candidates not testable on this data: 'absorbed' (no direction "
                     "beyond the inertial model: not identifiable) or 'support' (acting on too few samples)")
    return Diagnosis(problem.mechanism.name, problem.coordinates, alpha, train, held, effects, ambiguous,
                     gap, unexplained, _steps_json(candidates, chosen), untestable, closed, notes,
                     problem.t, before.residual, after.residual, added_full)


@dataclass
class _Prediction:
    residual: np.ndarray          # (N, f), unweighted, every sample
    fit: Fit                      # the weighted fit on the training rows
    model: np.ndarray             # (N, f, p): the fitted model's columns, every sample


def _predict(inertial: np.ndarray, added: list[Candidate], y: np.ndarray, fit: Fit | None,
             train: int) -> _Prediction:
    """Predict every row from the weighted ``fit`` on the first ``train`` rows of the
    inertial model plus ``added`` (the selection's own; None: fit it here)."""
    model = np.concatenate([inertial] + [c.columns for c in added], axis=-1)
    if fit is None:
        fit = weighted_fit(model[:train], y[:train])
    return _Prediction(y - model @ fit.coefficients, fit, model)


def holdout_floor(fit: Fit, rows: np.ndarray, tau: np.ndarray) -> tuple[float, float]:
    """(prediction floor, noise floor) on held-out model ``rows`` (m, f, p) with measured
    ``tau`` (m, f), in the normalisation of :func:`nrms`, from the training ``fit``'s own
    noise levels and coefficient covariance: the NRMS a correct model reaches there on
    average (squared: the mean of sigma_c^2 + x^T Cov x over the rows,
    :meth:`Fit.prediction_variance`), and the noise SD alone. The noise SD is the floor of a
    fitted residual, not of a prediction: where a held-out row lies far from the fitted ones
    (the SLA's arms next to their toggle, one sample holding half the inertial columns'
    energy) the coefficients' error is amplified."""
    sigma = np.broadcast_to(1.0 / fit.weights, tau.shape)
    return nrms(np.sqrt(fit.prediction_variance(rows)), tau), nrms(sigma, tau)


def nrms(residual: np.ndarray, tau: np.ndarray) -> float:
    """Normalized RMS: per coordinate RMS(residual) / RMS(tau), then the RMS over the
    coordinates (each coordinate counts equally, whatever its units)."""
    scale = np.sqrt(np.mean(tau ** 2, axis=0))
    scale[scale == 0] = 1.0
    per = np.sqrt(np.mean(residual ** 2, axis=0)) / scale
    return float(np.sqrt(np.mean(per ** 2)))


def coefficients(inertial: np.ndarray, candidates: list[Candidate], added: list[int], y: np.ndarray,
                 weights: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each added effect's coefficients and HAC standard deviations in the final model
    (Frisch-Waugh-Lovell: the effect columns with the inertial model projected out), with
    the final model's noise ``weights`` (None: estimated here)."""
    if not added:
        return []
    n, f, _ = inertial.shape
    blocks = [candidates[i].columns for i in added]
    full = weighted_fit(np.concatenate([inertial] + blocks, axis=-1), y, weights)
    base = weighted_fit(inertial, y, full.weights)
    Z = np.concatenate(blocks, axis=-1) * full.weights[None, :, None]
    Z = project_out(Z.reshape(n * f, -1), base.basis)
    e = base.residual
    gamma, *_ = np.linalg.lstsq(Z, e, rcond=None)
    r = e - Z @ gamma
    lags = hac_lags(r.reshape(n, f))
    scores = (Z * r[:, None]).reshape(n, f, -1).sum(axis=1)
    S = S_hac_simple(scores, nlags=lags) * (n * f) / max(n * f - full.rank, 1)
    H = np.linalg.pinv(Z.T @ Z)
    std = np.sqrt(np.maximum(np.diag(H @ S @ H), 0.0))
    out, start = [], 0
    for block in blocks:
        width = block.shape[-1]
        out.append((gamma[start:start + width], std[start:start + width]))
        start += width
    return out


def _coefficient_map(cand: Candidate, values: np.ndarray, stds: np.ndarray) -> dict:
    names = registry.effects()[cand.kind].item.coefficients
    return {name: {"value": float(v), "std": float(s)} for name, v, s in zip(names, values, stds)}


def _effect_entry(all_candidates: list[Candidate], values, stds, chosen: Selection, index: int) -> dict:
    cand = all_candidates[index]
    coefficients_ = _coefficient_map(cand, values, stds)
    single = len(coefficients_) == 1
    step = next(s for s in chosen.steps if s.chosen == index)
    test = step.tests[index]
    return {"kind": cand.kind, "coordinate": cand.coordinate,
            "value": float(values[0]) if single else {k: v["value"] for k, v in coefficients_.items()},
            "std": float(stds[0]) if single else {k: v["std"] for k, v in coefficients_.items()},
            "coefficients": coefficients_,
            "test": {"stat": test.stat, "df": test.df, "pvalue": test.pvalue,
                     "pvalue_holm": float(step.adjusted[index])},
            "rivals": [_rival_json(all_candidates[r.index], r) for r in step.beaten]}


def _rival_json(rival_candidate: Candidate, rival: Rival) -> dict:
    """A rival the named effect was tested against and beat: the evidence."""
    return {"candidate": rival_candidate.label, "correlation": rival.correlation,
            "pvalue_named_over_rival": rival.winner_over_rival.pvalue,
            "pvalue_rival_over_named": rival.rival_over_winner.pvalue}


def _ambiguous_entry(all_candidates: list[Candidate], chosen: Selection, index: int, estimate) -> dict:
    step = next(s for s in chosen.steps if s.chosen == index)
    members = [index] + [r.index for r in chosen.ambiguous[index]]
    cands = [all_candidates[i] for i in members]
    evidence = []
    for r in chosen.ambiguous[index]:
        evidence.append({"candidate": all_candidates[r.index].label,
                         "correlation": r.correlation,
                         "pvalue": step.tests[r.index].pvalue,
                         "pvalue_strongest_over_it": r.winner_over_rival.pvalue,
                         "pvalue_it_over_strongest": r.rival_over_winner.pvalue})
    return {"candidates": [{"kind": c.kind, "coordinate": c.coordinate,
                            "pvalue": step.tests[i].pvalue, "pvalue_holm": float(step.adjusted[i])}
                           for c, i in zip(cands, members)],
            "strongest": all_candidates[index].label,
            "evidence": evidence,
            "separate_by": separation([c.kind for c in cands], False),
            "reason": "the data cannot tell these apart: none adds significantly to what the "
                      "strongest explains, and it adds nothing significant over them (at the bar a "
                      "further effect must clear when each adds at alpha)"}


def _steps_json(candidates: list[Candidate], chosen: Selection) -> list[dict]:
    out = []
    for step in chosen.steps:
        tests = [{"candidate": c.label, "stat": t.stat, "df": t.df, "pvalue": t.pvalue,
                  "pvalue_holm": float(a), "z": t.z if np.isfinite(t.z) else None}
                 for c, t, a in zip(candidates, step.tests, step.adjusted) if t.tested]
        out.append({"chosen": candidates[step.chosen].label if step.chosen is not None else None,
                    "ambiguous_with": [candidates[r.index].label for r in step.confusable],
                    "tests": sorted(tests, key=lambda d: -(d["z"] if d["z"] is not None else -1e300))})
    return out


def _weak(inertial: np.ndarray, candidates: list[Candidate], first) -> list[dict]:
    """Candidates nearly collinear with the inertial model: what fraction of them survives
    beyond the first step's (inertial-only) weighted fit."""
    fit = first.fit
    n, f, _ = inertial.shape
    out = []
    for cand, test in zip(candidates, first.tests):
        if not test.tested:
            continue
        Z = (cand.columns * fit.weights[None, :, None]).reshape(n * f, -1)
        norms = np.linalg.norm(Z, axis=0)
        norms[norms == 0] = 1.0
        kept = float(np.linalg.svd(project_out(Z / norms, fit.basis), compute_uv=False).min())
        if kept < WEAK:
            out.append({"candidate": cand.label, "kept": kept, "separate_by": MODEL_HINT})
    return out


def noise_floor(residual: np.ndarray) -> np.ndarray:
    """Per-coordinate noise SD from second differences (white noise: var = 6 sigma^2); a
    smooth missing force barely changes it."""
    d2 = np.diff(residual, n=2, axis=0)
    return np.sqrt(np.mean(d2 ** 2, axis=0) / 6.0)


def _unexplained(prediction: _Prediction, train: int, coordinates, alpha: float) -> dict:
    """Whiteness of the final fit's residual per coordinate (Ljung-Box, its null simulated
    through the fit: :mod:`.whiteness`; Holm over the coordinates) and the residual against
    the noise level."""
    residual, fit = prediction.residual, prediction.fit
    fit_part, hold_part = residual[:train], residual[train:]
    sigma = noise_floor(fit_part)
    lags = min(LJUNG_BOX_LAGS, max(1, train // 5))
    weighted = fit.residual.reshape(train, len(coordinates))
    stats, pvalues = monte_carlo_pvalues(weighted, fit.basis, lags, alpha)
    flat = np.std(weighted, axis=0) == 0
    pvalues[flat] = 1.0
    count = replicates(len(coordinates), alpha)
    boxes = {c: {"stat": float(stats[j]), "pvalue": float(pvalues[j]), "lags": lags, "replicates": count}
             for j, c in enumerate(coordinates)}
    reject = holm(pvalues) <= alpha
    rms = np.sqrt(np.mean(fit_part ** 2, axis=0))
    hold_rms = np.sqrt(np.mean(hold_part ** 2, axis=0)) if len(hold_part) else None
    safe = np.where(sigma > 0, sigma, np.nan)
    return {
        "white": bool(not reject.any()),
        "ljung_box": boxes,
        "noise_level": dict(zip(coordinates, sigma.tolist())),
        "residual_rms": dict(zip(coordinates, rms.tolist())),
        "ratio": dict(zip(coordinates, _finite(rms / safe))),
        "holdout_ratio": dict(zip(coordinates, _finite(hold_rms / safe))) if hold_rms is not None else None,
    }


def _finite(values: np.ndarray) -> list:
    return [float(v) if np.isfinite(v) else None for v in values]


def diagnose_data(mechanism: Mechanism, data: MeasuredData, *, selection: Sequence[str] | None = None,
                  alpha: float = 0.05, holdout: float = 0.3, max_steps: int = MAX_STEPS) -> Diagnosis:
    """:func:`prepare` then :func:`diagnose` on measured data (the CSV's notes kept)."""
    problem = prepare(mechanism, data.motion, data.sample, selection, data)
    problem.notes = list(data.notes) + problem.notes
    return diagnose(problem, data.tau, alpha=alpha, holdout=holdout, max_steps=max_steps)


# ----- writing the fixed mechanism ---------------------------------------------------------
def decimal_text(value: float) -> str:
    """A float as a plain decimal string (exact in the mechanism format, no exponent)."""
    return format(Decimal(repr(float(value))), "f")


def effects_toml(effects: Sequence[EffectSpec], origin: str) -> str:
    """``[[effects]]`` tables for ``effects`` (coefficients as decimal strings)."""
    lines = ["", f"# Added by baseparams diagnose ({origin}): estimated effects."]
    for spec in effects:
        values = ", ".join(f'{name} = "{decimal_text(v)}"' for name, v in spec.values.items())
        lines += ["[[effects]]", f'kind = "{spec.kind}"', f'coordinate = "{spec.coordinate}"',
                  f"values = {{ {values} }}", ""]
    return "\n".join(lines)


def write_fixed(mechanism: Mechanism, effects: Sequence[EffectSpec], path: str | os.PathLike,
                origin: str = "") -> Mechanism:
    """Write the mechanism's own TOML text with ``effects`` appended as ``[[effects]]`` tables
    (the user's file stays as it was above them), check that it loads back with them, and
    write it atomically. Returns the mechanism read back."""
    source = mechanism.path
    if not source or Path(source).suffix.lower() != ".toml":
        raise InputError(f"--write needs a TOML mechanism file; {mechanism.name} was read from "
                         f"{source or 'no file'}", key="--write")
    try:
        text = Path(source).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=source) from None
    fixed = text.rstrip("\n") + "\n" + effects_toml(effects, origin)
    back = parse_mechanism(fixed, path=str(path))
    have = {(e.kind, e.coordinate) for e in back.effects}
    missing = [f"{e.kind}:{e.coordinate}" for e in effects if (e.kind, e.coordinate) not in have]
    if missing:
        raise InputError(f"the written mechanism does not load back with {', '.join(missing)}",
                         file=str(path), key="effects")
    atomic_write(path, fixed)
    return back
