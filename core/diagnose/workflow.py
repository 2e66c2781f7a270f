"""Discrepancy diagnosis: where the model and measured data disagree, which effect is
missing, and how much of the gap it closes.

The inertial model (every standard parameter free, fitted through the column space of the
regressor; or held as given, ``--params``) is fitted to the data (a last ``holdout``
fraction may be kept out of everything). Candidate effects (:mod:`.candidates`, and the
derived ones of :mod:`.derived`) are added one at a time by the tests of :mod:`.selection`
(coloured noise whitened); confusable candidates are reported together under ``ambiguous``
with the excitation that would separate them, never named. A candidate that entered the
model is named only when it also holds out of sample (:mod:`.outofsample`: physical,
predicting held-out blocks better, one coefficient for the recording) and is larger than
the structure left beside it; the others are ``unsupported``. The report leads with a
verdict; it gives each named effect's coefficients with HAC standard deviations, the gap
(NRMS) before and after, fitted and block cross-validated, where the gap remains (blocks,
motion regimes), and a Ljung-Box whiteness test of the residual against the noise level
estimated from its second differences (which a smooth missing force does not reach).

Effects the mechanism already has (``[[effects]]``): with every coefficient given they are
known forces, subtracted from tau; otherwise their coefficients are fitted with the inertial
model. Neither is a candidate.
"""

import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import numpy as np
from scipy.special import ndtri
from scipy.stats import chi2

from baseparams import registry
from baseparams.errors import InputError
from baseparams.diagnose import derived
from baseparams.diagnose.candidates import known_effect, known_values, library, parse_selection
from baseparams.diagnose.given import Given
from baseparams.diagnose.identifiable import Regrouping, regroup
from baseparams.diagnose.derived import KINDS as DERIVED_KINDS
from baseparams.diagnose.outofsample import FOLDS, CrossValidation, blocks, cross_validate, held_out_gain, stability
from baseparams.identify.impossible import implausible
from baseparams.recordings.data import MeasuredData, bandwidth
from baseparams.io.atomic import atomic_write
from baseparams.dynamics.forces import (Motion, design, effect_values, effects_design, evaluate,
                                       independent_names)
