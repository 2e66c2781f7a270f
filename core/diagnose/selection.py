"""Statistical selection of missing effects: forward steps of Wald tests (:mod:`.wald`: a
heteroscedasticity-and-autocorrelation-consistent covariance), Holm's correction over the
candidates, and encompassing tests that decide whether the winner is named or reported as
ambiguous with its rivals; then backward passes given the complete model.

Everything works on the weighted, stacked rows of the model (sample-major: the f
coordinates of sample 1, then of sample 2 ...). Each coordinate's rows are divided by its
noise level estimated from the current model's residual (Gautier's weighting), so a
coordinate with a large torque does not drown the others.

Why the steps are made so (the tests' own reasons: :mod:`.wald`):

- After the forward steps, two backward passes given the complete model (its residual is
  then white): an ambiguous group formed because a comparison inside it could not be made
  (:func:`regroup`) is compared again, and a named effect that no longer clears the bar it
  entered by is taken out (:func:`eliminate`); the forward steps then resume.
"""

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from baseparams.identify.linear import LinearFit as Fit, Reduced, WeightedLinearModel
from baseparams.identify.longrun import hac_lags
from baseparams.identify.weighting import TOLERANCE
from baseparams.diagnose.wald import (NOT_TESTED, Test, candidate_basis, column_bases, encompassing,
                                      encompassing_each, correlation, holm, wald, wald_each)

MAX_STEPS = 12

# Whether a step's residual (n, f; the data's units) is all a diagnosis asks to explain.
Enough = Callable[[np.ndarray], bool]
# Rivals are confusable with the winner only when what they explain is this correlated: two
# weak candidates that explain different things, neither adding over the other (on a residual
# with structure left, whitened) are not one ambiguous effect (the TX40 made a group of nine
# with correlations below 0.01).
CONFUSABLE_CORRELATION = 0.5
# Between steps the noise weights move little: refitted until no SD changes by 2 %, not 0.1 %
# (a test statistic moves by as little; half the weighted fits of a diagnosis).
STEP_TOLERANCE = 0.02


@dataclass(frozen=True)
class Candidate:
    """An effect on one coordinate: ``columns`` (N, f, c) on the independent coordinates.

    A shaped effect (Coulomb friction's transition speed) carries ``variants``: its columns
    at each value of a grid of shape parameters (``shapes``, one dict each). Selection tests
    the best variant against the current model (variable projection over the grid) and
    counts the fitted shape as one more degree of freedom; once the effect enters the model
    its variant is fixed (:meth:`at`)."""
    kind: str
    coordinate: str
    names: tuple[str, ...]
    columns: np.ndarray
    variants: tuple = ()                       # columns (N, f, c) at each shape of ``shapes``
    shapes: tuple = ()                         # shape parameters of each variant
    shape: dict = field(default_factory=dict)  # the shape of ``columns``
    generalises: tuple = ()                    # kinds this one generalises (Effect.generalises)
    make: Callable | None = field(default=None, compare=False, repr=False)
    # shape -> columns (N, f, c) at any shape value (None: the grid only)

    @property
    def label(self) -> str:
        return f"{self.kind}:{self.coordinate}"

    @property
    def extra_df(self) -> int:
        """Shape parameters fitted by the test (one per shape name, when there is a grid)."""
        return len(self.shapes[0]) if len(self.variants) > 1 else 0

    def at(self, k: int) -> "Candidate":
        """The candidate fixed at its ``k``-th shape."""
        return Candidate(self.kind, self.coordinate, self.names, self.variants[k], (), (), dict(self.shapes[k]),
                         self.generalises, self.make)

    def rows(self, index: slice | np.ndarray) -> "Candidate":
        """The candidate restricted to samples ``index`` (a slice or an index array)."""
        maker = self.make
        make = None if maker is None else (lambda shape: maker(shape)[index])
        return Candidate(self.kind, self.coordinate, self.names, self.columns[index],
                         tuple(v[index] for v in self.variants), self.shapes, self.shape, self.generalises, make)


@dataclass
class Rival:
    """Evidence on a candidate that competes with the winner: both directions of the
    encompassing test and the correlation of what the two explain."""
    index: int
    winner_over_rival: Test
    rival_over_winner: Test
    correlation: float


@dataclass
class Step:
    """One forward step: every candidate's test, the Holm-adjusted p values, the chosen
    candidate (None when nothing is significant) and the rivals it cannot be told from."""
    tests: list[Test]
    adjusted: np.ndarray
    fit: "Fit"                    # the weighted fit of the model this step tests against
    whiten: Callable[[np.ndarray], np.ndarray]   # the filter its fit and tests saw (Whitening or identity)
    chosen: int | None = None
    confusable: list[Rival] = field(default_factory=list)
    beaten: list[Rival] = field(default_factory=list)
    # the most significant candidate, which cleared Holm and opened the step, when a comparison
    # named another in its place (a rival that explains its signal, or a group resolved again),
    # and the test of what the chosen one adds over it (None: nested in it, nothing to test)
    strongest: int | None = None
    over: Test | None = None


