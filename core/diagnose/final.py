"""Tests of one effect against the final model of a selection, under its last filter and
weights: what a held-back effect's simpler forms explain in its place, whether a rival
outdoes a named effect, what an effect adds over each member of a family of rivals, and what
an effect found at its step adds to the final model. Why a module of their own: the workflow's
checks ask them after :func:`.selection.select` has finished; selection never does.
"""

from collections.abc import Callable, Sequence

import numpy as np

from baseparams.identify.linear import LinearFit as Fit, Reduced
from baseparams.diagnose.selection import (Candidate, Selection, Step, Whitening, best_variant, complete_fit,
                                           generalisation, resolve)
from baseparams.diagnose.wald import (ABSORB_TOL, NOT_TESTED, Test, candidate_basis, encompassing,
                                      encompassing_each, holm, orthonormal_basis, wald)


def simpler_in_place(model: np.ndarray, y: np.ndarray, selection: Selection, held: int,
                     kept: Sequence[int], alpha: float) -> tuple[Step, int] | None:
    """The simpler kinds a held-back effect generalises on its coordinate (cogging: an offset
    or a spring), tested in its place against the model with the ``kept`` effects, under the
    selection's last filter and weights, at the bar ``held`` entered by (Holm over the simpler
    forms): a step choosing the strongest that clears it, or None. Why: with AR(1) noise at
    0.9 a general form's extra directions take a part of the noise's slow swings, win over
    the simpler form that is the truth (cogging over an offset), and then fail the
    out-of-sample checks; without this the truth was lost in 2 of 40 such datasets. The
    step is not in ``selection`` (the caller enters it once its choice holds up)."""
    candidates = selection.candidates
    relation = generalisation(candidates)
    place = candidates[held].coordinate
    # one taken out when a form generalising it came in (a payload once a body was in) may
    # stand again once that form is held back
    simpler = [j for j, cand in enumerate(candidates) if cand.coordinate == place and relation(held, j)
               and j not in selection.in_model]
    if not simpler:
        return None
    last = selection.steps[-1]
    filtered = last.whiten
    n, f, _ = model.shape
    fit, _ = complete_fit(model, y, candidates, kept, filtered, last.fit.weights)
    tests, variant, bases = [NOT_TESTED] * len(candidates), {}, {}
    for j in simpler:
        seen = filtered.candidate(candidates[j]) if isinstance(filtered, Whitening) else candidates[j]
        bases[j], tests[j], variant[j] = best_variant(seen, fit, (n, f), fit.rank,
                                                      sparse_if_white=isinstance(filtered, Whitening),
                                                      sparse_if_coloured=isinstance(filtered, Whitening))
    tested = [j for j in simpler if tests[j].tested]
    adjusted = np.ones(len(candidates))
    if tested:
        adjusted[tested] = holm([tests[j].pvalue for j in tested])
    bar = selection.bars.get(held, alpha)
    passing = [j for j in tested if adjusted[j] <= bar]
    if not passing:
        return None
    strongest = max(passing, key=lambda j: tests[j].z)
    # among themselves as in a forward step: an offset nested in a spring replaces it unless
    # the spring's slope clears the bar too; forms the data cannot tell apart: none named
    best, confusable, beaten = resolve(strongest, [j for j in passing if j != strongest], bases, fit, (n, f),
                                       fit.rank, alpha, nested_level=bar, generalises=relation)
    if confusable:
        return None
    over = None if best == strongest else next((r.winner_over_rival for r in beaten if r.index == strongest), None)
    return Step(tests, adjusted, fit, filtered, chosen=best, beaten=beaten,
                strongest=None if best == strongest else strongest, over=over), variant[best]


def _left_out(complete: Fit, offsets: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int], i: int,
              whiten: Callable[[np.ndarray], np.ndarray]) -> tuple[Fit | Reduced, np.ndarray] | None:
    """The complete fit with effect ``i`` left out (Frisch-Waugh-Lovell) and i's directions
    beyond it; None when that needs a refit or i has no direction of its own."""
    k = list(in_model).index(i)
    fit = complete.without(range(offsets[k], offsets[k + 1]))
    if fit is None:
        return None
    own = candidate_basis(whiten(candidates[i].columns), fit)
    return (fit, own) if own.shape[1] else None