from baseparams.identify.fit import measured_design, measured_forces
from baseparams.identify.linear import RANK_TOL, LinearFit as Fit, WeightedLinearModel
from baseparams.numeric.linalg import svd
from baseparams.numeric.rank import numerical_rank
from baseparams.diagnose.final import added_test, outdone, simpler_in_place, weakest_over
from baseparams.diagnose.selection import BODY_KINDS, Candidate, Rival, Selection, Step, select_whitened
from baseparams.diagnose.wald import Test, holm
from baseparams.diagnose.whiteness import (MOTION_BASIS_NAMES, MOTION_BLOCKS, monte_carlo_pvalues, motion_basis,
                                            predictable, replicates)
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
    for many datasets on the same motion): ``inertial`` (N, f, P) the columns fitted to the
    data (the standard parameters plus the mechanism's effects with unknown coefficients;
    with a given simulation only those effects); ``known`` (N, f) the force the model
    already gives (known effects, known payloads, and the given simulation's torque);
    the candidates; ``qd`` (N, f) the independent speeds; ``bodies`` (N, f, P) the standard
    columns when the inertial parameters are given (body and payload candidates), else None."""
    mechanism: Mechanism
    coordinates: tuple[str, ...]
    t: np.ndarray
    inertial: np.ndarray
    known: np.ndarray
    candidates: list[Candidate]
    notes: list[str] = field(default_factory=list)
    qd: np.ndarray | None = None
    bodies: np.ndarray | None = None
    given: np.ndarray | None = None            # the given standard parameters (P,), or None
    wanted: set | None = None                  # derived candidates to build (None: all)
    # white noise's autocorrelation at the fit's lags after the recording's filter and
    # decimation (MeasuredData.noise_correlation), None when nothing was filtered
    correlation: np.ndarray | None = None
    given_masses: bool = True                  # whether given's body masses are the bodies' (given.Given)
    # an identify result held as given: E (r, P) to its base parameters and their covariance (r, r)
    given_uncertainty: tuple[np.ndarray, np.ndarray] | None = None
    quanta: np.ndarray | None = None           # (f,) the forces' quantisation steps (MeasuredData.quanta)
    # an identify result held as given: its residual NRMS on its own run (f,), NaN where unknown
    held_nrms: np.ndarray | None = None


def prepare(mechanism: Mechanism, motion: Motion, sample: Sample | None = None,
            selection: Sequence[str] | None = None, data: MeasuredData | None = None,
            given: np.ndarray | None = None) -> Problem:
    """The inertial and candidate columns along ``motion``; ``selection``: ``KIND[:COORD]``
    strings restricting the candidates (None: every registered effect on every coordinate
    and motor, and the derived candidates of :mod:`.derived`). With measured ``data`` every
    column is reduced to the fit's rows as its torques were (parallel filtering), and its
    known payloads' forces count as known. ``given``: standard parameters (P,) held as
    given (diagnose a simulation): their torque is known, and bodies become candidates."""
    sample = sample if sample is not None else evaluate(mechanism, motion)
    pairs = parse_selection(mechanism, selection, given is not None) if selection else None
    known_specs = [e for e in mechanism.effects if known_effect(e)]
    fitted_specs = [e for e in mechanism.effects if not known_effect(e)]
    t = np.asarray(motion.t, float)
    qd = np.asarray(motion.qd, float)
    reduce = None
    correlation = None
    if data is not None:
        correlation = data.noise_correlation() if data.reduced else None
        inertial, fitted, known = measured_design(mechanism, data, fitted_specs, known_specs)   # as identify's
        reduce, t = data.reduce, data.t
        qd = qd[data.kept_rows()]
    else:
        inertial, fitted = design(mechanism, motion, fitted_specs, sample)
        known = effects_design(mechanism, sample, motion.count, known_specs).matrix @ \
            effect_values(mechanism, known_specs) if known_specs else np.zeros(inertial.matrix.shape[:2])
    registered = None if pairs is None else [(k, c) for k, c in pairs if k not in DERIVED_KINDS]
    candidates, notes = library(mechanism, sample, motion.count, registered, reduce) \
        if registered is None or registered else ([], [])
    if known_specs:
        notes.append("known effects subtracted: " + ", ".join(f"{e.kind}:{e.coordinate}" for e in known_specs))
    if fitted_specs:
        notes.append("effects fitted with the inertial model: "
                     + ", ".join(f"{e.kind}:{e.coordinate}" for e in fitted_specs))
    wanted = None if pairs is None else {(k, c) for k, c in pairs if k in DERIVED_KINDS}
    if not candidates and wanted == set():
        raise InputError("no candidate effects left to test (every selected effect is already "
                         "in the mechanism)", key="--candidates")
    quanta = data.quanta if data is not None else None
    if given is not None:
        given = np.asarray(given, dtype=float)
        known = known + inertial.matrix @ given
        notes.append("the inertial parameters are held as given (--params): bodies, payloads and "
                     "torque gains are candidates")
        return Problem(mechanism, independent_names(mechanism), t, fitted.matrix, known, candidates, notes,
                       qd, inertial.matrix, given, wanted, correlation, quanta=quanta)
    model = np.concatenate([inertial.matrix, fitted.matrix], axis=-1)
    return Problem(mechanism, independent_names(mechanism), t, model, known, candidates, notes, qd,
                   None, None, wanted, correlation, quanta=quanta)


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
    verdict: str = ""
    unsupported: list[dict] = field(default_factory=list)
    where: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"mechanism": self.mechanism, "verdict": self.verdict, "coordinates": list(self.coordinates),
                "effects": self.effects, "ambiguous": self.ambiguous, "unsupported": self.unsupported,
                "gap": self.gap, "where": self.where,
                "unexplained": self.unexplained, "closed": self.closed, "alpha": self.alpha,
                "samples": {"fit": self.training, "holdout": self.held_out},
                "steps": self.steps, "untestable": self.untestable, "notes": self.notes}

    def named(self) -> list[EffectSpec]:
        """The named effects that are mechanism effects (registered kinds), with their
        estimated coefficients and fitted shapes."""
        effects = registry.effects()
        return [EffectSpec(e["kind"], e["coordinate"],
                           {**{k: v["value"] for k, v in e["coefficients"].items()}, **e.get("shape", {})})
                for e in self.effects if e["kind"] in effects]


# ----- the loop ------------------------------------------------------------------------------
def diagnose(problem: Problem, tau: np.ndarray, *, alpha: float = 0.05, holdout: float = 0.0,
             folds: int = FOLDS, max_steps: int | None = None) -> Diagnosis:
    """Fit, test, add, repeat (see the module docstring); ``tau`` (N, f) measured forces.
    ``max_steps`` None: until nothing is significant (every step adds one candidate or takes
    one out for good, so the search ends)."""
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha must be in (0, 1), not {alpha}", key="--alpha")
    if not 0.0 <= holdout < 1.0:
        raise InputError(f"holdout must be in [0, 1), not {holdout}", key="--holdout")
    if not 2 <= folds <= 100:
        raise InputError(f"folds must be in 2..100, not {folds}", key="--folds")
    tau = np.asarray(tau, dtype=float)
    n, f = tau.shape
    held = int(round(holdout * n))
    train = n - held
    y = tau - problem.known
    model = reduced_model(problem.inertial, train)
    model_rank = model.shape[-1]
    if train * f < model_rank + 20 or train < 20 or train < 4 * folds:
        raise InputError(f"{train} training samples x {f} coordinates cannot test effects beyond the "
                         f"{model_rank} identifiable inertial parameters: give more samples or a smaller "
                         "--holdout", key="samples")
    rows = slice(0, train)
    built, lag = _derived(problem, model, y, rows)
    everything = problem.candidates + built
    if not everything:
        raise InputError("no candidate effects left to test", key="--candidates")
    candidates = [c.rows(rows) for c in everything]
    limit = max_steps if max_steps is not None else 2 * len(candidates) + 2
    # data the inertial model reproduces to rounding (simulated without noise) leave nothing
    # to test: every candidate would be judged on the arithmetic's rounding
    exact = _at_rounding(model[rows], y[rows], tau[rows])
    chosen = select_whitened(model[rows], y[rows], [] if exact else candidates, alpha, limit)
    candidates = chosen.candidates                       # shaped ones fixed where they entered
    full = [_fixed(everything[i], c) for i, c in enumerate(candidates)]
    last = chosen.steps[-1]
    remaining = last.chosen is not None         # stopped at max_steps with something significant
    ambiguous_idx = set(chosen.ambiguous)
    named = [i for i in chosen.added if i not in ambiguous_idx]

    # out of sample: plausibility, block cross-validation, stability over the blocks
    weights = last.fit.weights
    checks: dict = {}
    lag = lag.rows(rows) if lag is not None else None
    whiten = last.whiten
    # ambiguous groups first: one that does not predict held-out blocks leaves the model before
    # the named effects are judged (it shares what they explain: judged beside it, Coulomb
    # friction on the TX40's joint 2 was too small to name, and both left)
    groups = {head: [head] + [r.index for r in rivals] for head, rivals in chosen.ambiguous.items()}
    _, unsupported = _gate(problem, model[rows], candidates, chosen.in_model, [], y[rows], weights, alpha, folds,
                           checks, groups=groups)
    dropped = {j for u in unsupported for j in u["members"]}
    in_model = [i for i in chosen.in_model if i not in dropped]
    kept_named, held_back = _gate(problem, model[rows], candidates, in_model, named, y[rows],
                                  weights, alpha, folds, checks, lag, whiten)
    unsupported += held_back
    dropped |= {u["index"] for u in held_back}
    in_model = [i for i in in_model if i not in dropped]
    level = alpha / len(named) if named else alpha         # the gate's bar (Bonferroni over the named)
    replaced = _simpler_forms(problem, model[rows], y[rows], chosen, everything, full, unsupported, kept_named,
                              in_model, weights, level, folds, checks, lag)
    replaced += _in_each_others_place(problem, model[rows], y[rows], chosen, unsupported, kept_named, in_model,
                                      weights, level, folds, checks, lag)
    for i, reason in _lag_stand_ins(problem, model[rows], y[rows], chosen, in_model, kept_named, level, lag):
        kept_named.remove(i)
        in_model.remove(i)
        checks.pop(i, None)
        unsupported.append(_held_back(candidates, i, reason))
    before = _predict(model, [], y, chosen.steps[0].fit, train)
    after = _predict(model, [full[i] for i in in_model], y, None, train)
    # structure left beside a named effect: is the effect larger than what is left there?
    size = np.sqrt(np.mean(tau[rows] ** 2, axis=0))
    unexplained = _unexplained(after, train, problem.coordinates, alpha, size, problem.correlation, problem.quanta)
    dominated = _dominated(after, train, [full[i] for i in in_model], in_model, kept_named, problem.coordinates,
                           alpha, unexplained)
    if dominated:
        for i, reason in dominated:
            unsupported.append(_held_back(candidates, i, reason))
        in_model = [i for i in in_model if i not in {i for i, _ in dominated}]
        after = _predict(model, [full[i] for i in in_model], y, None, train)
        unexplained = _unexplained(after, train, problem.coordinates, alpha, size, problem.correlation, problem.quanta)
    # what the identification held as given already lacked on its own run is not a change
    while (lacking := _held_lack_named(problem, model[rows], candidates, in_model, kept_named, groups, dropped,
                                       y[rows], after.fit.weights, size, after.residual[rows])) is not None:
        members, reason = lacking
        kept_named[:] = [i for i in kept_named if i not in members]
        in_model = [i for i in in_model if i not in members]
        dropped |= set(members)
        unsupported.append(_held_back(candidates, members[0], reason))
        after = _predict(model, [full[i] for i in in_model], y, None, train)
        unexplained = _unexplained(after, train, problem.coordinates, alpha, size, problem.correlation, problem.quanta)
    # physical in the final model too: a sign judged beside effects that later checks took out
    # can turn without them (a noise-free SLA: a rotor inertia of -162 was named)
    while True:
        estimates = coefficients(model[rows], candidates, in_model, y[rows], after.fit.weights)
        turned = _turned(problem, candidates, in_model, kept_named, estimates) or \
            _given_errors(problem, model[rows], candidates, in_model, kept_named, y[rows], after.fit.weights,
                          estimates)
        if not turned:
            break
        for i, reason in turned:
            unsupported.append(_held_back(candidates, i, reason))
        in_model = [i for i in in_model if i not in dict(turned)]
        after = _predict(model, [full[i] for i in in_model], y, None, train)
        unexplained = _unexplained(after, train, problem.coordinates, alpha, size, problem.correlation, problem.quanta)
    floor, noise_only = holdout_floor(after.fit, after.model[train:], tau[train:]) if held else (None, None)
    gap: dict = {"before": nrms(before.residual[rows], tau[rows]),
           "after": nrms(after.residual[rows], tau[rows]),
           "holdout_before": nrms(before.residual[train:], tau[train:]) if held else None,
           "holdout_after": nrms(after.residual[train:], tau[train:]) if held else None,
           "holdout_floor": floor, "holdout_noise_floor": noise_only}
    gap.update(_cross_validated(model[rows], [candidates[i] for i in in_model], y[rows], tau[rows],
                                after.fit.weights, folds))
    gap["per_coordinate"] = {c: {"before": nrms(before.residual[rows, j:j + 1], tau[rows, j:j + 1]),
                                 "after": nrms(after.residual[rows, j:j + 1], tau[rows, j:j + 1])}
                             for j, c in enumerate(problem.coordinates)}

    by_index = dict(zip(in_model, estimates))
    regrouped = _regroupings(model[rows], candidates, in_model, kept_named, y[rows], after.fit.weights)
    effects = [{**_effect_entry(candidates, by_index[i][0], by_index[i][1], chosen, i, regrouped.get(i)),
                "checks": checks.get(i, {}), **_known_entry(problem, candidates[i])}
               for i in chosen.added if i not in ambiguous_idx and i in by_index]
    ambiguous = [_ambiguous_entry(candidates, chosen, i, by_index.get(i), problem.mechanism, by_index)
                 for i in chosen.added if i in ambiguous_idx and i not in dropped]
    unsupported += _sparse_left(model[rows], y[rows], candidates, in_model, last, weights, alpha)
    rounding = _within_rounding(problem, model[rows], candidates, in_model, unsupported, y[rows], after.fit.weights)
    rounding |= _left_nothing(model[rows], y[rows], candidates, in_model, unsupported, last.whiten, weights, alpha)
    notes_colour: list[str] = []
    structure, adds_nothing = _predictable(after, train, problem, alpha, size, unexplained, notes_colour,
                                           candidates, unsupported, rounding)
    rounding |= adds_nothing
    closed = bool(not structure and not remaining and not [u for u in unsupported if u["index"] not in rounding])
    unexplained["significant_candidates_left"] = remaining
    unexplained["max_steps"] = max_steps
    first = chosen.steps[0]
    untestable = [f"{c.label} ({t.reason})" for c, t in zip(candidates, first.tests) if not t.tested]
    unexplained["confusable_with_model"] = _weak(model[rows], candidates, first)
    where = _where(after.residual[rows], tau[rows], problem.qd[rows] if problem.qd is not None else None,
                   problem.t[rows], problem.coordinates, unexplained["noise_level"], folds)
    named_any = bool(effects or ambiguous)
    verdict = ("explained" if closed else "partly explained") if named_any else \
        ("nothing missing" if closed else "unexplained")
    # the verdict follows its own cross-validation: named effects that predict held-out blocks
    # worse than the model without them explain nothing (a Kinova run: 0.69 -> 641.8, and the
    # verdict said "partly explained"); unless the model alone cannot be cross-validated
    blowup = gap["cv_before"] > CV_BLOWUP * max(gap["before"], 1e-300) and not exact
    grew = gap["cv_after"] > gap["cv_before"]
    if named_any and grew and not blowup:
        verdict, closed = "unexplained", False
    # a note says an effect is named only when it is in the lists: checks after the swap
    # (dominance, signs, a lag) can hold it back in turn
    listed = {i for i in chosen.added if i not in ambiguous_idx and i in by_index} | {
        j for i in chosen.added if i in ambiguous_idx and i not in dropped for j in [i] + [
            r.index for r in chosen.ambiguous[i]]}
    notes = list(problem.notes) + [named if j in listed else otherwise for j, named, otherwise in replaced]
    notes += _shared_bodies(candidates, regrouped)
    notes += _near_twins(effects)
    notes += notes_colour
    for coordinate, step in unexplained["quantised"].items():
        notes.append(f"{coordinate}: its residual is within half its force's quantisation step ({step:.4g}): "
                     "structure that small cannot be told from the rounding and is not judged")
    if exact:
        notes.append(f"the inertial model reproduces the data to rounding (NRMS {gap['before']:.3g}): data "
                     "without noise; no effect was tested")
    if blowup:
        notes.append(f"the inertial model predicts held-out blocks {gap['cv_before'] / gap['before']:.3g} times "
                     f"worse than it fits them ({gap['cv_before']:.3g} against {gap['before']:.3g}): too few "
                     "samples or too little motion in each block to cross-validate; the verdict rests on the "
                     "fit alone")
    for u in unsupported:
        u.pop("index")
        u.pop("members", None)
    for old, new in chosen.regrouped:
        notes.append(f"{candidates[old].label} and its rivals were ambiguous when they entered (their "
                     "difference acts on too few samples to test while other effects were missing from "
                     f"the residual); compared again in the complete model: {candidates[new].label} "
                     + ("leads a smaller group" if new in chosen.ambiguous and new in listed else
                        "is named" if new in listed else "won, and was later taken out or held back"))
    for i, test, bar in chosen.removed:
        given = (f"p = {test.pvalue:.3g} > {bar:.3g}, the bar it entered by" if test.tested else
                 f"nothing testable of it is left ({test.reason})")
        notes.append(f"{candidates[i].label} was named, then taken out: once the effects named after it "
                     f"are in, it adds nothing significant ({given})")
    if remaining:
        notes.insert(0, f"the search stopped at --max-steps {max_steps} with candidates still significant: "
                        "what is named is incomplete; raise --max-steps to go on")
    if grew:
        notes.insert(0, f"the cross-validated gap grew with the named effects ({gap['cv_before']:.3g} -> "
                        f"{gap['cv_after']:.3g}): they do not predict held-out blocks better than the model "
                        "without them"
                        + ("; the verdict is 'unexplained': the names are reported, but they do not explain "
                           "the gap" if named_any and not blowup else ""))
    if untestable:
        notes.append(f"{len(untestable)} candidate{'s' if len(untestable) != 1 else ''} not testable on this data: "
                     "'absorbed' (no direction beyond the inertial model: not identifiable) or 'support' "
                     "(acting on too few samples)")
    return Diagnosis(problem.mechanism.name, problem.coordinates, alpha, train, held, effects, ambiguous,
                     gap, unexplained, _steps_json(candidates, chosen), untestable, closed, notes,
                     problem.t, before.residual, after.residual, [full[i] for i in in_model],
                     verdict, unsupported, where)


def reduced_model(columns: np.ndarray, train: int) -> np.ndarray:
    """The model's columns (N, f, p) replaced by its identifiable directions (N, f, r): the
    principal combinations of the unit-norm columns on the training rows whose singular
    value exceeds RANK_TOL of the largest. Per-coordinate weights scale rows, so the weighted
    range is the same (range(W K) = W range(K)), and every fit is a third cheaper on a robot
    whose 60 standard parameters hold 36 base ones."""
    n, f, p = columns.shape
    if p == 0:
        return columns
    A = columns[:train].reshape(train * f, p)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    _, sv, vt = svd(A / scale, full_matrices=False)
    rank = numerical_rank(tol=RANK_TOL, singular_values=sv)
    return np.ascontiguousarray(columns @ (vt[:rank].T / scale[:, None]))


def _derived(problem: Problem, model: np.ndarray, y: np.ndarray, rows: slice
             ) -> tuple[list[Candidate], derived.LagEvidence | None]:
    """The candidates built from the model's torque (:mod:`.derived`): the training fit of the
    model alone predicts it (with a given simulation: the given torque); and what tells a
    delay from other lags (every row), None without a delay candidate."""
    torque = problem.known.copy()
    wanted = problem.wanted
    delay: list[tuple[dict, np.ndarray]] = []
    lag: derived.LagEvidence | None = None
    alone = torque
    if model.shape[-1]:
        fit = WeightedLinearModel(model[rows], y[rows]).fit()
        alone = torque + model @ fit.coefficients
        torque = alone

        def at_weights(extra: np.ndarray) -> np.ndarray:
            """The model and ``extra`` (training rows) fitted at the model's weights: the
            model's fit grown by the extra columns (an SVD update), else a refit."""
            grown = fit.extended((extra * fit.weights[None, :, None]).reshape(-1, extra.shape[-1]))
            if grown is not None:
                return grown.coefficients
            X = np.concatenate([model[rows], extra], axis=-1)
            return WeightedLinearModel(X, y[rows]).fit(fit.weights).coefficients

        if (wanted is None or any(kind == "delay" for kind, _ in wanted)) and len(problem.t) > 2:
            step = float(np.median(np.diff(problem.t)))
            band = bandwidth(problem.qd[rows], step) if problem.qd is not None else 0.0
            cutoffs = [m * band for m in derived.DELAY_CUTOFFS_PER_BANDWIDTH] if band > 0 else [None]
            for cutoff in cutoffs:               # the first low-pass's evidence tells a delay from a lag
                column, evidence = derived.delay_column(model, y, rows, problem.known, problem.t, alone,
                                                        at_weights, cutoff, band)
                lag = lag or evidence
                delay.append(({"low_pass_hz": cutoff} if cutoff is not None else {}, column))
        if problem.qd is not None and (wanted is None or any(kind == "load_friction" for kind, _ in wanted)):
            qd_ = problem.qd
            torque = derived.fitted_torque(model, y, rows, problem.known, alone, at_weights,
                                           lambda tau: derived.load_columns(tau, qd_))
    if problem.qd is None:          # a Problem built without speeds: no load friction to build
        wanted = {("delay", "all")} if wanted is None else {w for w in wanted if w[0] != "load_friction"}
    qd = problem.qd if problem.qd is not None else np.zeros_like(torque)
    out = derived.torque_candidates(problem.coordinates, problem.t, qd, torque, wanted, delay)
    if problem.bodies is not None:
        out += derived.given_candidates(problem.mechanism, problem.coordinates, alone, problem.bodies,
                                        problem.wanted)
    return out, lag


# A named effect on a coordinate whose residual still holds structure must be at least this
# many times the structure left there (RMS), or it may only stand in for what is missing.
DOMINANCE = 2.0
# A named effect must improve a typical held-out block's weighted residual (about n f: each
# coordinate's weighted noise variance is 1; outofsample.held_out_gain) by what an effect of
# at least this RMS, in noise SDs of one coordinate, gives (n ratio^2): below it, stand-ins
# for effects outside the catalogue (an offset or Coulomb friction for an elastic joint's
# lag, 0.02-3 %) were named.
MIN_EFFECT_TO_NOISE = 0.5


def _dominated(after: "_Prediction", train: int, added: list[Candidate], in_model: list[int], named: list[int],
               coordinates: Sequence[str], alpha: float, un: dict) -> list[tuple[int, str]]:
    """Named effects smaller than the structure their coordinate's residual still holds (not
    white: Ljung-Box; its size: sqrt(residual RMS^2 - noise level^2), the noise level from
    second differences). Why: on data with something the catalogue lacks (an elastic
    joint's lag), a small spring, cogging or viscous friction took a part of its signature
    and was named; the structure left beside it is as large as the effect itself. ``un``:
    :func:`_unexplained` of ``after``."""
    if not named:
        return []
    pvalues = np.array([un["ljung_box"][c]["pvalue"] for c in coordinates])
    structured = holm(pvalues.tolist()) <= alpha
    if not structured.any():
        return []
    rms = np.array([un["residual_rms"][c] for c in coordinates])
    noise = np.array([un["noise_level"][c] for c in coordinates])
    left = np.sqrt(np.maximum(rms ** 2 - noise ** 2, 0.0))
    coefficients = after.fit.coefficients[-sum(c.columns.shape[-1] for c in added):] if added else np.zeros(0)
    out, start = [], 0
    for index, cand in zip(in_model, added):
        width = cand.columns.shape[-1]
        force = cand.columns[:train] @ coefficients[start:start + width]
        start += width
        if index not in named:
            continue
        size = np.sqrt(np.mean(force ** 2, axis=0))
        j = int(np.argmax(size / np.where(noise > 0, noise, 1.0)))
        if structured[j] and size[j] < DOMINANCE * left[j]:
            out.append((index, f"structure is left on {coordinates[j]} as large as this effect (RMS {size[j]:.3g} "
                               f"against {left[j]:.3g} left): it may stand in for what is missing there"))
    return out


def _fixed(original: Candidate, chosen: Candidate) -> Candidate:
    """``original`` (every row) at the shape selection fixed ``chosen`` at."""
    if not original.variants or chosen.variants:
        return original
    k = next((k for k, shape in enumerate(original.shapes) if dict(shape) == chosen.shape), None)
    if k is not None:
        return original.at(k)
    assert original.make is not None
    return Candidate(original.kind, original.coordinate, original.names, original.make(chosen.shape), (), (),
                     dict(chosen.shape), original.generalises, original.make)


def _gate(problem: Problem, model: np.ndarray, candidates: list[Candidate], in_model: list[int], named: list[int],
          y: np.ndarray, weights: np.ndarray, alpha: float, folds: int, checks: dict,
          lag: derived.LagEvidence | None = None, whiten: Callable[[np.ndarray], np.ndarray] = lambda x: x,
          groups: dict[int, list[int]] | None = None) -> tuple[list[int], list[dict]]:
    """The named effects that hold up (physical, predicting held-out blocks, one coefficient for
    the whole recording, a delay not standing in for a resonant lag) and the others with
    their reasons (:mod:`.outofsample`); ``model``, ``y`` and ``lag`` (:func:`_derived`): the
    training rows; ``whiten``: the selection's last filter; ``checks`` receives each kept
    effect's figures. ``groups`` (an ambiguous group's strongest member: every member) must
    predict held-out blocks too, all members left out together: the ones that do not are
    returned with the others (index: the strongest member), their reason saying so."""
    groups = groups or {}
    if not named and not groups:
        return [], []
    checks.clear()
    blocks_ = [model] + [candidates[i].columns for i in in_model]
    X = np.concatenate(blocks_, axis=-1)
    fit = WeightedLinearModel(X, y).fit(weights)
    widths = [model.shape[-1]] + [candidates[i].columns.shape[-1] for i in in_model]
    offsets = np.cumsum([0] + widths)

    def span(i: int) -> range:
        return range(offsets[in_model.index(i) + 1], offsets[in_model.index(i) + 2])

    spans = {i: span(i) for i in named}
    together = {head: [c for j in members for c in span(j)] for head, members in groups.items()}
    cv_all, *cv_drops = cross_validate(X, y, weights, folds, leave_out=list(spans.values()) + list(together.values()))
    cv_without_of = dict(zip(spans, cv_drops))
    kept, out = [], []
    for head, cv_without in zip(together, cv_drops[len(spans):]):
        reason = _too_small(held_out_gain(cv_without, cv_all), y.shape[1])
        if reason:
            labels = " | ".join(candidates[j].label for j in groups[head])
            out.append({"index": head, "kind": candidates[head].kind, "coordinate": candidates[head].coordinate,
                        "values": {}, "reason": f"ambiguous ({labels}); all together: {reason}",
                        "members": list(groups[head])})
    level = alpha / len(named) if named else alpha
    inertial = model.shape[-1]
    held = np.maximum(np.sqrt(np.mean(y ** 2, axis=0)),             # what each coordinate's torque holds
                      np.sqrt(np.mean((X[:, :, :inertial] @ fit.coefficients[:inertial]) ** 2, axis=0)))
    for i in named:
        k = in_model.index(i)
        lo, hi = offsets[k + 1], offsets[k + 2]
        values = dict(zip(coefficient_names(candidates[i].kind), fit.coefficients[lo:hi].tolist()))
        reason = (_unphysical(problem, candidates[i], values)
                  or _cancelling(X[:, :, lo:hi] @ fit.coefficients[lo:hi], held, problem.coordinates))
        detail: dict = {}
        if not reason:
            others = np.r_[0:lo, hi:X.shape[-1]]
            cv_without = cv_without_of[i]
            gain = held_out_gain(cv_without, cv_all)
            partial = y - X[:, :, others] @ fit.coefficients[others]
            stable = stability(partial, candidates[i].columns, weights, folds)
            detail = {"cv_gain": gain, "stability_pvalue": stable.pvalue, "spread": stable.spread,
                      "per_block": stable.values}
            reason = _too_small(gain, y.shape[1])
            if not reason and stable.unstable(level):
                reason = (f"its coefficient changes from block to block (spread {stable.spread:.2g} of its value, "
                          f"p = {stable.pvalue:.2g}): it stands in for something the catalogue lacks")
            elif not reason and candidates[i].kind == "delay" and lag is not None:
                reason = (_second_order(X, y, weights, fit.rank, candidates[i], lag.curvature, level, detail)
                          or _one_joints_lag(X[:, :, others], y, weights, candidates[i], problem.coordinates,
                                             level, detail)
                          or _resonant_rival(model, y, candidates, in_model, i, lag, whiten, weights, level,
                                             detail))
            elif not reason and lag is not None and candidates[i].kind in LAG_STAND_INS:
                reason = _resonant_rival(model, y, candidates, in_model, i, lag, whiten, weights, level, detail)
        if reason:
            out.append({"index": i, "kind": candidates[i].kind, "coordinate": candidates[i].coordinate,
                        "values": values, "reason": reason, **detail})
        else:
            kept.append(i)
            checks[i] = detail
    return kept, out


# A named effect's force larger than this many times what its coordinate's torque holds
# (the measured torque's RMS, or the inertial model's part if larger) is cancelled by other
# columns rather than a force of the mechanism.
CANCELS = 10.0


def _cancelling(force: np.ndarray, held: np.ndarray, coordinates: Sequence[str]) -> str:
    """Why an effect's ``force`` (n, f) is not physical when it is many times what its
    coordinate's torque ``held`` (f,: the measured RMS, or the inertial part's if larger)
    ('' otherwise). Why: under a torque ripple in time, a spring (k 17 111) and cogging (c1
    -23 222) on one PUMA joint cancelled each other to a few N m, both 'significant' and
    steady over the blocks: each force was hundreds of times the joint's torque."""
    size = np.sqrt(np.mean(force ** 2, axis=0))
    ratio = size / np.where(held > 0, held, np.inf)
    j = int(np.argmax(ratio))
    if ratio[j] > CANCELS:
        return (f"its force on {coordinates[j]} (RMS {size[j]:.3g}) is {ratio[j]:.0f} times that coordinate's "
                f"torque (RMS {held[j]:.3g}): other columns cancel it, it is no force of the mechanism")
    return ""


def _too_small(gain: float, coordinates: int) -> str:
    """'' when an effect improving a typical held-out block's residual by ``gain`` (a
    fraction, :func:`.outofsample.held_out_gain`) is large enough to name; else why not."""
    if gain <= 0:
        return ("does not predict held-out blocks better: block cross-validation without it is "
                f"as good ({100 * gain:+.2g} % on a typical block)")
    if gain < MIN_EFFECT_TO_NOISE ** 2 / coordinates:
        return (f"too small to name: a held-out block improves by {100 * gain:.2g} % of its residual "
                "(geometric mean over the blocks), "
                f"what an effect of RMS under {MIN_EFFECT_TO_NOISE:g} times one coordinate's noise SD gives")
    return ""


def _simpler_forms(problem: Problem, model: np.ndarray, y: np.ndarray, chosen: Selection,
                   everything: list[Candidate], full: list[Candidate], unsupported: list[dict],
                   kept_named: list[int], in_model: list[int], weights: np.ndarray, alpha: float, folds: int,
                   checks: dict, lag: derived.LagEvidence | None) -> list[tuple[int, str, str]]:
    """Each held-back effect's simpler forms (:func:`.final.simpler_in_place`) tried in its
    place: one that clears the bar and passes the same checks (:func:`_gate`, at ``alpha``)
    is named instead, entered in ``chosen`` as a step, and the held-back effect leaves
    ``unsupported`` (it is superseded, not unexplained). Updates the lists given; returns
    the notes saying what was replaced: (the effect named instead, the note while it is
    named, the note once a later check holds it back too)."""
    notes = []
    for u in [u for u in unsupported if "members" not in u]:       # not an ambiguous group
        found = simpler_in_place(model, y, chosen, u["index"], in_model, alpha)
        if found is None:
            continue
        step, variant = found
        j = step.chosen
        assert j is not None
        cand = chosen.candidates[j] if variant < 0 else chosen.candidates[j].at(variant)
        trial = list(chosen.candidates)
        trial[j] = cand
        figures: dict = {}
        kept, _ = _gate(problem, model, trial, in_model + [j], [j], y, weights, alpha, folds, figures, lag,
                        chosen.steps[-1].whiten)
        if not kept:
            continue
        if variant >= 0:
            chosen.shaped[j] = chosen.candidates[j]
        chosen.candidates[j] = cand
        full[j] = _fixed(everything[j], cand)
        chosen.steps.insert(len(chosen.steps) - 1, step)
        chosen.added.append(j)
        chosen.bars[j] = chosen.bars.get(u["index"], alpha)
        in_model.append(j)
        kept_named.append(j)
        checks[j] = figures[j]
        unsupported.remove(u)
        held = chosen.candidates[u["index"]].label
        said = f"{held} was held back ({u['reason']}); {cand.label}, a simpler form it generalises, "
        notes.append((j, said + f"is named in its place (p = {step.tests[j].pvalue:.3g} against the other named "
                                "effects, and it passes the same checks)",
                      said + f"cleared the bar in its place (p = {step.tests[j].pvalue:.3g}) and was then held "
                             "back too (see unsupported)"))
    return notes


def _in_each_others_place(problem: Problem, model: np.ndarray, y: np.ndarray, chosen: Selection,
                          unsupported: list[dict], kept_named: list[int], in_model: list[int],
                          weights: np.ndarray, alpha: float, folds: int, checks: dict,
                          lag: derived.LagEvidence | None) -> list[tuple[int, str, str]]:
    """A held-back effect tried in the place of a named one on its coordinate: when it failed
    out of sample (too small, or predicting no block better) but in the named one's place
    predicts held-out blocks better by at least what a named effect must
    (:func:`_too_small`) and passes the same checks (:func:`_gate`), it is named instead,
    and the other is held back with that reason. Why: each effect is judged beside the
    others named, and a simpler form named later (:func:`_simpler_forms`) was never judged
    against it. A four-bar's load friction mu |tau| sign(qd) under AR noise, where the torque
    keeps its sign (correlation 0.998 with Coulomb friction beyond the model), failed beside
    position friction; position friction failed too, and Coulomb friction, its simpler form,
    was named in its place: 4 of 20 at effect/noise 20, where load friction in Coulomb
    friction's place predicts a typical block 49-600 % better. Updates the lists given;
    returns the notes saying what was swapped (as :func:`_simpler_forms`)."""
    notes: list[tuple[int, str, str]] = []
    f = y.shape[1]
    held = [u for u in unsupported if "members" not in u and "cv_gain" in u and _too_small(u["cv_gain"], f)]
    pairs = [(u, k) for u in held for k in kept_named
             if chosen.candidates[k].coordinate == chosen.candidates[u["index"]].coordinate and k != u["index"]]
    if not pairs:
        return notes
    # one block cross-validation of the named model with every held-back one beside it: the
    # named model and each swap are that model less some columns (partitioned inverses)
    order = in_model + [u["index"] for u in held]
    X = np.concatenate([model] + [chosen.candidates[j].columns for j in order], axis=-1)
    offsets = np.cumsum([0, model.shape[-1]] + [chosen.candidates[j].columns.shape[-1] for j in order])

    def span(j: int) -> list[int]:
        return list(range(offsets[order.index(j) + 1], offsets[order.index(j) + 2]))

    beside = [c for u in held for c in span(u["index"])]
    swaps = [sorted(set(beside) - set(span(u["index"])) | set(span(k))) for u, k in pairs]
    named_cv, *swapped_cv = cross_validate(X, y, weights, folds, leave_out=[beside] + swaps)[1:]
    gains = [held_out_gain(CrossValidation(named_cv.residual, named_cv.sse), CrossValidation(cv.residual, cv.sse))
             for cv in swapped_cv]
    done: set[int] = set()
    for (u, k), gain in zip(pairs, gains):
        i = u["index"]
        if i in done or k not in kept_named or _too_small(gain, f):
            continue
        trial_model = [j for j in in_model if j != k] + [i]
        figures: dict = {}
        kept, _ = _gate(problem, model, chosen.candidates, trial_model, [i], y, weights, alpha, folds,
                        figures, lag, chosen.steps[-1].whiten)
        if not kept:
            continue
        named_label, held_label = chosen.candidates[k].label, chosen.candidates[i].label
        unsupported.remove(u)
        unsupported.append(_held_back(chosen.candidates, k, f"{held_label} in its place predicts held-out "
                                                             f"blocks {100 * gain:.3g} % better (typical block)"))
        in_model[:] = trial_model
        kept_named[:] = [j for j in kept_named if j != k] + [i]
        checks.pop(k, None)
        checks[i] = figures[i]
        done.add(i)
        said = (f"{held_label} was held back ({u['reason']}); in the place of {named_label} it predicts "
                f"held-out blocks {100 * gain:.3g} % better on a typical block and passes the same checks: ")
        notes.append((i, said + f"it is named instead of {named_label}",
                      said + f"it replaced {named_label}, and was then held back too (see unsupported)"))
    return notes


def _lag_stand_ins(problem: Problem, model: np.ndarray, y: np.ndarray, chosen: Selection, in_model: list[int],
                   named: list[int], level: float, evidence: derived.LagEvidence | None
                   ) -> list[tuple[int, str]]:
    """Named effects on a coordinate that a lag of the joints' torques outdoes
    (:func:`.final.outdone`), with the reason. The lag: -dtau_c/dt and -d2tau_c/dt2 (the
    delay's columns; ``evidence``: training rows) on every coordinate c with its own
    coefficients: one drive's delay or filter, or an elastic joint, not default candidates.
    Why: with one joint's torque lagging 4-6 samples, cogging and a spring on that joint
    imitated the lag, held steady over the blocks and predicted them, and were named (5 of 6
    such datasets on the PUMA's fourth joint); on a generated chain an elastic joint's lag had
    an offset or cogging named on another joint (the inertial fit's compromise moves the lag
    there) in 2 of 20; with every joint's lag as the rival, none. (The recording's delay is not
    tested against it: the rival generalises it; and a filter's phase lag, common to the
    joints, differs between joints whose torques differ in band, so a test that every joint
    lags alike held a first-order filter's lag back.)"""
    lag = next((c for c in chosen.candidates if c.kind == "delay" and c.coordinate == "all"), None)
    if lag is None or evidence is None or len(problem.coordinates) < 2:
        return []
    asked = {c.coordinate for c in chosen.candidates if c.kind == "delay"}
    lagging = [j for j, c in enumerate(problem.coordinates) if c not in asked]
    columns = np.zeros(lag.columns.shape[:2] + (2 * len(lagging),))
    for k, j in enumerate(lagging):
        columns[:, j, 2 * k], columns[:, j, 2 * k + 1] = lag.columns[:, j, 0], evidence.curvature[:, j]
    every = Candidate("lag", "every", tuple(f"a{k}" for k in range(columns.shape[-1])), columns)
    on_joints = set(problem.coordinates) - asked
    rivals = {i: every for i in named if chosen.candidates[i].coordinate in on_joints}
    out = []
    for i, (over, under) in outdone(model, y, chosen, in_model, rivals, level).items():
        names = ", ".join(problem.coordinates[j] for j in lagging)
        out.append((i, f"a lag of the joints' torques (-dtau/dt, -d2tau/dt2 on each of {names}: a drive's own delay "
                       "or filter, or an elastic joint; not default candidates) explains what it does and more "
                       f"(p = {over.pvalue:.2g}; it adds nothing over the lag, p = {under.pvalue:.2g}): it may stand "
                       "in for that lag; name delay:COORD in --candidates to test a delay on one joint"))
    return out


def _second_order(X: np.ndarray, y: np.ndarray, weights: np.ndarray, rank: int, delay: Candidate,
                  curvature: np.ndarray, level: float, detail: dict) -> str:
    """'' when the delay (in the model ``X``, of ``rank``) is a delay or a filter's lag; else
    why not: the second-order term (-d2tau/dt2 on the coordinates it acts on) added to the
    model has a significantly positive coefficient (one-sided, at ``level``, prewhitened HAC
    standard deviation). A delay d: tau(t - d) = tau - d tau' + d^2/2 tau'' - ..., so its
    coefficient on -tau'' is negative (-d^2/2; the terms beyond, fitted into it, make it less
    so: -0.0025 s^2 for -0.0045 on a 5-sample delay); a resonant lag (an elastic
    transmission, a resonant filter: tau - 2 zeta/w tau' - tau''/w^2) gives +1/w^2. A
    first-order filter's lag (time constant 1-3 samples) came out negative too (13-34 SD below
    zero on the PUMA) and is named a delay. Why: an elastic joint's lag is, to first order, a
    delay on that joint. (Above d^2, a first-order filter's Taylor coefficient, the check held
    back no elastic lag: near the motion's band the fitted coefficient is not Taylor's.)"""
    acts = np.any(delay.columns[:, :, 0] != 0, axis=0)
    column = np.where(acts[None, :], curvature, 0.0)[:, :, None]
    fit = WeightedLinearModel(np.concatenate([X, column], axis=-1), y).fit(weights, cov_type="hac_prewhitened")
    if fit.rank <= rank:
        return ""
    a2, std = float(fit.coefficients[-1]), float(fit.std[-1])
    z = a2 / std if std > 0 else 0.0
    detail["second_order_z"] = z
    if z <= -ndtri(level):
        return ""
    return (f"a resonant lag fits beyond it (the -d2tau/dt2 term's coefficient is {a2:.3g} s^2, {z:.1f} SD above "
            "zero, where a delay's or a filter's is negative): an elastic transmission or a resonant filter, not "
            "in the catalogue, that the delay stands in for")


# A delay common to the recording lags every joint alike: on each joint whose own lag is
# measured, at least this fraction of the most significant joint's.
COMMON_DELAY_FRACTION = 0.5


def _one_joints_lag(others: np.ndarray, y: np.ndarray, weights: np.ndarray, delay: Candidate,
                    coordinates: Sequence[str], level: float, detail: dict) -> str:
    """'' when the delay (``others``: the model without it) may be common to the joints it
    acts on; else why not: each joint's own delay (its -dtau/dt column alone) fitted, every
    joint but the most significant one lags significantly less (one-sided at ``level``,
    prewhitened HAC) than COMMON_DELAY_FRACTION of that one's: one joint's lag (an elastic
    joint, a drive's own filter) that the recording's delay stands in for. Why: on a
    generated chain whose third joint is elastic, a delay was named in 2 of 20 datasets:
    that joint's own delay was 6.4-6.9 ms, 18 SD from zero, the others' -0.5 to 1.5 ms; true
    delays agreed on every joint to 5 %. (An equality test held back a first-order filter's
    lag: its phase lag differs between joints whose torques differ in band; half is far
    from that.)"""
    acts = np.nonzero(np.any(delay.columns[:, :, 0] != 0, axis=0))[0]
    if acts.size < 2:
        return ""
    split = np.zeros(delay.columns.shape[:2] + (acts.size,))
    split[:, acts, np.arange(acts.size)] = delay.columns[:, acts, 0]
    fit = WeightedLinearModel(np.concatenate([others, split], axis=-1), y).fit(weights, cov_type="hac_prewhitened")
    d, std = fit.coefficients[-acts.size:], fit.std[-acts.size:]
    if not np.all(np.isfinite(std)) or np.any(std <= 0):
        return ""
    detail["per_joint_delay"] = {coordinates[int(j)]: float(v) for j, v in zip(acts, d)}
    strongest = int(np.argmax(d / std))
    z = (d - COMMON_DELAY_FRACTION * d[strongest]) / std
    below = np.delete(z, strongest)
    if d[strongest] <= 0 or np.any(below > ndtri(level)):
        return ""
    name = coordinates[int(acts[strongest])]
    return (f"only {name} lags ({1e3 * d[strongest]:.3g} ms on its own; every other joint significantly less than "
            f"half that, at most {1e3 * float(np.max(np.delete(d, strongest))):.3g} ms): one joint's lag (an elastic "
            f"joint, a drive's own filter), not the recording's; name delay:{name} in --candidates to test a delay "
            "on that joint")


# A resonant lag is a rival to a delay when its fitted coefficient is within this range of 1
# (the whole torque through the resonance).
RESONANT_SCALE = (0.5, 2.0)
# Kinds besides the delay that an elastic lag's first-order term imitates (-(2 zeta / w)
# dtau/dt; on a joint whose torque is mostly gravity, dtau/dt ~ dG/dq qd: a viscous force),
# so they too must add over every resonant lag to be named (:func:`_resonant_rival`).
LAG_STAND_INS = ("viscous_friction",)


def _resonant_rival(model: np.ndarray, y: np.ndarray, candidates: list[Candidate], in_model: list[int],
                    index: int, lag: derived.LagEvidence, whiten: Callable[[np.ndarray], np.ndarray],
                    weights: np.ndarray, level: float, detail: dict) -> str:
    """'' when the effect ``candidates[index]`` (in ``in_model``: the delay, or a kind of
    :data:`LAG_STAND_INS`) adds significantly (at ``level``) over every resonant lag of the
    grid (:meth:`.derived.LagEvidence.resonant`, on the coordinates it acts on), given the
    other effects; else why not: a resonant lag (an elastic transmission, a resonant filter:
    not in the catalogue) explains what it does, and the data cannot tell the two apart. Why:
    the second-order term alone (:func:`_second_order`) did not tell them apart on a
    one-coordinate four-bar, whose 21 inertial parameters absorb most of -d2tau/dt2 there: an
    elastic joint (resonance 1.5-3 times the torque's band, zeta 0.2) was named a delay in 12
    of 20 datasets; over the weakest test, true delays added with p below 1e-44 (or had no
    rival in scale) and the elastic joints' delays with p 0.14-0.99 (8 datasets each). Viscous
    friction: under AR(1) 0.9 noise the same elastic joint was named viscous friction in 2 of
    20 on each of two seeds; three of the four add over the weakest lag with p 0.03-0.63 and
    are held back (the fourth adds at p < 1e-4); true viscous friction there added with p below
    1e-3 (or had no lag in scale) in 38 of 40 datasets, one was held back (p 0.09)."""
    acts = np.any(candidates[index].columns[:, :, 0] != 0, axis=0)
    grid = list(lag.resonant(acts))
    weakest = weakest_over(model, y, candidates, in_model, index, [columns[:, :, 0] for _, _, columns in grid],
                           whiten, weights, RESONANT_SCALE)
    if weakest is None:
        return ""
    test, k = weakest
    zeta, w, _ = grid[k]
    detail["over_resonant_lag_pvalue"] = test.pvalue
    if test.pvalue <= level:
        return ""
    what = "a delay" if candidates[index].kind == "delay" else candidates[index].kind.replace("_", " ")
    return (f"a resonant lag (zeta {zeta:g}, {w / (2 * np.pi):.3g} Hz: an elastic transmission or a resonant "
            f"filter, not in the catalogue) explains what it does (it adds p = {test.pvalue:.2g} over it): "
            f"these data cannot tell {what} from an elastic lag")


def _turned(problem: Problem, candidates: list[Candidate], in_model: list[int], named: list[int],
            estimates: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[int, str]]:
    """The named effects whose coefficients in the model ``in_model`` (``estimates``:
    :func:`coefficients`) are not physical, each with the reason."""
    reasons = [(i, _unphysical(problem, candidates[i], dict(zip(coefficient_names(candidates[i].kind),
                                                                 values.tolist()))))
               for i, (values, _) in zip(in_model, estimates) if i in named]
    return [(i, f"{reason} in the final model, without the effects held back") for i, reason in reasons if reason]


def _unphysical(problem: Problem, cand: Candidate, values: dict) -> str:
    """Why an effect with coefficients ``values`` (name -> value) is not physical ('' when it
    is): its kind's signs and ranges, a friction that drives the motion, and a changed body's
    mass."""
    known = known_values(problem.mechanism, cand.kind, cand.coordinate)
    if known:             # a correction of the model's own known value: the total must be physical
        total = {name: value + known.get(name, 0.0) for name, value in values.items()}
        # a total near zero is the model's effect absent from the data: physical
        reason = implausible(cand.kind, {name: abs(known[name]) if absent(total[name], known.get(name)) else value
                                         for name, value in total.items()})
        if reason:
            return ("with the model's own " + ", ".join(f"{k} = {v:.3g}" for k, v in known.items())
                    + f" the total is not physical: {reason}")
    else:
        reason = implausible(cand.kind, values)
        coulomb = known_values(problem.mechanism, "coulomb_friction", cand.coordinate).get("fc")
        if reason and cand.kind == "stribeck_friction" and coulomb and values.get("fs", 0.0) < 0:
            reason += (f" (the friction is lower near rest than in motion: the robot's Coulomb friction may "
                       f"be smooth, tanh(qd/vs), where the model's {coulomb:.3g} is sign(qd))")
    return reason or _drives(problem, cand, values) or _body_implausible(problem, cand, values)


NEAR_TWIN = 0.999       # a rival this correlated with a named effect ...
NEAR_TWIN_P = 0.001     # ... that it outdoes at a p above this only: a note (_near_twins)

# Frictions whose coefficients' signs alone do not make them resist the motion (position
# friction: fcc cos q + fcs sin q changes sign with q), and the share of the samples where
# such a force may drive the motion before it is no friction: it changes sign once over a
# wide travel when it stands for a bearing's eccentricity beside Coulomb friction.
DRIVES_CHECKED = ("position_friction",)
DRIVES_LIMIT = 0.5


def _drives(problem: Problem, cand: Candidate, values: dict) -> str:
    """Why a friction of a kind in DRIVES_CHECKED is not friction ('' when it is): its force
    does positive work on the motion (force . qd < 0: the measured torque is lowered) on
    more than DRIVES_LIMIT of the samples where it acts. Why: a Z1 arm whose URDF gives
    Coulomb friction that its data lack got position friction named on four joints, fcc
    -0.9 to -1.2 about q = 0: a negative Coulomb friction, resisting nowhere."""
    if cand.kind not in DRIVES_CHECKED or problem.qd is None:
        return ""
    force = cand.columns @ np.array(list(values.values()), dtype=float)            # (n, f)
    power = np.sum(force * problem.qd[:len(force)], axis=1)
    acting = np.abs(power) > 1e-9 * np.max(np.abs(power), initial=0.0)
    if not acting.any():
        return ""
    share = float(np.mean(power[acting] < 0))
    if share <= DRIVES_LIMIT:
        return ""
    return (f"its force drives the motion instead of resisting it on {100 * share:.0f} % of the samples where "
            "it acts: no friction does (it may stand in for friction the model has but the data lack)")


def _body_implausible(problem: Problem, cand: Candidate, values: dict) -> str:
    """A changed body keeps a positive mass (its other parameters are not all identifiable:
    the estimate is one of many changes with the same torques, so only the mass is checked);
    not judged when the given masses are not the bodies' (an identify result of a mechanism
    without inertias: least-norm parameters)."""
    if cand.kind != "body" or problem.given is None or not problem.given_masses:
        return ""
    mass = problem.given[derived.body_columns(problem.mechanism, cand.coordinate)][0] + values["m"]
    return f"the changed body's mass {mass:.3g} is not positive" if mass <= 0 else ""


# A body changed within the given identification's uncertainty at this level is its error.
WITHIN_GIVEN_LEVEL = 0.95


def _given_errors(problem: Problem, inertial: np.ndarray, candidates: list[Candidate], in_model: list[int],
                  named: list[int], y: np.ndarray, weights: np.ndarray,
                  estimates: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[int, str]]:
    """The named changed body or point mass that only corrects the identification held as
    given (an identify result with its covariance), with the reason; [] when none does. Each
    is judged by what it adds: the base parameters the named bodies change together (E's
    columns of each body times its values), with it and without it (the model refitted),
    differ by less than the identification's covariance allows (Mahalanobis distance below
    the chi-square quantile over the base parameters). The one nearest is returned; the
    caller refits and asks again. Why what it adds, in base parameters: a payload on a
    planar arm's last link is also the previous link's first moment and inertia, so the two
    bodies share it in any proportion; only the base parameters they change together are
    determined, and what the second adds to them is the given fit's error, which a quiet
    second run makes significant (planar_2r: 0.4 kg named as 0.21 kg on link 2
    and 0.12 kg m on link 1)."""
    if problem.given_uncertainty is None:
        return []
    bodies = [i for i in in_model if i in named and candidates[i].kind in BODY_KINDS]
    if not bodies:
        return []
    base_map, covariance = problem.given_uncertainty
    precision = np.linalg.pinv(covariance, hermitian=True)
    rank = int(np.linalg.matrix_rank(covariance))
    bar = float(chi2.ppf(WITHIN_GIVEN_LEVEL, max(rank, 1)))
    def change(indices: list[int], values: list[np.ndarray]) -> np.ndarray:
        total = np.zeros(base_map.shape[0])
        for i, v in zip(indices, values):
            columns = derived.body_columns(problem.mechanism, candidates[i].coordinate)
            total += base_map[:, columns][:, derived.BODY_PARTS[candidates[i].kind]] @ v
        return total

    by_index = dict(zip(in_model, (v for v, _ in estimates)))
    whole = change(bodies, [by_index[i] for i in bodies])
    nearest: tuple[float, int] | None = None
    for i in bodies:
        others = [j for j in in_model if j != i]
        refit = dict(zip(others, (v for v, _ in coefficients(inertial, candidates, others, y, weights))))
        rest = [j for j in bodies if j != i]
        d = whole - change(rest, [refit[j] for j in rest])
        distance = float(d @ precision @ d)
        if distance <= bar and (nearest is None or distance < nearest[0]):
            nearest = (distance, i)
    if nearest is None:
        return []
    distance, i = nearest
    return [(i, f"within the uncertainty of the identification held as given: what it adds moves the base "
                f"parameters {np.sqrt(distance):.3g} standard deviations (Mahalanobis; {np.sqrt(bar):.3g} at "
                f"{100 * WITHIN_GIVEN_LEVEL:.0f} % over {rank}): the given model's own error, not a change")]


def _cross_validated(model: np.ndarray, added: list[Candidate], y: np.ndarray, tau: np.ndarray,
                     weights: np.ndarray, folds: int) -> dict:
    """Block cross-validated NRMS of the model alone and with ``added``, overall and per block."""
    X = np.concatenate([model] + [c.columns for c in added], axis=-1)
    after, before = cross_validate(X, y, weights, folds, leave_out=[range(model.shape[-1], X.shape[-1])])
    per_block = [{"start": float(b[0]), "before": nrms(before.residual[b], tau[b]),
                  "after": nrms(after.residual[b], tau[b])} for b in blocks(len(tau), folds)]
    return {"cv_before": nrms(before.residual, tau), "cv_after": nrms(after.residual, tau),
            "cv_folds": folds, "cv_blocks": per_block}


def _where(residual: np.ndarray, tau: np.ndarray, qd: np.ndarray | None, t: np.ndarray, coordinates: Sequence[str],
           noise: dict, folds: int) -> dict:
    """Where the final residual is concentrated: per block of time and per motion regime
    (velocity reversals, high acceleration, slow or static poses), as RMS / the whole
    coordinate's residual RMS; regimes at 1.5 times or more are listed in ``concentrated``."""
    rms = np.sqrt(np.mean(residual ** 2, axis=0))
    rms[rms == 0] = 1.0
    out: dict = {"blocks": [], "regimes": {}, "concentrated": []}
    for b in blocks(len(residual), folds):
        ratio = np.sqrt(np.mean(residual[b] ** 2, axis=0)) / rms
        out["blocks"].append({"t": [float(t[b[0]]), float(t[b[-1]])],
                              "ratio": dict(zip(coordinates, np.round(ratio, 4).tolist()))})
    if qd is None or len(qd) < 3:
        return out
    speed = np.sqrt(np.mean(qd ** 2, axis=0))
    speed[speed == 0] = 1.0
    acc = np.gradient(qd, t, axis=0)
    acc_rms = np.sqrt(np.mean(acc ** 2, axis=0))
    acc_rms[acc_rms == 0] = 1.0
    slow_all = np.all(np.abs(qd) < 0.1 * speed, axis=1)
    for j, c in enumerate(coordinates):
        regimes = {"reversal": np.abs(qd[:, j]) < 0.1 * speed[j],
                   "high_acceleration": np.abs(acc[:, j]) > 1.5 * acc_rms[j],
                   "slow_or_static": slow_all}
        entry = {}
        for name, mask in regimes.items():
            if mask.sum() < 10:
                continue
            ratio = float(np.sqrt(np.mean(residual[mask, j] ** 2)) / rms[j])
            entry[name] = {"ratio": ratio, "share": float(mask.mean())}
            if ratio >= 1.5:
                out["concentrated"].append({"coordinate": c, "regime": name, "ratio": ratio})
        out["regimes"][c] = entry
    return out


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
        fit = WeightedLinearModel(model[:train], y[:train]).fit()
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
    """Each added effect's coefficients and HAC standard deviations in the final model (the
    sandwich's effect block equals Frisch-Waugh-Lovell's on the effect columns with the
    inertial model projected out), with the final model's noise ``weights`` (None: estimated
    here)."""
    if not added:
        return []
    blocks = [candidates[i].columns for i in added]
    full = WeightedLinearModel(np.concatenate([inertial] + blocks, axis=-1), y).fit(weights, cov_type="hac")
    std = full.std
    out, start = [], inertial.shape[-1]
    for block in blocks:
        width = block.shape[-1]
        out.append((full.coefficients[start:start + width], std[start:start + width]))
        start += width
    return out


def coefficient_names(kind: str) -> tuple[str, ...]:
    """A candidate kind's coefficient names (a registered effect's, or a derived kind's)."""
    effects = registry.effects()
    return effects[kind].item.coefficients if kind in effects else derived.COEFFICIENTS[kind]


def _coefficient_map(cand: Candidate, values: np.ndarray, stds: np.ndarray,
                     regrouped: Regrouping | None = None) -> dict:
    """{coefficient: {"value", "std"}}; with ``regrouped``, the kept ones are the identified
    combinations and the others have value and std None and ``absorbed_into`` {kept:
    coefficient} (empty: the rest of the model absorbs it), as ``identify`` writes them."""
    names = coefficient_names(cand.kind)
    if regrouped is None:
        return {name: {"value": float(v), "std": float(s)} for name, v, s in zip(names, values, stds)}
    out: dict = {}
    for k, name in enumerate(names):
        if k in regrouped.kept:
            t = regrouped.kept.index(k)
            out[name] = {"value": float(regrouped.values[t]),
                         "std": float(np.sqrt(max(regrouped.covariance[t, t], 0.0)))}
        else:
            column = regrouped.into[:, regrouped.absorbed.index(k)]
            out[name] = {"value": None, "std": None,
                         "absorbed_into": {names[regrouped.kept[t]]: float(v) for t, v in enumerate(column) if v}}
    return out


def _regroupings(inertial: np.ndarray, candidates: list[Candidate], in_model: list[int], named: list[int],
                 y: np.ndarray, weights: np.ndarray) -> dict[int, Regrouping]:
    """The named changed bodies whose ten parameters the data do not each determine beside
    the rest of the final model: their identifiable combinations (:mod:`.identifiable`)."""
    bodies = [i for i in in_model if i in named and candidates[i].kind == "body"]
    if not bodies:
        return {}
    blocks = [candidates[i].columns for i in in_model]
    X = np.concatenate([inertial] + blocks, axis=-1)
    fit = WeightedLinearModel(X, y).fit(weights, cov_type="hac")
    n, f, p = X.shape
    weighted = (X * fit.weights[None, :, None]).reshape(n * f, p)
    ends = np.cumsum([inertial.shape[-1]] + [b.shape[-1] for b in blocks])
    out = {}
    for i in bodies:
        lo, hi = ends[in_model.index(i)], ends[in_model.index(i) + 1]
        found = regroup(np.delete(weighted, np.s_[lo:hi], axis=1), weighted[:, lo:hi], fit.coefficients[lo:hi],
                        fit.covariance[lo:hi, lo:hi])
        if found is None:
            continue
        # which of the model's other columns take what it cannot keep: the other named bodies?
        others = [j for j in bodies if j != i]
        if others:
            rest = [c for k, j in enumerate(in_model) if j not in others and j != i
                    for c in range(ends[k], ends[k + 1])]
            alone = regroup(weighted[:, list(range(inertial.shape[-1])) + rest], weighted[:, lo:hi],
                            fit.coefficients[lo:hi], fit.covariance[lo:hi, lo:hi])
            seen_alone = set(range(hi - lo)) if alone is None else set(alone.kept)
            shared = [k for k in found.absorbed if k in seen_alone]
            if shared:
                found = dataclasses.replace(found, shared=(tuple(shared), tuple(others)))
        out[i] = found
    return out


def _near_twins(effects: list[dict]) -> list[str]:
    """A note for a named effect that a rival explains nearly as well (correlation beyond the
    model at least NEAR_TWIN, the named one ahead at p above NEAR_TWIN_P only): which of the
    two it is, these data barely tell. Why: a payload hung on the TIAGo's last axis moves with
    arm_6_link as with arm_7_link (correlation 0.999), and arm_6_link was named ahead at p 0.03
    with nothing in the text to say so."""
    out = []
    for effect in effects:
        for rival in effect.get("rivals", []):
            if abs(rival["correlation"]) >= NEAR_TWIN and rival["pvalue_named_over_rival"] > NEAR_TWIN_P:
                out.append(f"{effect['kind']}:{effect['coordinate']}: {rival['candidate']} explains it nearly as well "
                           f"(correlation {rival['correlation']:.4f} beyond the model; named ahead at p = "
                           f"{rival['pvalue_named_over_rival']:.2g} only): these data barely tell the two apart")
    return out


def _shared_bodies(candidates: list[Candidate], regrouped: dict[int, Regrouping]) -> list[str]:
    """A note for named changed bodies whose parameters the data determine for each alone but
    not beside the others: what they add is split between them in no way the data hold (a
    payload on a Z1's last link named as 0.395 kg there and 0.557 kg on link04)."""
    groups: dict[frozenset, list[str]] = {}
    for i, found in regrouped.items():
        if found.shared is None:
            continue
        absorbed, others = found.shared
        names = ", ".join(coefficient_names(candidates[i].kind)[k] for k in absorbed)
        groups.setdefault(frozenset((i, *others)), []).append(f"{names} of {candidates[i].coordinate}")
    return [f"{' and '.join(sorted(candidates[i].label for i in group))}: the motion moves them alike ("
            f"{'; '.join(parts)} determined for each alone, not beside the others): how a change is split "
            "between these bodies is not in the data, and one of them may carry all of it"
            for group, parts in groups.items()]


def _effect_entry(all_candidates: list[Candidate], values: np.ndarray, stds: np.ndarray, chosen: Selection,
                  index: int, regrouped: Regrouping | None = None) -> dict:
    cand = all_candidates[index]
    coefficients_ = _coefficient_map(cand, values, stds, regrouped)
    single = len(coefficients_) == 1
    step = next(s for s in chosen.steps if s.chosen == index)
    test = step.tests[index]
    return {"kind": cand.kind, "coordinate": cand.coordinate,
            "value": float(values[0]) if single else {k: v["value"] for k, v in coefficients_.items()},
            "std": float(stds[0]) if single else {k: v["std"] for k, v in coefficients_.items()},
            "coefficients": coefficients_,
            "test": _named_test(all_candidates, step, index),
            "rivals": [_rival_json(all_candidates[r.index], r) for r in step.beaten],
            **({"shape": {k: float(v) for k, v in cand.shape.items()}} if cand.shape else {})}


def _named_test(candidates: list[Candidate], step: Step, index: int) -> dict:
    """The test a named effect was named by. Its own, with its Holm p at the step, when it was
    the step's most significant candidate; when a comparison named it in the place of that
    one (a simpler form explaining its signal as well, a rival adding over it, or an ambiguous
    group resolved again in the complete model), ``pvalue_holm`` is the Holm p the step was opened by (the strongest's:
    the family-wise evidence that an effect is missing there), ``holm_of`` names it,
    ``pvalue_holm_own`` keeps the effect's own Holm p and ``pvalue_over_strongest`` what it
    adds over the strongest (when it is not nested in it). Why: the own Holm p of an effect
    named by comparison can be above alpha (a Kinova run showed "p = 0.2, Holm" for a named
    effect), which no name may show."""
    test = step.tests[index]
    out: dict = {"stat": test.stat, "df": test.df, "pvalue": test.pvalue, "pvalue_holm": float(step.adjusted[index])}
    if step.strongest is not None and step.strongest != index:
        out.update(pvalue_holm=float(step.adjusted[step.strongest]), holm_of=candidates[step.strongest].label,
                   pvalue_holm_own=float(step.adjusted[index]))
        if step.over is not None and step.over.tested:
            out["pvalue_over_strongest"] = float(step.over.pvalue)
    return out


# A correction leaving a total within this fraction of the model's own value of zero says the
# model's known effect is not in the data (the total's sign is then the noise's).
ABSENT = 0.05


def absent(total: float, known: float | None) -> bool:
    """Whether a corrected coefficient's ``total`` is zero for the purpose: within ABSENT of
    the model's own ``known`` value."""
    return known is not None and abs(total) <= ABSENT * abs(known)


def _within_rounding(problem: Problem, model: np.ndarray, candidates: list[Candidate], in_model: list[int],
                     unsupported: list[dict], y: np.ndarray, weights: np.ndarray | None) -> set[int]:
    """The unsupported candidates whose force, fitted beside the final model, is within half
    the quantisation step of every coordinate it acts on (their entries say so): they do not
    hold the verdict back. Why: rounding that coarse leaves an error that follows the signal,
    which such a force fits significantly without it being there (exact TIAGo-like data
    rounded to 0.2 N m on the wrist: a Stribeck friction of -0.02 N m, significant)."""
    if problem.quanta is None:
        return set()
    steps = np.asarray(problem.quanta, float)
    out = set()
    for entry in unsupported:
        i = entry["index"]
        if i in in_model:
            continue
        value, _ = coefficients(model, candidates, [*in_model, i], y, weights)[-1]
        rms = np.sqrt(np.mean((candidates[i].columns @ value) ** 2, axis=0))
        acts = rms > 0
        if acts.any() and np.all(steps[acts] > 0) and np.all(rms[acts] <= steps[acts] / 2):
            out.add(i)
            entry["reason"] += (f"; within the rounding of its torques (force RMS {rms[acts].max():.3g}, "
                                f"under half the quantisation step {steps[acts].min():.3g})")
    return out


def _left_nothing(model: np.ndarray, y: np.ndarray, candidates: list[Candidate], in_model: list[int],
                  unsupported: list[dict], whiten: Callable[[np.ndarray], np.ndarray], weights: np.ndarray,
                  alpha: float) -> set[int]:
    """The unsupported candidates that, added to the final model, are not significant at
    ``alpha`` (their entries say so): they do not hold the verdict back. Why: one significant
    at its step can stand in for an effect named later (a negative Stribeck friction on a
    simulated TIAGo's arm_3, chosen before its Coulomb correction, p 0.2 beside it), and the
    verdict said "partly explained" for structure the final model no longer leaves."""
    out = set()
    for entry in unsupported:
        i = entry.get("index")
        if i is None or i in in_model:
            continue
        test = added_test(model, y, candidates, in_model, i, whiten, weights)
        if test is not None and test.tested and test.pvalue > alpha:
            out.add(i)
            entry["reason"] += f"; beside the named effects it is not significant (p = {test.pvalue:.2g})"
    return out


def _sparse_left(model: np.ndarray, y: np.ndarray, candidates: list[Candidate], in_model: list[int], last: Step,
                 weights: np.ndarray, alpha: float) -> list[dict]:
    """Unsupported entries for the candidates the selection's last step could not test for
    their support (acting on under MIN_SUPPORT of the samples) that, added to the final model,
    are significant (Holm at ``alpha``) with the residual's own variance (the classical one on a
    white residual, the stationary one on a coloured one, scaled by the noise's local power:
    :func:`.final.added_test` with ``sparse``): what the model lacks there holds the verdict
    back. Why: on the SLA the rotor inertia of theta2, beyond the inertial model, acts near the
    arms' toggle only; refused on support at every step, it left "nothing missing" (exit 0)."""
    refused = [i for i, t in enumerate(last.tests) if t.reason == "support" and i not in in_model]
    found = [(i, added_test(model, y, candidates, in_model, i, last.whiten, weights, sparse=True)) for i in refused]
    tests: list[tuple[int, Test]] = [(i, t) for i, t in found if t is not None and t.tested]
    if not tests:
        return []
    adjusted = holm([t.pvalue for _, t in tests])
    return [{"index": i, "kind": candidates[i].kind, "coordinate": candidates[i].coordinate, "values": {},
             "reason": f"acts on too few samples for the selection's test (support); added to the named model and "
                       f"tested with the residual's own variance it is significant (p = {t.pvalue:.2g}): "
                       "what the model lacks there is not named"}
            for (i, t), p in zip(tests, adjusted) if p <= alpha]


def _held_back(candidates: list[Candidate], index: int, reason: str) -> dict:
    """An ``unsupported`` entry for a named effect a final check took out, with its reason."""
    return {"index": index, "kind": candidates[index].kind, "coordinate": candidates[index].coordinate,
            "values": {}, "reason": reason}


def _known_entry(problem: Problem, cand: Candidate) -> dict:
    """``known``: the model's own coefficients of this effect (subtracted as known) that the
    named value corrects, when it has them; the effect's total is their sum."""
    known = known_values(problem.mechanism, cand.kind, cand.coordinate)
    return {"known": known} if known else {}


def _rival_json(rival_candidate: Candidate, rival: Rival) -> dict:
    """A rival the named effect was tested against and beat: the evidence."""
    return {"candidate": rival_candidate.label, "correlation": rival.correlation,
            "pvalue_named_over_rival": rival.winner_over_rival.pvalue,
            "pvalue_rival_over_named": rival.rival_over_winner.pvalue}


def tied_reason(mechanism: Mechanism, cands: Sequence[Candidate]) -> str | None:
    """Why no motion can separate a group: one kind of effect on joint coordinates that a
    coupling or a closed loop ties at a fixed ratio (a parallelogram's angles, a
    counterweight on a cable: their columns are proportional for every motion, issue 49);
    None when the group is not such a group."""
    coordinates = [c.coordinate for c in cands]
    kinds = {c.kind for c in cands}
    if len(kinds) != 1 or kinds & set(DERIVED_KINDS) or not all(c in mechanism.coordinates for c in coordinates):
        return None                  # a body's, a gain's, a delay's candidates are not on a joint coordinate
    from baseparams.dynamics.tied import ties, tied_group
    if tied_group(mechanism, coordinates) is None:
        return None
    why = {"coupling": "a coupling", "loop": "a closed loop"}
    parts = [f"{t.coordinate} = {t.ratio:.6g} x {t.leader} ({why[t.how]})" for t in ties(mechanism)
             if t.coordinate in coordinates]
    return f"{'; '.join(parts)} at every state: one effect for every motion, on any of them"


def _as_strongest(cands: Sequence[Candidate], estimates: Sequence[np.ndarray]) -> list[float]:
    """An equivalent group's coefficients as one effect on its first member (the strongest):
    sum_k S_k est_k, S_k the exact map of member k's columns onto the first's (they are
    proportional for every motion, so the fit splits one force among them at will)."""
    base = cands[0].columns.reshape(-1, cands[0].columns.shape[-1])
    total = np.zeros(base.shape[1])
    for cand, est in zip(cands, estimates):
        s, *_ = np.linalg.lstsq(base, cand.columns.reshape(-1, cand.columns.shape[-1]), rcond=None)
        total += s @ np.asarray(est, dtype=float)
    return [float(v) for v in total]


def _ambiguous_entry(all_candidates: list[Candidate], chosen: Selection, index: int,
                     estimate: tuple[np.ndarray, np.ndarray] | None, mechanism: Mechanism | None = None,
                     estimates: dict | None = None) -> dict:
    step = next(s for s in chosen.steps if s.chosen == index)
    members = [index] + [r.index for r in chosen.ambiguous[index]]
    cands = [all_candidates[i] for i in members]
    tied = tied_reason(mechanism, cands) if mechanism is not None else None
    # bodies that move together through a closed loop: the motion that separates them is the geometry's (issue 49)
    from baseparams.diagnose.loopbodies import body_group
    loop = body_group(mechanism, cands) if mechanism is not None and tied is None else None
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
            "separate_by": (f"no motion can: {tied}" if tied else loop.separate_by if loop else
                            separation([c.kind for c in cands], False)),
            **({"equivalent": tied} if tied else {"equivalent": loop.reason} if loop else {}),
            **({"value": _as_strongest(cands, [estimates[i][0] for i in members])}
               if tied and estimates is not None and all(i in estimates for i in members) else {}),
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
                    "tests": sorted(tests, key=lambda d: -(float(d["z"]) if d["z"] is not None else -1e300))})
    return out