@dataclass
class Selection:
    steps: list[Step]
    added: list[int]              # candidate indices, in the order they entered the model
    ambiguous: dict               # added index -> the confusable rivals of that step
    companions: list[int] = field(default_factory=list)   # those rivals: in the model, never named
    removed: list[tuple[int, Test, float]] = field(default_factory=list)
    # named effects taken out again by backward elimination: (index, its test given the
    # others, the bar it failed)
    regrouped: list[tuple[int, int]] = field(default_factory=list)
    # ambiguous groups resolved again once the model was complete: (old head, new winner)
    candidates: list = field(default_factory=list)
    # the candidates as selection left them: shaped ones in the model fixed at their shape
    shaped: dict = field(default_factory=dict)     # shaped ones in the model: index -> every variant
    bars: dict = field(default_factory=dict)       # named index -> the Bonferroni bar it entered by
    resolved: set = field(default_factory=set)     # ambiguous groups already resolved again
    cut: int = 0                  # significant candidates left out as ``enough`` held (0: none since the last entry)

    @property
    def in_model(self) -> list[int]:
        """Every candidate in the final model, in the order of its columns after the model's."""
        return self.added + self.companions



# ----- coloured residuals: Prais-Winsten whitening --------------------------------------------
# The largest AR(1) coefficient whitening uses (beyond it the filter is a plain difference).
MAX_RHO = 0.98


@dataclass(frozen=True)
class Whitening:
    """Per-coordinate AR(1) filter x_t - rho x_(t-1) (Prais-Winsten: the first row times
    sqrt(1 - rho^2)), applied alike to the data, the model and the candidates: feasible GLS
    (Cochrane-Orcutt). Why: on residuals correlated over tens of samples (AR(1) noise at 0.9,
    filtered recordings) the tests of candidates orthogonal to a smooth model are liberal
    however their variance is estimated: the fitted model removes the residual's
    low-frequency content, where a low-frequency candidate's own variance lives; HAC tests
    rejected at 16 % (prewhitened HAC 9 %, batch means 14 %) instead of 5 % on the PUMA with
    AR(1) noise at 0.9. The tests after whitening see a nearly white residual."""
    rho: np.ndarray                     # (f,)

    @staticmethod
    def of(residual: np.ndarray) -> "Whitening | None":
        """The filter for a residual (n, f), or None when it is white (HAC window 0)."""
        if len(residual) < 20 or hac_lags(residual) == 0:
            return None
        lag0 = np.sum(residual[:-1] ** 2, axis=0)
        rho = np.sum(residual[1:] * residual[:-1], axis=0) / np.where(lag0 > 0, lag0, 1.0)
        return Whitening(np.clip(rho, 0.0, MAX_RHO))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """x (n, f) or (n, f, c), filtered along the samples."""
        rho = self.rho if x.ndim == 2 else self.rho[:, None]
        out = np.empty_like(x)
        out[1:] = x[1:] - rho * x[:-1]
        out[0] = x[0] * np.sqrt(1.0 - rho ** 2)
        return out

    def candidate(self, cand: Candidate) -> Candidate:
        maker = cand.make
        make = None if maker is None else (lambda shape: self(maker(shape)))
        return Candidate(cand.kind, cand.coordinate, cand.names, self(cand.columns),
                         tuple(self(v) for v in cand.variants), cand.shapes, cand.shape, cand.generalises, make)


def _same(x: np.ndarray) -> np.ndarray:
    return x