def outdone(model: np.ndarray, y: np.ndarray, selection: Selection, in_model: Sequence[int],
            rivals: dict[int, Candidate], level: float) -> dict[int, tuple[Test, Test]]:
    """Named effects (keys of ``rivals``, in ``in_model``) that their rival outdoes: given every
    other effect in ``in_model``, the rival adds significantly (at ``level``) over the effect
    and the effect adds nothing over the rival; each with (the rival's test over it, its test
    over the rival). Under the selection's last filter and weights, from one fit of the
    complete model (each effect left out by Frisch-Waugh-Lovell). Why: rivals that are not
    candidates (one drive's own delay) still show what a named effect may stand in for."""
    last = selection.steps[-1]
    filtered = last.whiten                  # the identity when the noise was white
    n, f, p = model.shape
    candidates = selection.candidates
    complete, offsets = complete_fit(model, y, candidates, in_model, filtered, last.fit.weights)
    out = {}
    for i, rival in rivals.items():
        found = _left_out(complete, offsets, candidates, in_model, i, filtered)
        if found is None:
            continue
        fit, own = found
        other = candidate_basis(filtered(rival.columns), fit)
        if other.shape[1] == 0:
            continue
        over_other, over_own = encompassing(own, other, fit.residual, (n, f), fit.rank)
        rival_adds = over_own.tested and over_own.pvalue <= level
        own_adds = over_other.tested and over_other.pvalue <= level
        if rival_adds and not own_adds:
            out[i] = (over_own, over_other)
    return out


def weakest_over(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
                 i: int, rivals: Sequence[np.ndarray], whiten: Callable[[np.ndarray], np.ndarray],
                 weights: np.ndarray, scale: tuple[float, float]) -> tuple[Test, int] | None:
    """What candidate ``i`` (in ``in_model``) adds over each rival (n, f) whose fitted
    coefficient lies in ``scale`` (given every other effect in ``in_model``, ``i`` left out):
    the weakest of those tests (largest p) and its rival's index; None when no rival is in
    scale or ``i`` has no direction of its own. Why: a named effect that some member of a
    physical family (a resonant lag over its grid) explains as well cannot be told from that
    family on these data; the scale keeps the member physical (a third of a resonance, which
    is no elastic joint, imitated a first-order filter's lag)."""
    if not rivals:
        return None
    n, f, p = model.shape
    found = _left_out(*complete_fit(model, y, candidates, in_model, whiten, weights), candidates, in_model, i, whiten)
    if found is None:
        return None
    fit, own = found
    Z = np.stack([(whiten(rival) * fit.weights[None, :]).reshape(n * f) for rival in rivals], axis=1)
    beyond = fit.orthogonal(Z)                       # every rival projected off the model at once
    size = np.einsum("xr,xr->r", beyond, beyond)
    fitted = (beyond.T @ fit.residual) / np.where(size > 0, size, 1.0)
    in_scale = [r for r in range(len(rivals)) if size[r] > 0 and scale[0] <= fitted[r] <= scale[1]]
    others = {r: orthonormal_basis(beyond[:, r:r + 1], ABSORB_TOL, reference=Z[:, r:r + 1]) for r in in_scale}
    others = {r: b for r, b in others.items() if b.shape[1]}
    weakest: tuple[Test, int] | None = None
    pairs = encompassing_each(own, list(others.values()), fit.residual, (n, f), fit.rank)
    for r, (over, _) in zip(others, pairs):
        if not over.tested:              # no test to make: the rival is the candidate on these data
            continue
        if weakest is None or over.z < weakest[0].z:
            weakest = (over, r)
    return weakest


def added_test(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
               i: int, whiten: Callable[[np.ndarray], np.ndarray], weights: np.ndarray,
               sparse: bool = False) -> Test | None:
    """The Wald test of candidate ``i`` added to the model and the effects ``in_model`` (i not
    among them), filtered by ``whiten`` at ``weights``; None when i has no direction of its
    own there or the fit needs a refit. Why: an effect found significant at its step, then
    held back, may explain nothing the final model leaves (it stood in for one named later).
    ``sparse``: directions acting on few samples are tested too (:func:`_sparse_test`)."""
    n, f, _ = model.shape
    found = _left_out(*complete_fit(model, y, candidates, [*in_model, i], whiten, weights), candidates,
                      [*in_model, i], i, whiten)
    if found is None:
        return None
    fit, own = found
    return wald(fit.residual, own, (n, f), fit.rank, sparse_if_white=sparse, sparse_if_coloured=sparse)
