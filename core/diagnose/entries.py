"""The diagnosis report's entries: each named effect with its coefficients, the test it was
named by and the rivals it beat; each ambiguous group with its evidence and the excitation that
would separate it; the steps; where the residual remains; and the notes about effects the data
barely tell apart. JSON shaping only: the decisions are made in :mod:`.workflow`,
:mod:`.gates` and :mod:`.verdict`.
"""

import dataclasses
from collections.abc import Sequence

import numpy as np

from baseparams.diagnose.candidates import known_values
from baseparams.diagnose.derived import KINDS as DERIVED_KINDS
from baseparams.diagnose.estimates import coefficient_names
from baseparams.diagnose.identifiable import Regrouping, regroup
from baseparams.diagnose.outofsample import blocks
from baseparams.diagnose.problem import Problem
from baseparams.diagnose.selection import Candidate, Rival, Selection, Step
from baseparams.identify.linear import WeightedLinearModel
from baseparams.model.mechanism import Mechanism


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


NEAR_TWIN = 0.999       # a rival this correlated with a named effect ...
NEAR_TWIN_P = 0.001     # ... that it outdoes at a p above this only: a note (_near_twins)


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
    bodies = [i for i in in_model if i in named and candidates[i].kind in ("body", "payload")]
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