# ----- the forward loop ----------------------------------------------------------------------
def select(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], alpha: float = 0.05,
           max_steps: int = MAX_STEPS, whiten: "Whitening | None" = None,
           resume: Selection | None = None, enough: "Enough | None" = None) -> Selection:
    """Forward selection: test every candidate against the current model, Holm-correct, add
    the most significant (or, for a confusable group, its strongest member, reported as
    ambiguous), refit and repeat until no candidate is significant. Then backward
    elimination (:func:`eliminate`): a named effect that no longer clears the bar it entered
    by, once the effects named after it are in, is taken out and may not come back, and the
    forward steps resume; until nothing is taken out. The last step always tests the final
    model (its ``fit`` is the final fit, ``chosen`` None unless ``max_steps`` ran out).

    ``enough``: whether a step's residual (n, f, in the data's units, unfiltered) is all the
    question asks to explain; then that step adds nothing, as if no candidate were
    significant (its tests are still made and kept).

    A confusable group enters the working model whole (its strongest member among ``added``,
    the others as ``companions``): with only one member in, what the hidden member adds over
    it, a small but sharp remainder, was chased by further candidates (the SLA, viscous
    friction on the upper arm hidden, named four wrong effects after its group).

    ``whiten``: a filter for coloured noise (:class:`Whitening`, estimated from a complete
    model's residual: :func:`select_whitened`) applied to the data, the model and every
    candidate before each fit and test.

    ``resume``: a selection made with another filter (the first round of
    :func:`select_whitened`), continued from where it stopped: its model is tested again
    under ``whiten``, effects that no longer clear their bar are taken out and missing ones
    added, with the same rules; its steps stay in the history. ``max_steps`` counts the new
    steps only."""
    n, f, _ = model.shape
    filtered: Callable[[np.ndarray], np.ndarray] = whiten or _same
    # Coloured noise (whitened data): a direction acting on few samples is tested with the
    # stationary variance, for entry and in comparisons. Why: refused, the truth never
    # entered and a stand-in took its place (a four-bar's gear loss, whitened, acts on 4 % of
    # the samples: Coulomb friction on the other joint was named in 3 of 20 under AR(1) 0.9),
    # and a refused comparison counted as nesting, so Coulomb friction and viscous friction on
    # the other joint ended ambiguous in 9 of 20 although Coulomb added p 1e-173 over it. On
    # white noise a refused comparison waits for the complete model (:func:`regroup`).
    coloured = whiten is not None
    # the selection so far, grown in place; shaped candidates are fixed at their variant on entry
    state = Selection([], [], {}, candidates=list(candidates)) if resume is None else _resumed(resume)
    touched: set = set()                      # places where the model changed since the last step
    if resume is not None:
        touched = {"all"}                     # every shape is chosen again under the new filter
        max_steps = len(state.steps) + max_steps
    previous = None
    known: KnownFit | None = None             # the last step's fit, which the next complete fit extends
    whitened: dict[int, tuple[Candidate, Candidate]] = {}
    while len(state.steps) < max_steps:
        candidates, in_model = state.candidates, state.in_model
        complete = refine_shapes(model, y, candidates, in_model, state.shaped, previous, filtered, touched, known)
        touched = set()
        blocks = [candidates[i].columns for i in in_model]
        if complete is None and known is not None and previous is not None:
            complete = _extended(known, blocks, model.shape[-1], filtered, previous)
        # the step's fit, at the weights its noise levels move to, refitted from the complete one
        design = np.concatenate([model] + blocks, axis=-1)
        fit = WeightedLinearModel(filtered(design), filtered(y)).fit(
            start=previous, tolerance=STEP_TOLERANCE if previous is not None else TOLERANCE, near=complete)
        previous, known = fit.weights, (fit, blocks)
        excluded = set(state.added) | set(state.companions) | {i for i, _, _ in state.removed}
        seen = _seen(candidates, excluded, whiten, whitened)
        tests, bases, variant = _tested(candidates, seen, fit, (n, f), coloured)
        tested = [i for i, t in enumerate(tests) if t.tested]
        adjusted = np.ones(len(candidates))
        if tested:
            adjusted[tested] = holm([tests[i].pvalue for i in tested])
        step = Step(tests, adjusted, fit, filtered)
        state.steps.append(step)
        significant = [i for i in tested if adjusted[i] <= alpha]
        if significant and enough is not None and enough(y - design @ fit.coefficients):
            significant, state.cut = [], len(significant)
        if not significant:
            if len(state.steps) >= max_steps:    # no step left to test a changed model: this fit is the last
                break
            change = regroup(model, y, candidates, state.added, state.companions, state.ambiguous, state.bars,
                             fit.weights, alpha, state.resolved, filtered)
            if change is not None:
                touched |= _regrouped(state, *change)
                continue
            out = eliminate(model, y, candidates, state.added, state.companions, state.ambiguous, state.bars,
                            fit.weights, filtered, complete=fit)    # this step's fit: the final model at these weights
            if out is None:
                break
            state.removed.append(out)
            state.added.remove(out[0])
            touched.add(candidates[out[0]].coordinate)
            continue
        strongest = max(significant, key=lambda i: tests[i].z)
        rivals = [i for i in tested if tests[i].pvalue <= alpha and i != strongest]
        winner, confusable, beaten = resolve(strongest, rivals, bases, fit, (n, f), fit.rank, alpha,
                                             nested_level=alpha / len(tested),
                                             generalises=generalisation(candidates), sparse_if_coloured=coloured)
        step.chosen, step.confusable, step.beaten = winner, confusable, beaten
        if winner != strongest:                   # a rival named for the signal the strongest cleared Holm on
            step.strongest = strongest
            step.over = encompassing(bases[winner], bases[strongest], fit.residual, (n, f), fit.rank, coloured)[0]
        touched |= _entered(state, winner, confusable, variant, alpha / len(tested))
        state.cut = 0
    return state


def _resumed(selection: Selection) -> Selection:
    """A copy of ``selection`` to continue (its lists, dicts and sets new: it stays as it was)."""
    return Selection(list(selection.steps), list(selection.added),
                     {k: list(v) for k, v in selection.ambiguous.items()}, list(selection.companions),
                     list(selection.removed), list(selection.regrouped), list(selection.candidates),
                     dict(selection.shaped), dict(selection.bars), set(selection.resolved), selection.cut)


def _seen(candidates: Sequence[Candidate], excluded: set[int], whiten: "Whitening | None",
          whitened: dict[int, tuple[Candidate, Candidate]]) -> dict[int, Candidate]:
    """The candidates a step tests (index -> candidate, those not ``excluded``) as its filter
    sees them: whitened once a pass, until a shape changes (``whitened`` keeps them)."""
    seen: dict[int, Candidate] = {}
    for i, cand in enumerate(candidates):
        if i in excluded:
            continue
        if whiten is None:
            seen[i] = cand
        else:
            if i not in whitened or whitened[i][0] is not cand:
                whitened[i] = (cand, whiten.candidate(cand))
            seen[i] = whitened[i][1]
    return seen