def _weak(inertial: np.ndarray, candidates: list[Candidate], first: Step) -> list[dict]:
    """Candidates nearly collinear with the inertial model: what fraction of them survives
    beyond the first step's (inertial-only) weighted fit."""
    fit = first.fit
    n, f, _ = inertial.shape
    out = []
    for cand, test in zip(candidates, first.tests):
        if not test.tested:
            continue
        Z = (first.whiten(cand.columns) * fit.weights[None, :, None]).reshape(n * f, -1)
        norms = np.linalg.norm(Z, axis=0)
        norms[norms == 0] = 1.0
        kept = float(svd(fit.orthogonal(Z / norms), compute_uv=False).min())
        if kept < WEAK:
            out.append({"candidate": cand.label, "kept": kept, "separate_by": MODEL_HINT})
    return out


def noise_floor(residual: np.ndarray, correlation: np.ndarray | None = None) -> np.ndarray:
    """Per-coordinate noise SD from second differences (white noise: var = 6 sigma^2; noise
    with autocorrelation r: (6 - 8 r1 + 2 r2) sigma^2); a smooth missing force barely
    changes it."""
    r = np.zeros(3)
    if correlation is not None:
        r[:min(3, len(correlation))] = correlation[:3]
    d2 = np.diff(residual, n=2, axis=0)
    return np.sqrt(np.mean(d2 ** 2, axis=0) / max(6.0 - 8.0 * r[1] + 2.0 * r[2], 1e-12))


