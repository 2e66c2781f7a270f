"""The gates a selected effect passes before it is named: physical (signs, ranges, a friction
resisting the motion, a changed body's mass), predicting held-out blocks better by enough, one
coefficient over the recording, larger than the structure left beside it, not a stand-in for a
lag of the joints or a resonant lag, not within the given identification's uncertainty; and
the swaps a failed one may make (a simpler form in its place, a held-back effect in a named
one's place). The ones that fail are reported ``unsupported`` with their reason.
"""

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
from scipy.special import ndtri
from scipy.stats import chi2

from baseparams.diagnose import derived
from baseparams.diagnose.candidates import known_values
from baseparams.diagnose.entries import _held_back, absent
from baseparams.diagnose.estimates import _Prediction, coefficient_names, coefficients
from baseparams.diagnose.final import outdone, simpler_in_place, weakest_over
from baseparams.diagnose.outofsample import CrossValidation, cross_validate, held_out_gain, stability
from baseparams.diagnose.problem import Problem
from baseparams.diagnose.selection import BODY_KINDS, Candidate, Selection
from baseparams.diagnose.wald import holm
from baseparams.identify.impossible import body_limits, implausible
from baseparams.identify.linear import WeightedLinearModel


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
    :func:`.verdict._unexplained` of ``after``."""
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
    """``original`` (every row) at the shape selection fixed ``chosen`` at, and with the
    columns selection kept of it (:func:`.selection._beyond_named`)."""
    if chosen.names != original.names and not original.variants:
        keep = [original.names.index(name) for name in chosen.names]
        return dataclasses.replace(original, names=chosen.names, columns=np.ascontiguousarray(original.columns[:, :, keep]))
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
    their reasons (:mod:`.outofsample`); ``model``, ``y`` and ``lag`` (:func:`.workflow._derived`): the
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
    :func:`.estimates.coefficients`) are not physical, each with the reason."""
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
    return reason or _drives(problem, cand, values) or _body_implausible(problem, cand, values) \
        or _beyond_scale(problem, cand, values)

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
    """A changed body (or a payload on it: a load taken off is a negative one) keeps a positive
    mass (its other parameters are not all identifiable: the estimate is one of many changes
    with the same torques, so only the mass is checked); not judged when the given masses are
    not the bodies' (an identify result of a mechanism without inertias: least-norm parameters),
    nor when the held body's own mass is not positive: no body has it, so the held values there
    are not the body's. Why: a real Kinova run identified and held had its last link at -366 kg
    (the first link's first moments, through an axis 4e-6 rad off vertical, came out at -7e4 kg m,
    and the masses completed from them followed); a 2 kg payload added to the next run was then
    refused as "the changed body's mass -365 is not positive" and nothing was named."""
    if cand.kind not in ("body", "payload") or problem.given is None or not problem.given_masses:
        return ""
    held = problem.given[derived.body_columns(problem.mechanism, cand.coordinate)][0]
    if held <= 0:
        return ""
    mass = held + values["m"]
    return f"the changed body's mass {mass:.3g} is not positive" if mass <= 0 else ""


def _beyond_scale(problem: Problem, cand: Candidate, values: dict) -> str:
    """A body's, payload's or mass's coefficient above a hundred times what the mechanism's
    bodies could have (:func:`.impossible.body_limits`; '' when the mechanism gives no
    masses): its columns cancel one another. Why: on a real Kinova run held against its first,
    a body on half_arm_1_link came out at m = 7.8e5 kg (refused then only because it moved
    from block to block); between the runs, a 1 kg load was named as -2900 kg on another link."""
    if cand.kind not in BODY_KINDS:
        return ""
    limits = body_limits(problem.mechanism)
    for name, value in values.items():
        if name in limits and abs(value) > limits[name]:
            return (f"its {name} = {value:.3g} is beyond any physical scale of this mechanism (above "
                    f"{limits[name]:.3g}: a hundred times what its bodies could have): its columns cancel one another")
    return ""


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