def _tested(candidates: Sequence[Candidate], seen: dict[int, Candidate], fit: Fit, shape: tuple[int, int],
            coloured: bool) -> tuple[list[Test], dict[int, np.ndarray], dict[int, int]]:
    """Every candidate's test against a step's ``fit`` (NOT_TESTED unless ``seen``), with the
    basis and variant index of each seen one's best form. Every form of every candidate is
    tested at once; whitened (``coloured``), a step (Coulomb friction) is a few spikes: tested
    with the classical variance when the whitened residual is white, else with the stationary one."""
    n, f = shape
    lags = hac_lags(fit.residual.reshape(n, f))     # one window per step: candidates barely change it
    forms = dict(zip(seen, candidate_bases(list(seen.values()), fit)))
    flat = [basis for i in seen for basis in forms[i]]
    extra = [seen[i].extra_df if seen[i].variants else 0 for i in seen for _ in forms[i]]
    each = wald_each([fit.residual], flat, (n, f), [fit.rank], lags, extra, sparse_if_white=coloured,
                     sparse_if_coloured=coloured)
    form_tests, at = {}, 0
    for i in seen:
        form_tests[i], at = each[at:at + len(forms[i])], at + len(forms[i])
    tests: list[Test] = []
    bases, variant = {}, {}
    for i in range(len(candidates)):
        if i not in seen:
            tests.append(NOT_TESTED)
            continue
        bases[i], test, variant[i] = best_variant(seen[i], fit, (n, f), fit.rank, bases=forms[i], tests=form_tests[i])
        tests.append(test)
    return tests, bases, variant


def _regrouped(state: Selection, old: int, winner: int, confusable: list[Rival], beaten: list[Rival]) -> set[str]:
    """An ambiguous group resolved again (:func:`regroup`) put into ``state``: ``winner`` in the
    old head's place, at its bar, and the step that entered the group rewritten. Returns the
    places where the model changed."""
    state.regrouped.append((old, winner))
    for r in state.ambiguous.pop(old):
        state.companions.remove(r.index)
    state.added[state.added.index(old)] = winner
    state.bars[winner] = state.bars[old]
    state.resolved.add(winner)
    entered = next(s for s in state.steps if s.chosen == old)
    opened = old if entered.strongest is None else entered.strongest
    entered.chosen, entered.confusable, entered.beaten = winner, confusable, beaten
    entered.strongest, entered.over = (None, None) if winner == opened else (
        opened, next((r.winner_over_rival for r in beaten if r.index == opened), None))
    if confusable:
        state.ambiguous[winner] = confusable
        state.companions.extend(r.index for r in confusable)
    return {state.candidates[old].coordinate, state.candidates[winner].coordinate}


def _entered(state: Selection, winner: int, confusable: list[Rival], variant: dict[int, int], bar: float) -> set[str]:
    """A step's ``winner`` (and its confusable group, as companions) put into ``state`` at the
    Bonferroni ``bar`` it cleared; shaped ones fixed at their tested variant (their shape is
    chosen again at each step: :func:`refine_shapes`). Returns the places where the model changed."""
    candidates = state.candidates
    group = [winner] + [r.index for r in confusable]
    for i in group:
        if candidates[i].variants:
            state.shaped[i] = candidates[i]
            candidates[i] = candidates[i].at(variant[i])
    if confusable:
        for i in group:
            candidates[i] = _beyond_named(candidates, i, state.added)
    state.added.append(winner)
    state.bars[winner] = bar
    if confusable:
        state.ambiguous[winner] = confusable
        state.companions.extend(r.index for r in confusable)
    return {candidates[i].coordinate for i in group}


def _beyond_named(candidates: Sequence[Candidate], i: int, named: Sequence[int]) -> Candidate:
    """Candidate ``i`` without the leading columns it shares with a named effect it generalises
    on its place (a body's ten beyond a payload's four), for an ambiguous group: the group
    claims one of its members, and a rival that does not generalise the named effect leaves
    it named. Why: a 94 g payload on a UR5's last link entered; then its body, confusable with
    the last joint's rotor inertia (the load's inertia about the axis), took the payload's
    columns in with it, the payload was taken out as absorbed, and the report said "body or
    rotor inertia", which the payload's force is not."""
    cand = candidates[i]
    relation = generalisation(candidates)
    for j in named:
        inner = candidates[j].columns
        w = inner.shape[-1]
        if (relation(i, j) and cand.coordinate == candidates[j].coordinate and w < cand.columns.shape[-1]
                and not cand.variants and np.array_equal(cand.columns[:, :, :w], inner)):
            return dataclasses.replace(cand, names=cand.names[w:], columns=np.ascontiguousarray(cand.columns[:, :, w:]))
    return cand


# kinds that act on a body, not a coordinate: a kind generalising them may act anywhere
BODY_KINDS = ("mass", "payload", "body")


def generalisation(candidates: Sequence[Candidate]) -> Callable[[int, int], bool]:
    """Whether candidate a's kind generalises candidate b's on the same coordinate (or on the
    body b acts on: cogging on a joint imitates the gravity of a mass carried beyond it)."""
    def relation(a: int, b: int) -> bool:
        ca, cb = candidates[a], candidates[b]
        return cb.kind in ca.generalises and (ca.coordinate == cb.coordinate or cb.kind in BODY_KINDS)
    return relation