# A coordinate's residual below this fraction of its torque's RMS is the arithmetic's rounding
# (data simulated without noise fit to 1e-11), not structure: it counts as white.
ROUNDING = 1e-9
# The inertial model's cross-validated gap this many times its fitted gap: the blocks cannot be
# predicted from each other (a note says so).
CV_BLOWUP = 5.0


def _at_rounding(model: np.ndarray, y: np.ndarray, tau: np.ndarray) -> bool:
    """Whether the model alone fits every coordinate to ROUNDING of its torque's RMS."""
    fit = WeightedLinearModel(model, y).fit(np.ones(y.shape[1]))
    size = np.sqrt(np.mean(tau ** 2, axis=0))
    return bool(np.all(np.sqrt(np.mean(fit.unweighted_residual() ** 2, axis=0)) <= ROUNDING * size))


def _unexplained(prediction: _Prediction, train: int, coordinates: Sequence[str], alpha: float,
                 size: np.ndarray, correlation: np.ndarray | None = None, quanta: np.ndarray | None = None
                 ) -> dict:
    """Whiteness of the final fit's residual per coordinate (Ljung-Box, its null simulated
    through the fit: :mod:`.whiteness`, with the recording's filter's ``correlation``; Holm
    over the coordinates) and the residual against the noise level; ``size``: each
    coordinate's torque RMS (training rows). A coordinate whose residual RMS is within half
    its force's quantisation step (``quanta``) is not judged: rounding to a coarse grid leaves
    an error that follows the signal (structure) as large as that (``quantised``)."""
    residual, fit = prediction.residual, prediction.fit
    fit_part, hold_part = residual[:train], residual[train:]
    sigma = noise_floor(fit_part, correlation)
    lags = min(LJUNG_BOX_LAGS, max(1, train // 5))
    weighted = fit.residual.reshape(train, len(coordinates))
    stats, pvalues = monte_carlo_pvalues(weighted, fit.basis, lags, alpha, correlation=correlation)
    flat = np.std(weighted, axis=0) == 0
    flat |= np.sqrt(np.mean(residual[:train] ** 2, axis=0)) <= ROUNDING * size
    steps = np.zeros(len(coordinates)) if quanta is None else np.asarray(quanta, float)
    quantised = (steps > 0) & (np.sqrt(np.mean(residual[:train] ** 2, axis=0)) <= steps / 2)
    pvalues[flat | quantised] = 1.0
    count = replicates(len(coordinates), alpha)
    boxes = {c: {"stat": float(stats[j]), "pvalue": float(pvalues[j]), "lags": lags, "replicates": count}
             for j, c in enumerate(coordinates)}
    reject = holm(pvalues.tolist()) <= alpha
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
        "quantised": {c: float(steps[j]) for j, c in enumerate(coordinates) if quantised[j]},
    }


def _predictable(after: _Prediction, train: int, problem: Problem, alpha: float, size: np.ndarray, un: dict,
                 notes: list[str], candidates: Sequence[Candidate] = (), unsupported: Sequence[dict] = (),
                 excused: set[int] | frozenset[int] = frozenset()) -> tuple[bool, set[int]]:
    """Whether structure remains: the final residual is predicted by a generic basis of the
    motion on some coordinate (:func:`.whiteness.predictable`: position, speed, direction,
    reversals, acceleration, blocks of the recording; GLS with the residual's AR filter;
    Holm over the coordinates at half ``alpha``), not whether it is white. Each coordinate's
    basis also holds the columns there of the ``unsupported`` candidates (those not
    ``excused``): a candidate the diagnosis held back is a force that follows the motion, and
    what it still explains is structure. When the motion predicts nothing they are returned
    (they do not hold the verdict back; their entries say so). Adds ``structure``,
    ``predictable``, ``predictable_basis`` and ``colour`` to ``un`` (:func:`_unexplained` of
    ``after``), and to ``notes`` the structure, or the residual's colour when Ljung-Box
    rejects and the motion predicts nothing.

    Why half alpha: the verdict is one claim about the whole recording, and after the filter's
    estimate the test's tail is above nominal under strongly coloured noise; with nothing
    missing, exit 0 in 96-100 % of datasets (benchmarks/bench_diagnose_coloured.py). Why the
    held candidates inside the basis, not tested one by one: each had been selected as the best
    of all candidates by the selection's AR(1)-whitened test, whose filter is fitted to a
    residual the model took the low frequencies from (liberal under AR(1) 0.9 noise: a spring
    or cogging selected, then held back, made 6 of 30 null PUMA datasets "unexplained")."""
    coordinates = problem.coordinates
    f = len(coordinates)
    residual = after.residual[:train]
    rms = np.sqrt(np.mean(residual ** 2, axis=0))
    skip = (rms <= ROUNDING * size) | np.array([c in un["quantised"] for c in coordinates])
    qd = problem.qd[:train] if problem.qd is not None else None
    t = problem.t[:train]
    y = residual + after.model[:train] @ after.fit.coefficients
    held = [u["index"] for u in unsupported if u.get("index") is not None and u["index"] not in excused]
    basis = motion_basis(qd, t)
    basis = basis if len(basis) == f else basis * f
    for i in held:
        columns = candidates[i].columns[:train]
        for j in range(f):
            if np.any(columns[:, j]):
                basis[j] = np.concatenate([basis[j], columns[:, j]], axis=1)
    tests: list = [None] * f
    colours: list = [None] * f
    if not skip.all():
        tests, colours, _ = predictable(after.model[:train], y, after.fit.weights, basis, t, skip.tolist())
    pvalues = np.array([1.0 if test is None or not test.tested else test.pvalue for test in tests])
    adjusted = holm(pvalues.tolist())
    un["predictable"] = {c: (None if test is None else
                             {"stat": float(test.stat), "df": int(test.df), "pvalue": float(pvalues[j]),
                              "pvalue_holm": float(adjusted[j]), "effective_samples": int(test.lags)})
                         for j, (c, test) in enumerate(zip(coordinates, tests))}
    un["predictable_basis"] = list(MOTION_BASIS_NAMES) + [f"block {b + 1}/{MOTION_BLOCKS}" for b in range(MOTION_BLOCKS)] \
        + [candidates[i].label for i in held]
    un["colour"] = dict(zip(coordinates, colours))
    structured = adjusted <= alpha / 2
    common = _held_lack(problem, rms / np.where(size > 0, size, 1.0), structured, un, notes)
    structured &= ~common
    un["structure"] = bool(structured.any())
    adds_nothing: set[int] = set()
    if un["structure"]:
        notes.append("structure remains: the residual follows the motion on "
                     + ", ".join(f"{c} (p = {adjusted[j]:.2g})" for j, c in enumerate(coordinates) if structured[j]))
        return True, adds_nothing
    for i in held:
        adds_nothing.add(i)
        entry = next(u for u in unsupported if u.get("index") == i)
        entry["reason"] += ("; what it and the motion predict is no larger than the held identification's own "
                            "residual on its run: it does not hold the verdict back" if common.any() else
                            "; with the residual's colour estimated, it and the motion together do not predict "
                            f"the residual (p >= {float(adjusted.min()):.2g}): it does not hold the verdict back")
    if not un["white"] and not common.any():
        coloured = [(c, k) for c, k in zip(coordinates, colours) if k is not None]
        text = ", ".join(f"{c} {k['lag1']:.2f}" for c, k in coloured)
        half = ", ".join(f"{c} {k['half_power_hz']:.3g}" for c, k in coloured)
        notes.append(f"the residual is coloured (lag-1 autocorrelation: {text}; half its power below "
                     f"(Hz): {half}; Nyquist {coloured[0][1]['nyquist_hz']:.3g} Hz) but the motion does not predict it "
                     f"(smallest p = {float(adjusted.min()):.2g} over position, speed, direction, reversals, "
                     "acceleration and blocks): stationary noise, not a missing force")
    return False, adds_nothing


# What remains on a coordinate is what the held model always lacked when it is no larger than
# that model's residual on its own run, by this factor. Why 1.5: what a model error leaves
# changes with the force it acts on (a 27 ms delay on the PUMA's q4 left 1.29 times more
# after a payload than before); an unnamed change as large as the held fit's own residual
# (1.12 times it, added in quadrature) still holds the verdict back.
COMMON_LACK = 1.5


def _held_lack(problem: Problem, nrms_here: np.ndarray, structured: np.ndarray, un: dict,
               notes: list[str]) -> np.ndarray:
    """Coordinates whose remaining structure is what the identify result held as given
    (``--params``) already left on its own run: their residual's NRMS here and there agree
    within COMMON_LACK (:func:`_alike`). Adds ``held_lack`` to ``un`` and a note; the verdict
    is not held back by them.

    Why: a model fitted to one run and held for another lacks the same things in both (a
    friction law's shape, the drive's delay); the residual then follows the motion in both,
    and a diagnosis of what changed read that as an unexplained change (every real run ended
    "partly explained"). Why relative to each run's force: what a delay or a gain error
    leaves grows with the force, and a payload raises the wrist's force many times. A change
    left unnamed makes the residual larger than the held fit's own and still holds the
    verdict back."""
    if problem.held_nrms is None:
        return np.zeros(len(nrms_here), dtype=bool)
    common = structured & _alike(problem, nrms_here)
    if common.any():
        pairs = [(c, float(nrms_here[j]), float(problem.held_nrms[j]))
                 for j, c in enumerate(problem.coordinates) if common[j]]
        un["held_lack"] = {c: {"nrms": here, "held_nrms": there} for c, here, there in pairs}
        notes.append("the residual follows the motion on " + ", ".join(c for c, _, _ in pairs)
                     + ", but is no larger than the held identification's own residual on its run (NRMS here / "
                     "there: " + ", ".join(f"{c} {a:.3g} / {b:.3g}" for c, a, b in pairs)
                     + "): what the held model lacks in both runs, not a change; it does not hold the verdict back")
    return common


def _alike(problem: Problem, nrms_here: np.ndarray) -> np.ndarray:
    """Coordinates where this run's residual (NRMS, the complete model's) and the held identify
    result's own residual on its run agree within COMMON_LACK either way: there the held
    residual measures what the model lacks in both runs. Why both ways: a held run much
    noisier than this one (planar_2r identified on 300 samples at noise 0.5, a payload then
    diagnosed on a quiet run) has a residual of noise, not of what the model lacks, and a
    0.4 kg payload would pass as its lack."""
    held = problem.held_nrms
    if held is None:
        return np.zeros(len(nrms_here), dtype=bool)
    with np.errstate(invalid="ignore"):
        return np.isfinite(held) & (nrms_here <= COMMON_LACK * held) & (nrms_here * COMMON_LACK >= held)


def _held_lack_named(problem: Problem, inertial: np.ndarray, candidates: list[Candidate], in_model: list[int],
                     named: list[int], groups: dict[int, list[int]], dropped: set[int], y: np.ndarray,
                     weights: np.ndarray, size: np.ndarray, final: np.ndarray) -> tuple[list[int], str] | None:
    """A named effect, or an ambiguous group, that explains no more than the identify result
    held as given (``--params``) already left on its own run: without it, the residual's NRMS
    on every coordinate it acts on is at most COMMON_LACK times that result's own there. The
    one that leaves the least without it, as (its members, the reason); None when none.

    Why: a model held for a second run lacks there what it lacked on its own (a friction law's
    shape, a delay), and the forward steps name whatever imitates it best; with nothing changed
    between two PUMA runs, load friction, Coulomb friction and gains were named in 4 of 8.
    Such a "change" is not one. A change larger than the held model's own misfit is still
    named; a smaller one needs both runs (``--baseline``). Judged only where the two runs'
    residuals agree (``final``, the complete model's residual here: :func:`_alike`)."""
    if problem.held_nrms is None:
        return None
    alike = _alike(problem, np.sqrt(np.mean(final ** 2, axis=0)) / np.where(size > 0, size, 1.0))
    heads = [i for i in named if i in in_model] + [h for h in groups if h in in_model and h not in dropped]
    best: tuple[float, list[int], np.ndarray] | None = None
    for head in heads:
        members = [m for m in groups.get(head, [head]) if m in in_model]
        acts = np.zeros(y.shape[1], dtype=bool)
        for m in members:
            acts |= np.any(candidates[m].columns != 0, axis=(0, 2))
        held = problem.held_nrms[acts]
        if not acts.any() or not alike[acts].all():
            continue
        others = [candidates[j].columns for j in in_model if j not in members]
        X = np.concatenate([inertial] + others, axis=-1)
        fit = WeightedLinearModel(X, y).fit(weights)
        residual = y - X @ fit.coefficients
        without = np.sqrt(np.mean(residual ** 2, axis=0)) / np.where(size > 0, size, 1.0)
        ratio = float(np.max(without[acts] / held))
        if ratio <= COMMON_LACK and (best is None or ratio < best[0]):
            best = (ratio, members, without)
    if best is None:
        return None
    ratio, members, without = best
    coordinates = [c for j, c in enumerate(problem.coordinates)
                   if np.any([np.any(candidates[m].columns[:, j] != 0) for m in members])]
    label = " | ".join(candidates[m].label for m in members)
    shown = ", ".join(f"{c} {without[problem.coordinates.index(c)]:.3g} / "
                      f"{problem.held_nrms[problem.coordinates.index(c)]:.3g}" for c in coordinates)
    return members, (f"what the identification held as given already lacked on its own run: without "
                     f"{label} the residual's NRMS is no larger than that result's own (here / there: {shown}; "
                     f"at most {COMMON_LACK} times): not a change (--baseline with that run tells smaller ones)")


def _finite(values: np.ndarray) -> list:
    return [float(v) if np.isfinite(v) else None for v in values]


def diagnose_data(mechanism: Mechanism, data: MeasuredData, *, selection: Sequence[str] | None = None,
                  alpha: float = 0.05, holdout: float = 0.0, folds: int = FOLDS, max_steps: int | None = None,
                  given: Given | np.ndarray | None = None) -> Diagnosis:
    """:func:`prepare` then :func:`diagnose` on measured data (the CSV's notes kept);
    ``given``: the simulation held as given (--params: :class:`.given.Given`, or its
    standard parameters alone)."""
    held = given if isinstance(given, Given) else None
    parameters = given.parameters if isinstance(given, Given) else given
    problem = prepare(mechanism, data.motion, data.sample, selection, data, parameters)
    if held is not None:
        problem.given_masses = held.masses
        if held.base_map is not None and held.covariance is not None:
            problem.given_uncertainty = (held.base_map, held.covariance)
        if held.fit_nrms:
            problem.held_nrms = np.array([held.fit_nrms.get(c, np.nan) for c in problem.coordinates])
    # held values no robot has first: said before the diagnosis that holds them (.given)
    problem.notes = (list(held.notes) if held is not None else []) + list(data.notes) + problem.notes
    return diagnose(problem, _forces(data, held, problem.notes), alpha=alpha, holdout=holdout, folds=folds,
                    max_steps=max_steps)


def _forces(data: MeasuredData, held: Given | None, notes: list[str]) -> np.ndarray:
    """The data's generalized forces: currents whose gains the description leaves unknown
    converted with the gains of the identify result held as given (a note says so); without
    them, an InputError. Why: such a channel's force is not in ``data.tau`` (zero there), and
    a diagnosis of the rest named nothing and called the data unexplained."""
    if not data.gain_names:
        return data.tau
    gains = held.gains if held is not None else {}
    missing = [g for g in data.gain_names if g not in gains]
    if missing:
        raise InputError(f"the gains {', '.join(missing)} of these data are unknown: identify them first (`identify` "
                         "on these channels with a run that carries a known payload), then diagnose with --params "
                         "that result, or give the gains in the recording description", file=data.path,
                         key="--params")
    values = np.array([gains[g] for g in data.gain_names])
    notes.append("currents with unknown gains converted with the identify result's: "
                 + ", ".join(f"{g} = {v:.6g}" for g, v in zip(data.gain_names, values)))
    return measured_forces(data, data.gain_names, values)


# ----- writing the fixed mechanism ---------------------------------------------------------
def decimal_text(value: float | Fraction) -> str:
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


def check_writable(mechanism: Mechanism, path: str | os.PathLike) -> None:
    """--write needs a TOML mechanism file to append to: refused before the run otherwise."""
    source = mechanism.path
    if not source or Path(source).suffix.lower() != ".toml":
        raise InputError(f"--write needs a TOML mechanism file; {mechanism.name} was read from "
                         f"{source or 'no file'} (convert it first: baseparams convert MECH FILE.toml)",
                         key="--write")
    if Path(path).suffix.lower() != ".toml":
        raise InputError(f"--write writes a TOML mechanism file, not {Path(path).name}", key="--write")


def write_fixed(mechanism: Mechanism, effects: Sequence[EffectSpec], path: str | os.PathLike,
                origin: str = "") -> Mechanism:
    """Write the mechanism's own TOML text with ``effects`` appended as ``[[effects]]`` tables
    (the user's file stays as it was above them), check that it loads back with them, and
    write it atomically. Returns the mechanism read back."""
    check_writable(mechanism, path)
    source = mechanism.path
    try:
        text = Path(str(source)).read_text(encoding="utf-8")
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