# A fit of the model and some effects' columns (the arrays, in their order), for complete_fit to extend.
KnownFit = tuple[Fit, list[np.ndarray]]


def complete_fit(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], in_model: Sequence[int],
              whiten: Callable[[np.ndarray], np.ndarray], weights: np.ndarray,
              known: KnownFit | None = None) -> tuple[Fit, np.ndarray]:
    """The complete model's fit (the model and every effect in ``in_model``, filtered by
    ``whiten``, at ``weights``) and the column offsets of each effect (len(in_model) + 1);
    extended from ``known`` (the same model and data with fewer effects, at these weights)
    when it can be."""
    p = model.shape[-1]
    blocks = [candidates[i].columns for i in in_model]
    offsets = np.cumsum([p] + [b.shape[-1] for b in blocks])
    complete = _extended(known, blocks, p, whiten, weights) if known is not None else None
    if complete is None:
        complete = WeightedLinearModel(whiten(np.concatenate([model] + blocks, axis=-1)), whiten(y)).fit(weights)
    return complete, offsets


def _extended(known: KnownFit, blocks: list[np.ndarray], p: int, whiten: Callable[[np.ndarray], np.ndarray],
              weights: np.ndarray) -> Fit | None:
    """``known``'s fit with the blocks it has that ``blocks`` lacks taken out (a shape changed
    or an effect taken out since: :meth:`LinearFit.subset`), those it lacks added
    (:meth:`LinearFit.extended`), and its columns put in ``blocks``' order; None when it is
    at other weights or rank-deficient."""
    fit, old = known
    if not np.array_equal(fit.weights, weights):
        return None
    position: list[int] = []                  # where each of known's blocks still in use is in ``blocks``
    dropped: list[int] = []                   # known's columns no longer in use
    at = p
    for block in old:
        j = next((j for j, b in enumerate(blocks) if b is block and j not in position), None)
        if j is None:
            dropped += range(at, at + block.shape[-1])
        else:
            position.append(j)
        at += block.shape[-1]
    if dropped:
        kept = fit.subset([c for c in range(at) if c not in set(dropped)])
        if kept is None:
            return None
        fit = kept
    new = [j for j in range(len(blocks)) if j not in position]
    if new:
        n, f, _ = blocks[new[0]].shape
        columns = whiten(np.concatenate([blocks[j] for j in new], axis=-1)) * weights[None, :, None]
        grown = fit.extended(columns.reshape(n * f, -1))
        if grown is None:
            return None
    else:
        grown = fit                               # the same columns (a step that added nothing)
    start, at = {}, p                          # each block's first column in the grown fit
    for j in position + new:
        start[j], at = at, at + blocks[j].shape[-1]
    return grown.reordered(list(range(p)) + [start[j] + c for j in range(len(blocks))
                                             for c in range(blocks[j].shape[-1])])



# A selection is repeated when the complete model's residual asks for a filter differing from
# the one it ran with by more than this (in any coordinate's AR(1) coefficient).
RHO_AGREEMENT = 0.01


def select_whitened(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], alpha: float = 0.05,
                    max_steps: int = MAX_STEPS, enough: "Enough | None" = None) -> Selection:
    """:func:`select` on data, model and candidates whitened (feasible GLS, :class:`Whitening`)
    when the noise is coloured. The first AR(1) filter comes from the residual of the model
    plus every candidate at once: the model alone would leave the missing effects in its
    residual (an AR(1) coefficient near 1, a plain difference that hides a step-like effect
    among a few spikes). That residual is overfitted, its coefficient a little low (0.86 for
    0.90 on the PUMA, which made the tests liberal), so the filter is estimated again from the
    selected model's residual and the selection repeated with it when the two differ
    (Cochrane-Orcutt, one more round). ``enough``: as :func:`select`'s, in both rounds."""
    n, f = y.shape
    complete = WeightedLinearModel(np.concatenate([model] + [c.columns for c in candidates], axis=-1), y).fit()
    whiten = Whitening.of(complete.unweighted_residual())
    chosen = select(model, y, candidates, alpha, max_steps, whiten, enough=enough)
    final = np.concatenate([model] + [chosen.candidates[i].columns for i in chosen.in_model], axis=-1)
    fit = WeightedLinearModel(final, y).fit(chosen.steps[-1].fit.weights)
    again = Whitening.of(fit.unweighted_residual())
    before = whiten.rho if whiten is not None else np.zeros(f)
    after = again.rho if again is not None else np.zeros(f)
    if np.max(np.abs(after - before)) <= RHO_AGREEMENT:
        return chosen
    return select(model, y, candidates, alpha, max_steps, again, resume=chosen, enough=enough)


def refine_shapes(model: np.ndarray, y: np.ndarray, candidates: list[Candidate], in_model: list[int],
                  shaped: dict, weights: np.ndarray | None, whiten: Callable = _same,
                  touched: set | None = None, known: KnownFit | None = None) -> Fit | None:
    """Variable projection for the shaped effects in the model: each one's shape is chosen
    again given everything else in the model (the variant that leaves the smallest weighted
    residual), in place. Why: a shape chosen while other effects were still missing fits
    those too (Coulomb friction took a smooth shape, then a Stribeck bump made up the
    difference). ``touched``: the places where the model changed since the last call (a shape
    is chosen again only where something changed beside it; None: everywhere). ``known``: a
    fit at ``weights`` with fewer effects (the last step's) that the complete fit extends.
    Returns the complete fit with the shapes as left, when one was made, else None."""
    complete: Fit | None = None
    whole: Fit | None = None                  # without weights: the whole model at its own, once
    whole_columns: list[np.ndarray] = []
    for i in in_model:
        if i not in shaped or (touched is not None and candidates[i].coordinate not in touched
                               and "all" not in touched):
            continue
        # the model without i: at given weights from the model with everything (Frisch-Waugh-
        # Lovell: one factorisation for all), else a refit
        fit: Fit | Reduced | None = None
        if weights is not None:
            if complete is None:
                complete, _ = complete_fit(model, y, candidates, in_model, whiten, weights, known)
                known = (complete, [candidates[j].columns for j in in_model])
            start = model.shape[-1] + sum(candidates[j].columns.shape[-1] for j in in_model[:in_model.index(i)])
            fit = complete.without(range(start, start + candidates[i].columns.shape[-1]))
        if fit is None:
            others = [j for j in in_model if j != i]
            near = None
            if weights is None:           # at its own weights: refitted from the whole model's factors
                if whole is None:
                    whole = WeightedLinearModel(whiten(np.concatenate(
                        [model] + [candidates[j].columns for j in in_model], axis=-1)), whiten(y)).fit()
                    whole_columns = [candidates[j].columns for j in in_model]
                widths = [c.shape[-1] for c in whole_columns]
                if all(candidates[j].columns is c for j, c in zip(in_model, whole_columns)):
                    first = model.shape[-1] + sum(widths[:in_model.index(i)])
                    drop = set(range(first, first + widths[in_model.index(i)]))
                    near = whole.subset([c for c in range(len(whole.coefficients)) if c not in drop])
            fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others],
                                                            axis=-1)), whiten(y)).fit(weights, near=near)

        def explained(columns: np.ndarray) -> float:
            basis = candidate_basis(whiten(columns), fit)
            return float(np.sum((basis.T @ fit.residual) ** 2))

        gains = [float(np.sum((basis.T @ fit.residual) ** 2))
                 for basis in column_bases([whiten(columns) for columns in shaped[i].variants], fit)]
        best = int(np.argmax(gains))
        before = candidates[i]
        candidates[i] = _between(shaped[i], best, explained) or shaped[i].at(best)
        if candidates[i].columns is not before.columns:
            complete = None                   # i's columns changed: the next one needs a new complete fit
    return complete


# Shape values between grid points are searched on logarithms rounded to this step (2.5 %): the
# columns of a value met again (the next step's search) are made once (candidates._maker).
SHAPE_STEP = 0.025


def _between(cand: Candidate, k: int, explained: Callable[[np.ndarray], float]) -> Candidate | None:
    """The candidate at the shape value between grid points k - 1 and k + 1 that explains the
    most (bounded search on its logarithm), when it has one shape, a column maker and a
    positive value there; else None. Why: between grid points the misfit of the shape was
    larger than the noise, and a Stribeck bump was named to make up the difference."""
    if cand.make is None or len(cand.shapes[k]) != 1:
        return None
    (name, value), = cand.shapes[k].items()
    values = [next(iter(s.values())) for s in cand.shapes]
    if value <= 0:
        return None
    low = values[k - 1] if k > 0 and values[k - 1] > 0 else value / 2
    high = values[k + 1] if k + 1 < len(values) else value * 2
    made: dict[float, np.ndarray] = {}          # each shape's columns, made once (a filtering each)
    maker = cand.make

    def snapped(x: float) -> float:
        return round(x / SHAPE_STEP) * SHAPE_STEP

    def columns(x: float) -> np.ndarray:
        x = snapped(x)
        if x not in made:
            made[x] = maker({name: float(np.exp(x))})
        return made[x]

    # to 5 % of the value: grid points are 3 times apart, and the fit is flat near its best
    found = minimize_scalar(lambda x: -explained(columns(x)), bounds=(np.log(low), np.log(high)),
                            method="bounded", options={"xatol": 0.05})
    shape = {name: float(np.exp(snapped(found.x)))}
    return Candidate(cand.kind, cand.coordinate, cand.names, columns(found.x), (), (), shape, cand.generalises)


def candidate_bases(candidates: Sequence[Candidate], fit: "Fit | Reduced") -> list[list[np.ndarray]]:
    """:func:`candidate_basis` of every form of each candidate (its one form, or each
    variant), the projection off the model done for all at once (two matrix products
    instead of one pair per form: most of a step's cost on a robot's many candidates)."""
    forms = [list(c.variants) if c.variants else [c.columns] for c in candidates]
    bases = column_bases([columns for each in forms for columns in each], fit)
    out, at = [], 0
    for each in forms:
        out.append(bases[at:at + len(each)])
        at += len(each)
    return out


def best_variant(cand: Candidate, fit: "Fit", shape: tuple[int, int], dof: int, sparse_if_white: bool = False,
                 lags: int | None = None, sparse_if_coloured: bool = False,
                 bases: list[np.ndarray] | None = None,
                 tests: list[Test] | None = None) -> tuple[np.ndarray, Test, int]:
    """(basis, test, variant index) of the candidate's best shape against ``fit`` (the
    largest normal-equivalent statistic; the one form of an unshaped candidate); ``bases``:
    each form's :func:`candidate_basis`, when already made (:func:`candidate_bases`);
    ``tests``: each form's Wald test, when already made (:func:`wald_each`)."""
    forms = list(cand.variants) if cand.variants else [cand.columns]
    if bases is None:
        bases = [candidate_basis(columns, fit) for columns in forms]
    if tests is None:
        extra = cand.extra_df if cand.variants else 0
        tests = [wald(fit.residual, basis, shape, dof, lags=lags, extra_df=extra, sparse_if_white=sparse_if_white,
                      sparse_if_coloured=sparse_if_coloured) for basis in bases]
    if not cand.variants:
        return bases[0], tests[0], -1
    best = 0
    for k in range(1, len(tests)):
        if tests[k].z > tests[best].z:
            best = k
    return bases[best], tests[best], best


def regroup(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], added: list[int],
            companions: list[int], ambiguous: dict, bars: dict, weights: np.ndarray, alpha: float,
            done: set[int], whiten: Callable = _same) -> tuple[int, int, list[Rival], list[Rival]] | None:
    """An ambiguous group formed while a comparison inside it could not be made, resolved
    again given the rest of the final model: (the group's old strongest member, the new
    winner, its confusable rivals, the beaten ones) when the group changes, else None.

    When the difference of two rivals acts on few samples (viscous friction on the SLA's
    upper arm against the same on the lower arm: they differ only near the arms' toggle
    position), only the classical variance can test it, and only on a white residual; at the
    step the group formed, other hidden effects were still in the residual, the comparison
    was refused ('support') and the two were reported ambiguous although one is 2,500 times
    as likely. Once the model is complete the residual is white and the comparison can be
    made. (On whitened data the comparison is made at once with the stationary variance:
    there the residual's colour is the noise's, and waiting for a white one would wait for
    ever.) Groups formed with every comparison made are left as they are: the data did not
    separate them, and a second look with the same data would only add chances of a wrong
    name."""
    n, f, _ = model.shape
    for head, rivals in list(ambiguous.items()):
        if head in done:
            continue
        done.add(head)
        if not any("support" in (r.winner_over_rival.reason, r.rival_over_winner.reason) for r in rivals):
            continue
        members = [head] + [r.index for r in rivals]
        others = [j for j in added + companions if j not in members]
        fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others], axis=-1)),
                                  whiten(y)).fit(weights)
        bases = {i: candidate_basis(whiten(candidates[i].columns), fit) for i in members}
        if any(b.shape[1] == 0 for b in bases.values()):
            continue
        winner, confusable, beaten = resolve(head, members[1:], bases, fit, (n, f), fit.rank, alpha,
                                             nested_level=bars[head], generalises=generalisation(candidates))
        if winner == head and {r.index for r in confusable} == set(members[1:]):
            continue
        return head, winner, confusable, beaten
    return None


def eliminate(model: np.ndarray, y: np.ndarray, candidates: Sequence[Candidate], added: list[int],
              companions: list[int], ambiguous: dict, bars: dict, weights: np.ndarray,
              whiten: Callable = _same, complete: Fit | None = None) -> tuple[int, Test, float] | None:
    """Backward elimination, one effect at a time: each named effect (not an ambiguous
    group: those are not named) is tested beyond everything else in the final model, at the
    Bonferroni bar alpha / m it cleared to enter (the most significant of m candidates under
    Holm). The one furthest above its bar (largest p / bar) is returned when it fails, else
    None; one with nothing left beyond the others ('absorbed') fails, one whose remainder is
    too sparse to test (a Stribeck bump beside Coulomb friction on a coloured residual) is
    kept: untestable is not evidence of absence. Why: forward selection names a candidate
    that imitates two hidden effects at once
    (on the SLA, Coulomb friction on the hub imitating viscous friction on the hub plus
    Coulomb friction on a damper joint); once those are in, it adds nothing, and naming it
    is a wrong name. The noise weights are the final model's (one weighted fit per test);
    ``complete``: the final model's fit at them, when made (the last step's)."""
    named = [i for i in added if i not in ambiguous]
    if not named:
        return None
    n, f, p = model.shape
    in_model = added + companions
    if complete is None:
        complete = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in in_model],
                                                             axis=-1)), whiten(y)).fit(weights)
    offsets = np.cumsum([p] + [candidates[j].columns.shape[-1] for j in in_model])
    worst = None
    for i in named:
        k = in_model.index(i)
        fit: Fit | Reduced | None = complete.without(range(offsets[k], offsets[k + 1]))
        if fit is None:                      # the complete model is rank deficient: refit without i
            others = [j for j in in_model if j != i]
            fit = WeightedLinearModel(whiten(np.concatenate([model] + [candidates[j].columns for j in others],
                                                            axis=-1)), whiten(y)).fit(weights)
        basis = candidate_basis(whiten(candidates[i].columns), fit)
        test = wald(fit.residual, basis, (n, f), fit.rank, sparse_if_white=True)
        if not test.tested and test.reason != "absorbed":
            continue                         # too sparse to test on this residual: no evidence to take it out
        score = test.pvalue / bars[i]
        if score > 1.0 and (worst is None or score > worst[0]):
            worst = (score, i, test)
    return None if worst is None else (worst[1], worst[2], bars[worst[1]])


def _verdict(winner_adds: bool, rival_adds: bool) -> str | None:
    """Encompassing: 'beaten' (only the winner adds over the other), 'switch' (only the
    rival does), 'confusable' (neither), None (both)."""
    if winner_adds != rival_adds:
        return "beaten" if winner_adds else "switch"
    return None if winner_adds else "confusable"


def resolve(winner: int, rivals: list[int], bases: dict, fit: Fit, shape: tuple[int, int], dof: int,
            alpha: float, nested_level: float | None = None,
            generalises: Callable[[int, int], bool] | None = None,
            sparse_if_coloured: bool = False) -> tuple[int, list[Rival], list[Rival]]:
    """Compare the winner with each rival by encompassing tests (does each add significantly
    to the other?). A rival nested in the winner (an offset inside a spring on the same
    independent coordinate) replaces it unless the winner's extra directions are significant
    at ``nested_level`` (default ``alpha``; ``select`` passes Bonferroni's alpha / m, the bar
    the most significant of m candidates clears to enter the model under Holm): those extra
    directions are a further effect and must clear the same bar as any other, or the larger
    effect would be named whenever its extra directions fluctuate past alpha (an offset named
    a spring in 12-15 % of datasets at alpha = 0.05, benchmarks/bench_diagnose.py, where
    low-frequency directions make the HAC test somewhat liberal). A rival that adds over the winner
    while the winner adds nothing over it replaces the winner. Rivals over which the winner
    adds nothing, and that add nothing over the winner, are confusable with it: the data
    cannot tell them apart. When each adds over the other at alpha, both are effects only if
    each clears ``nested_level`` too (the same argument: the second is a further effect);
    otherwise the one that clears it wins, and if neither does they are confusable. (Before,
    'both add' named the winner and let the rival compete at the next step, where it failed
    Holm's bar: the slider-crank's crank offset was named for a hidden coupler offset, cos
    0.9999, in 3 of 40 datasets.) Differences acting on few samples are tested with the
    classical variance when the residual is white (``wald(..., sparse_if_white=True)``), and
    with ``sparse_if_coloured`` with the stationary variance when it is not."""
    nested_level = alpha if nested_level is None else nested_level
    seen = {winner}
    rivals = [winner] + list(rivals)       # after a switch the first winner is a rival too
    while True:
        A = bases[winner]
        confusable: list[Rival] = []
        beaten: list[Rival] = []
        switch: list[Rival] = []
        others = [j for j in rivals if j != winner]
        pairs = encompassing_each(A, [bases[j] for j in others], fit.residual, shape, dof, sparse_if_coloured)
        for j, (t_ab, t_ba) in zip(others, pairs):
            rival = Rival(j, t_ab, t_ba, correlation(fit.residual, A, bases[j]))
            a_adds = t_ab.tested and t_ab.pvalue <= alpha
            b_adds = t_ba.tested and t_ba.pvalue <= alpha
            if not (t_ab.tested or t_ba.tested) and generalises is not None and (
                    generalises(winner, j) or generalises(j, winner)):
                # one span (a planar link's payload and body): the simpler kind is named
                (switch if generalises(winner, j) else beaten).append(rival)
            elif not t_ba.tested:               # rival nested in the winner
                (beaten if t_ab.tested and t_ab.pvalue <= nested_level else switch).append(rival)
            elif not t_ab.tested:               # winner nested in the rival
                (switch if t_ba.pvalue <= nested_level else beaten).append(rival)
            else:
                # who adds over whom at alpha decides; when both do, two distinct effects only
                # if each adds at the bar of a further effect (nested_level), else one of them
                # is a fluke of alpha; both at that bar: the rival competes again next step
                verdict = _verdict(a_adds, b_adds) or _verdict(t_ab.pvalue <= nested_level,
                                                               t_ba.pvalue <= nested_level)
                if verdict == "confusable" and abs(rival.correlation) < CONFUSABLE_CORRELATION:
                    verdict = None      # unrelated, each too weak to add over the other: it competes again
                if verdict == "confusable" and generalises is not None:
                    # a kind that generalises the other (cogging's harmonics an offset over a small
                    # range) is not named for what the simpler kind explains as well
                    verdict = ("beaten" if generalises(j, winner) else
                               "switch" if generalises(winner, j) else verdict)
                if verdict is not None:
                    {"beaten": beaten, "switch": switch, "confusable": confusable}[verdict].append(rival)
        fresh = [r for r in switch if r.index not in seen]
        if not fresh:
            confusable += [r for r in switch if r.index in seen]
            return winner, confusable, beaten
        # the simplest (fewest directions), then the strongest rival that explains the winner's signal
        best = min(fresh, key=lambda r: (bases[r.index].shape[1], -r.rival_over_winner.z))
        winner = best.index
        seen.add(winner)
