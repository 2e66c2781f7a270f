"""What changed between recordings: ``diagnose MECH CHANGED... --baseline BASE...``.

Two sets of runs of one robot, the second after something changed (a payload, a drive's
gain, its friction, an offset, a delay), are fitted with one model: the inertial
parameters (with ``--params`` the given simulation), the mechanism's own effects, viscous
and Coulomb friction, an offset and a gear's load friction on every coordinate, and one
delay between positions and torques, fitted to the baseline runs. The load friction
mu |tau| sign(qd) is computed from each side's own measured torque, and kept where the runs
are paired and the baseline determines it as a gear's (:data:`LOAD_MIN` to :data:`LOAD_MAX`):
a payload's torque passes through the same gearbox, so the friction it adds is the shared
model's, not a change (a 0.48 kg payload on a simulated UR5 with mu 0.1 was named with
friction changes on three joints without it). Its residual on both sides holds what the
model always lacked, and on the changed side the change as well.

What the model lacks in both cancels by pairing: each changed sample is paired with the
baseline sample in the nearest state (positions and speeds, each scaled by its
spread), and the change is tested on the difference of their residuals. A force that
depends on the state alone (a friction law of another shape, a missing spring, an
unmodelled inertia) is the same in both and drops out. Why not a joint fit with the
change's columns alone: the common lack leaks into whatever the change candidates can
imitate (a 2.8 kg payload was named with elbow and shoulder gain changes that never
happened, and a model error became a body on the wrong link). When the runs do not share
their states (other motions), a note says so, the change is tested on the changed runs'
residual, and a change is named only when its force outgrows what the shared model misses
on baseline motions it was not fitted to.

The candidates act on the changed runs only, late by the shared delay: a payload or
changed body at each moving body (``body``: ten parameters; ``mass``: a point mass at the
frame origin), a torque-gain scale (``gain``), viscous and Coulomb friction and an offset
per coordinate, one delay. Each of these steps must hold for a change to be named:

1. the gate (closed testing): every candidate together explains the difference (an F test
   after each coordinate's autoregressive whitening fitted to the difference itself,
   :func:`rest_test`), or one candidate does (Holm) under the search's final noise model,
   each at ``alpha / 2``;
2. the search, :func:`~baseparams.diagnose.selection.select_whitened` (Wald tests,
   coloured noise whitened, Holm over the candidates);
3. each named group adds to the others by the whitened F test (Bonferroni);
4. each predicts held-out blocks of the difference (:func:`held_out_gain`);
5. what each group adds to the others' fitted force reaches half of one run's noise SD on
   some coordinate (its own force fitted beside them may be borrowed from a true change).

"Nothing changed" is the verdict when no change survives. What is left after the named
changes is "structure" (verdict "partly explained", or "unexplained" with nothing named)
when the candidates together explain it at ``alpha / 10`` and predict held-out blocks.
"""

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from baseparams.errors import InputError
from baseparams.diagnose import derived
from baseparams.diagnose.candidates import known_effect, library
from baseparams.recordings.data import MeasuredData
from baseparams.diagnose.entries import _coefficient_map
from baseparams.diagnose.estimates import coefficients, nrms
from baseparams.identify.fit import measured_design
from baseparams.diagnose.given import Given
from baseparams.diagnose.identifiable import regroup
from baseparams.diagnose.loopbodies import named_groups
from baseparams.diagnose.changeplausible import impossible_changes, shared_values
from baseparams.identify.impossible import body_limits
from baseparams.identify.linear import LinearFit, WeightedLinearModel
from baseparams.dynamics.forces import evaluate, independent_names
from baseparams.numeric.linalg import gram_route
from baseparams.diagnose.timeshift import shifted, time_derivative
from baseparams.diagnose.changesearch import (BLOCKS, UNEXPLAINED_BAR, Search, _filtered, held_out_gain,
                                             named_changes, noise_filters, predicts, rest_test)
from baseparams.diagnose.selection import Candidate, Whitening
from baseparams.model.mechanism import EffectSpec, Mechanism

# The effects shared by both sides (fitted on the baseline) besides the mechanism's own.
SHARED_KINDS = ("viscous_friction", "coulomb_friction", "offset")
# The registered effects that may change between the runs, per coordinate.
CHANGE_KINDS = ("viscous_friction", "coulomb_friction", "offset")
# A changed sample is paired with a baseline sample when their states (each coordinate's
# position and speed divided by its spread over both sides) differ by at most
# this RMS per component: 5 % of the spread. Replays of one trajectory pair at 0.1-1 %.
PAIR_DISTANCE = 0.05
# Pairing is used when at least this share of the changed samples finds a partner; the
# others are left out of the tests (a note says how many).
PAIRED_SHARE = 0.5
# Gauss-Newton steps on the shared delay, and the step (in samples) below which it stops.
DELAY_ITERATIONS = 4
DELAY_TOLERANCE = 0.05
VERDICTS = ("nothing changed", "changed", "partly explained", "unexplained")


@dataclass
class _Side:
    """One side's runs at the fit's rows: the shared columns (n, f, s), the known force (n, f),
    the standard inertial columns (n, f, P), the forces (n, f) and the states (n, 2 f:
    positions and speeds; accelerations, derived twice from a log, are too noisy to pair by)."""
    data: MeasuredData
    shared: np.ndarray
    known: np.ndarray
    standard: np.ndarray
    tau: np.ndarray
    state: np.ndarray
    rigid: np.ndarray          # (n, f): the given inertial parameters' torque (zeros when fitted)


@dataclass
class ChangeDiagnosis:
    """What :func:`diagnose_change` found; :meth:`to_json` is the documented JSON object."""
    mechanism: str
    coordinates: tuple[str, ...]
    verdict: str
    alpha: float
    changes: list[dict]
    ambiguous: list[dict]
    gap: dict
    common: dict
    pairing: dict
    rest: dict
    steps: list[dict]
    notes: list[str]
    t: np.ndarray = field(repr=False)
    difference_before: np.ndarray = field(repr=False)     # (m, f) at the tested rows
    difference_after: np.ndarray = field(repr=False)

    @property
    def closed(self) -> bool:
        return self.verdict in ("nothing changed", "changed")

    def to_json(self) -> dict:
        return {"mechanism": self.mechanism, "mode": "change", "verdict": self.verdict,
                "coordinates": list(self.coordinates), "effects": self.changes, "changes": self.changes,
                "ambiguous": self.ambiguous, "gap": self.gap, "common": self.common, "pairing": self.pairing,
                "rest": self.rest, "closed": self.closed, "alpha": self.alpha, "steps": self.steps,
                "notes": self.notes}


def shared_effects(mechanism: Mechanism) -> list[EffectSpec]:
    """The effects fitted on both sides: the mechanism's own with unknown coefficients, then
    :data:`SHARED_KINDS` on every independent coordinate it does not already have."""
    own = [e for e in mechanism.effects if not known_effect(e)]
    present = {(e.kind, e.coordinate) for e in mechanism.effects}
    extra = [EffectSpec(kind, c) for c in independent_names(mechanism) for kind in SHARED_KINDS
             if (kind, c) not in present]
    return own + extra


def _side(mechanism: Mechanism, data: MeasuredData, given: Given | None, gains: dict[str, float]) -> _Side:
    known_specs = [e for e in mechanism.effects if known_effect(e)]
    inertial, fitted, known = measured_design(mechanism, data, shared_effects(mechanism), known_specs)
    rows = data.kept_rows()
    m = data.motion
    shared = [fitted.matrix]
    rigid = np.zeros(known.shape)
    if given is None:
        shared.insert(0, inertial.matrix)
    else:
        rigid = inertial.matrix @ given.parameters
        known = known + rigid
    tau = data.tau
    if data.gain_names:               # currents, converted with the held identification's gains (_sides)
        tau = tau + data.gain_columns @ np.array([gains[g] for g in data.gain_names])
    shared.append(derived.load_columns(np.asarray(data.tau, float), m.qd[rows]))     # the last f columns
    state = np.concatenate([m.q[rows], m.qd[rows]], axis=1)
    return _Side(data, np.concatenate(shared, axis=-1), known, inertial.matrix, np.asarray(tau, float), state,
                 rigid)


# A coordinate's load friction mu is shared when the baseline determines it (mu above LOAD_Z
# standard deviations, the delay fitted too) and it is a gear's: LOAD_MIN <= mu < LOAD_MAX.
# Why the floor: a mu of 1 % is no gearbox worth naming, and such small ones were stand-ins
# for other errors (the simulations' smooth Coulomb law): on the PUMA, mu 0.012 on the last
# joint turned a payload's own torque there into a Coulomb or gain change in 10 of 10 runs.
# Why the bound: a gear dissipating half the load is already a poor one.
LOAD_Z = 3.0
LOAD_MIN = 0.02
LOAD_MAX = 0.5


def _without_load_friction(side: _Side, f: int, keep: np.ndarray) -> _Side:
    """``side`` with only the load-friction columns (its last ``f``) that ``keep`` says."""
    columns = np.concatenate([np.ones(side.shared.shape[-1] - f, bool), keep])
    return dataclasses.replace(side, shared=side.shared[:, :, columns])


def _load_friction_kept(base: _Side, given: Given | None, parameters: int, f: int
                        ) -> tuple[np.ndarray, tuple[float, np.ndarray, np.ndarray]]:
    """Which coordinates' load friction (the shared columns' last ``f``) the baseline
    determines as a gear's (f,), from the shared fit with every one of them; and where the
    fit without the others starts (its delay, coefficients and weights)."""
    delay, theta, fit = _shared_fit(base, given, parameters)
    mu, std = fit.coefficients[-f - 1:-1], fit.std[-f - 1:-1]       # the delay's step column is last
    keep = (mu > LOAD_Z * std) & (mu >= LOAD_MIN) & (mu < LOAD_MAX)
    columns = np.concatenate([np.ones(len(theta) - f, bool), keep])
    return keep, (delay, theta[columns], fit.weights)


def pair(baseline: np.ndarray, changed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(partner, distance): each changed state's nearest baseline state (index into the
    baseline rows) and their RMS difference per component, every component divided by its
    spread over both sides (a component that does not move is left out)."""
    both = np.concatenate([baseline, changed], axis=0)
    spread = np.std(both, axis=0)
    moving = spread > 1e-12 * max(float(np.max(np.abs(both), initial=0.0)), 1e-300)
    if not np.any(moving):
        return np.zeros(len(changed), int), np.zeros(len(changed))
    scale = spread[moving]
    tree = cKDTree(baseline[:, moving] / scale)
    distance, partner = tree.query(changed[:, moving] / scale, k=1)
    return np.asarray(partner, int), np.asarray(distance, float) / np.sqrt(int(np.sum(moving)))


def pair_runs(baseline: np.ndarray, changed: np.ndarray, base_runs: np.ndarray, changed_runs: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pair`, each changed run (``changed_runs``: the run of each row) within the one
    baseline run (``base_runs``) that pairs most of it, one that no earlier changed run took
    when such a run pairs at least PAIRED_SHARE of it, else against every baseline run; one run
    a side: :func:`pair`. Why: with two runs of one motion a side, both changed runs took the
    same baseline partners, so their difference rows shared that baseline noise across runs,
    and the rest test read the correlation as structure (the PUMA, nothing changed: p 1e-4 to
    0.03, 'unexplained' in 1 of 6 seeds)."""
    partner, distance = np.zeros(len(changed), int), np.zeros(len(changed))
    runs = list(dict.fromkeys(base_runs.tolist()))
    taken: set[int] = set()
    for run in dict.fromkeys(changed_runs.tolist()):
        rows = changed_runs == run
        best: tuple | None = None
        for b in (runs if len(runs) > 1 else []):
            within = np.flatnonzero(base_runs == b)
            p, d = pair(baseline[within], changed[rows])
            share = float(np.mean(d <= PAIR_DISTANCE))
            rank = (share >= PAIRED_SHARE, b not in taken, share)
            if share >= PAIRED_SHARE and (best is None or rank > best[0]):
                best = (rank, b, within[p], d)
        if best is None:
            p, d = pair(baseline, changed[rows])
            partner[rows], distance[rows] = p, d
        else:
            taken.add(best[1])
            partner[rows], distance[rows] = best[2], best[3]
    return partner, distance


def delayed_all(candidates: list[Candidate], delay: float, data: MeasuredData) -> list[Candidate]:
    """Every candidate's columns (and every shaped one's variants) late by ``delay`` (s)
    (:func:`shifted`), all in one spline (one per candidate cost a fifth of the diagnosis)."""
    if delay == 0.0:
        return list(candidates)
    blocks = [c.columns for c in candidates] + [v for c in candidates for v in c.variants]
    widths = [b.shape[-1] for b in blocks]
    moved = shifted(np.concatenate(blocks, axis=-1), data, delay)
    parts = np.split(moved, np.cumsum(widths)[:-1], axis=-1)
    out, at = [], len(candidates)
    for i, c in enumerate(candidates):
        variants = tuple(parts[at:at + len(c.variants)])
        at += len(c.variants)
        maker = c.make
        make = None if maker is None else (lambda shape, maker=maker: shifted(maker(shape), data, delay))
        out.append(Candidate(c.kind, c.coordinate, c.names, np.ascontiguousarray(parts[i]),
                             tuple(np.ascontiguousarray(v) for v in variants), c.shapes, c.shape, c.generalises, make))
    return out


# A pair belongs to a replay of one motion when its time offset (baseline time less changed
# time) agrees, within REPLAY_TOLERANCE sample periods, with at least REPLAY_SHARE of the
# offsets of the REPLAY_WINDOW rows either side: two runs of one trajectory keep one offset
# for long stretches; states that merely come close in two different motions do not.
REPLAY_WINDOW = 10
REPLAY_TOLERANCE = 3.0
REPLAY_SHARE = 0.8


def replayed(partner: np.ndarray, t_base: np.ndarray, t_changed: np.ndarray) -> np.ndarray:
    """Which pairs (each changed row's baseline ``partner``) hold a time offset shared by
    their neighbours: the changed run replays the baseline's motion there. Why: paired by
    state alone, 51 % of the TX40's last 3 s found a partner in its first 6 s, another
    motion, and the difference at those pairs was 2.9 times the torque (12 changes named)."""
    n = len(partner)
    if n == 0:
        return np.zeros(0, bool)
    offset = t_base[partner] - t_changed
    period = float(np.median(np.diff(t_changed))) if n > 1 else 1.0
    tolerance = REPLAY_TOLERANCE * max(period, float(np.median(np.diff(t_base))) if len(t_base) > 1 else 0.0)
    agree = np.zeros(n)
    count = np.zeros(n)
    for k in range(1, REPLAY_WINDOW + 1):
        close = np.abs(offset[k:] - offset[:-k]) <= tolerance
        agree[k:] += close
        agree[:-k] += close
        count[k:] += 1
        count[:-k] += 1
    return agree >= REPLAY_SHARE * np.maximum(count, 1)


def _change_candidates(mechanism: Mechanism, side: _Side, predicted: np.ndarray,
                       coordinates: tuple[str, ...]) -> tuple[list[Candidate], list[str]]:
    """The candidates for a change, on every fit row of the changed side."""
    data = side.data
    sample = data.sample if data.sample is not None else evaluate(mechanism, data.motion)
    pairs = [(kind, c) for c in coordinates for kind in CHANGE_KINDS]
    reduce = data.reduce if data.reduced else None
    plain = dataclasses.replace(mechanism, effects=())   # the library skips the mechanism's own effects:
    registered, notes = library(plain, sample, data.motion.count, pairs, reduce)
    given = derived.given_candidates(mechanism, coordinates, predicted, side.standard)
    t = data.t
    delay = derived.torque_candidates(coordinates, t, np.zeros_like(predicted), predicted, {("delay", "all")})
    return given + registered + delay, notes


def _physical_text(entry: dict) -> None:
    """A payload's centre of mass (m) where the mass and first moments are identified."""
    if entry["kind"] != "body":
        return
    c = entry["coefficients"]
    m = c.get("m", {}).get("value")
    firsts = [c.get(k, {}).get("value") for k in ("mx", "my", "mz")]
    if m is not None and abs(m) > 0 and all(v is not None for v in firsts):
        entry["centre_of_mass"] = [float(v) / float(m) for v in firsts]


def _shared_fit(base: _Side, given: Given | None, parameters: int,
                start: tuple[float, np.ndarray, np.ndarray] | None = None) -> tuple[float, np.ndarray, LinearFit]:
    """(delay, coefficients, the last step's fit): the shared model fitted to the baseline, a delay between the
    positions and the torques included (a filter's or a bus's lag is the robot's, on both
    sides): Gauss-Newton on the delay, the model's columns shifted exactly (cubic) at each
    step and the rigid bodies' torque's derivative the step's column (a friction's jumps made
    spikes of its derivative that pulled the delay to half its value). ``start``: (delay,
    coefficients, weights) to start from (a fit of nearly these columns: one step is enough)."""
    rigid = slice(0, 0 if given is not None else parameters)
    step_size = max(float(np.median(np.diff(base.data.t))), 1e-12) if len(base.data.t) > 1 else 1.0
    if start is None:
        delay = 0.0
        fit = WeightedLinearModel(base.shared, base.tau - base.known).fit()
        theta, weights = fit.coefficients, fit.weights
    else:
        delay, theta, weights = start
    for _ in range(DELAY_ITERATIONS):     # each step's model from the one before (converged: the same)
        shared, known = shifted(base.shared, base.data, delay), shifted(base.known, base.data, delay)
        lag = -time_derivative(shifted(base.rigid, base.data, delay) + shared[:, :, rigid] @ theta[rigid], base.data)
        fit = WeightedLinearModel(np.concatenate([shared, lag[:, :, None]], axis=-1), base.tau - known).fit(
            start=weights)
        weights = fit.weights
        theta, step = fit.coefficients[:-1], float(fit.coefficients[-1])
        delay += step
        if abs(step) <= DELAY_TOLERANCE * step_size:
            break
    return delay, theta, fit


# The named changes' lag is moved to only when its estimate is this many of its standard
# deviations from the shared delay (whitened rows).
LAG_Z = 3.0


def _change_lag(chosen: Search, kept: set, y: np.ndarray, data: MeasuredData, rows: np.ndarray) -> float:
    """The delay (s) by which the named changes' force in ``y`` (the paired ``rows`` of
    ``data``'s fit rows) is later than their columns: one Gauss-Newton step, the force's
    time derivative a column beside theirs, fitted on rows whitened as the search's tests
    are (:func:`.changesearch.noise_filters` of this model's residual); 0 when nothing was
    named or the step is within LAG_Z of its standard deviations. Why whitened and tested:
    fitted by least squares on the raw rows, low-passed noise moved a UR5 shoulder's named
    friction drift 16.8 ms off the true delay, and the search run again there named nothing."""
    named = [j for j in chosen.in_model if j in kept]
    if not named:
        return 0.0
    weights = chosen.weights
    X = np.concatenate([chosen.candidates[j].columns for j in named], axis=-1)
    force = X @ WeightedLinearModel(X, y).fit(weights).coefficients
    full = np.zeros((len(data.t),) + force.shape[1:])
    full[rows] = force
    derivative = -time_derivative(full, data)[rows]
    columns = np.concatenate([X, derivative[:, :, None]], axis=-1) * weights[None, :, None]
    filters = noise_filters(y * weights[None, :], columns, unit=chosen.unit)
    A = _filtered(filters, columns)
    A = A.reshape(-1, A.shape[-1])
    b = _filtered(filters, y * weights[None, :]).reshape(-1)
    value, *_ = np.linalg.lstsq(A, b, rcond=None)
    rest = b - A @ value
    variance = float(rest @ rest) / max(len(b) - A.shape[1], 1)
    inverse = np.linalg.pinv(A.T @ A)
    std = float(np.sqrt(max(inverse[-1, -1] * variance, 0.0)))
    return float(value[-1]) if abs(value[-1]) > LAG_Z * std else 0.0


def diagnose_change(mechanism: Mechanism, baseline: MeasuredData, changed: MeasuredData, *,
                    given: Given | None = None, alpha: float = 0.05) -> ChangeDiagnosis:
    """What changed between the ``baseline`` runs and the ``changed`` runs (module docstring);
    its rank-deficient fits through their Gram matrices (:func:`~baseparams.numeric.linalg.gram_route`)."""
    with gram_route():
        return _diagnose_change(mechanism, baseline, changed, given, alpha)


def _diagnose_change(mechanism: Mechanism, baseline: MeasuredData, changed: MeasuredData, given: Given | None,
                     alpha: float) -> ChangeDiagnosis:
    """:func:`diagnose_change`'s work."""
    coordinates, base, other = _sides(mechanism, baseline, changed, given, alpha)
    notes: list[str] = []
    f = len(coordinates)
    partner, distance = pair_runs(base.state, other.state, base.data.run_of_row(), other.data.run_of_row())
    matched = (distance <= PAIR_DISTANCE) & replayed(partner, base.data.t, other.data.t)
    share = float(np.mean(matched))
    paired = share >= PAIRED_SHARE
    # the load friction only between runs of one motion: on another the shared model
    # extrapolates, and a mu fitted to one half of the real TX40 recording (0.4 on joint 3,
    # standing in for what the model lacks) made an 85 % "gain change" on joint 5 of the other
    loaded, start = np.zeros(f, bool), None
    if paired:
        loaded, start = _load_friction_kept(base, given, len(mechanism.parameters), f)
    result = _diagnosed(mechanism, coordinates, base, other, given, alpha, loaded, start,
                        (partner, matched, share, paired, distance), list(notes))
    if loaded.any():
        plain = _diagnosed(mechanism, coordinates, base, other, given, alpha, np.zeros(f, bool), None,
                           (partner, matched, share, paired, distance), list(notes))
        if _simpler(plain, result):
            mu = ", ".join(f"{c} {v:.3g}" for c, v in result.common["load_friction"].items())
            plain.notes.append(f"the baseline's gear load friction (mu {mu}) is left out of the shared model: with it "
                               f"the change took {_size(result)} named change(s) and the verdict '{result.verdict}', "
                               f"without it {_size(plain)} and '{plain.verdict}' (a load friction that stands in for "
                               "what the model lacks predicts a friction change with every change of load)")
            return plain
    return result


def _size(result: ChangeDiagnosis) -> int:
    """How many changes a result names (an ambiguous group counts as one)."""
    return len(result.changes) + len(result.ambiguous)


def _simpler(a: ChangeDiagnosis, b: ChangeDiagnosis) -> bool:
    """Whether ``a`` tells the change more simply than ``b``: fewer named changes, or as many
    and a closed verdict where ``b``'s is not. Why: a load friction the baseline fitted (mu 0.06-0.1
    on a simulated xArm7's and Z1's wrists, none simulated: it stood in for the smooth Coulomb
    law) predicted a friction change with the payload's torque; four friction and gain changes
    were named beside the payload, or "structure remains". A real one (a UR5 simulated with a
    gear's mu 0.1) leaves friction changes on several joints when left out."""
    return _size(a) < _size(b) or (_size(a) == _size(b) and a.closed and not b.closed)


def _diagnosed(mechanism: Mechanism, coordinates: tuple[str, ...], base: _Side, other: _Side, given: Given | None,
               alpha: float, loaded: np.ndarray, start: tuple | None, matching: tuple, notes: list[str]
               ) -> ChangeDiagnosis:
    """The change search and its report with the shared model holding the load friction of the
    coordinates ``loaded`` (its fit started at ``start``); ``matching``: (partner, matched,
    share, paired, distance) of the changed samples (:func:`pair`)."""
    partner, matched, share, paired, distance = matching
    f = len(coordinates)
    base, other = _without_load_friction(base, f, loaded), _without_load_friction(other, f, loaded)
    delay, theta, _ = _shared_fit(base, given, len(mechanism.parameters), start)
    shared_base, known_base = shifted(base.shared, base.data, delay), shifted(base.known, base.data, delay)
    shared_other, known_other = shifted(other.shared, other.data, delay), shifted(other.known, other.data, delay)
    y_base, y_other = base.tau - known_base, other.tau - known_other
    residual_base = y_base - shared_base @ theta
    residual_other = y_other - shared_other @ theta
    predicted = known_other + shared_other @ theta
    rows, difference = _tested_rows(residual_base, residual_other, partner, matched, share, f, notes)

    raw, more = _change_candidates(mechanism, other, predicted, coordinates)
    notes += more

    def floored(chosen: Search, kept: set, delay: float) -> tuple[set, list[dict], np.ndarray]:
        if paired:
            return kept, [], np.zeros(0)
        # what both lack does not cancel: a change must outgrow the model's own error
        floor = _transfer_error(base, given, delay, theta.shape[0])
        return (*_above_floor(chosen, difference, floor, coordinates, kept), floor)

    chosen, kept, gate, delay, below, floor = _plausible_search(mechanism, given, theta, raw, rows, delay, other.data,
                                                                difference, alpha, notes, paired, floored)
    weights = chosen.weights
    if below:
        notes.append(f"{len(below)} significant candidate{'s' if len(below) != 1 else ''} not named: each force is "
                     f"smaller than {DOMINANCE:g} times what the shared model misses on baseline motions it was not "
                     "fitted to (" + ", ".join(f"{c} {v:.3g}" for c, v in zip(coordinates, floor)) + "): "
                     + ", ".join(b["candidate"] for b in below))
    empty = np.zeros((len(rows), f, 0))
    changes, ambiguous, _ = _entries(chosen, difference, empty, kept)
    # bodies that move together through a closed loop: one change, with its physical alternatives (issue 49)
    changes, ambiguous = named_groups(mechanism, chosen, kept, changes, ambiguous, difference, alpha,
                                      lambda search, keep: _entries(search, difference, empty, keep)[0])
    after, rest, verdict = _rest_and_verdict(chosen, kept, difference, empty, weights, bool(changes or ambiguous),
                                             paired, alpha, notes)

    tau_rows = other.tau[rows]
    gap = {"before": nrms(difference, tau_rows), "after": nrms(after, tau_rows),
           "changed_before": nrms(residual_other, other.tau),
           "changed_after": nrms(residual_other[rows] - (difference - after), tau_rows),
           "per_coordinate": {c: {"before": nrms(difference[:, j:j + 1], tau_rows[:, j:j + 1]),
                                  "after": nrms(after[:, j:j + 1], tau_rows[:, j:j + 1])}
                              for j, c in enumerate(coordinates)}}
    mu = theta[len(theta) - int(np.sum(loaded)):]
    common = {"nrms": nrms(residual_base, base.tau), "delay": delay,
              "load_friction": {str(c): float(v) for c, v in zip(np.array(coordinates)[loaded], mu)},
              "per_coordinate": {c: nrms(residual_base[:, j:j + 1], base.tau[:, j:j + 1])
                                 for j, c in enumerate(coordinates)},
              "cancelled": paired}
    pairing = {"paired": paired, "share": share, "median_distance": float(np.median(distance)),
               "samples": int(len(rows)), "baseline_samples": int(len(y_base)), "changed_samples": int(len(y_other))}
    steps = chosen.steps
    t = other.data.t[rows]
    return ChangeDiagnosis(mechanism.name, coordinates, verdict, alpha, changes, ambiguous, gap, common, pairing,
                           {**rest, "below_model_error": below, "gate": gate}, steps, notes, t, difference, after)


def _sides(mechanism: Mechanism, baseline: MeasuredData, changed: MeasuredData, given: Given | None,
           alpha: float) -> tuple[tuple[str, ...], _Side, _Side]:
    """The coordinates and both sides, once the two sets of runs are known to be comparable
    (alike coordinates, gains and model columns; baseline samples enough to fit the model)."""
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha must be in (0, 1), not {alpha}", key="--alpha")
    coordinates = independent_names(mechanism)
    if baseline.coordinates != changed.coordinates:
        raise InputError("the baseline and the changed runs hold other coordinates", key="--baseline")
    gains = dict(given.gains) if given is not None else {}
    # currents of unknown gains: nothing in two runs that differ by an unknown change fixes their
    # scale. Why: fitted as shared unknowns, every gain unknown gave the trivial fit (gains and
    # model 0: 'nothing changed', NRMS 0 -> 0, for a hidden payload on the PUMA), and with one
    # gain known the others came out zero within their noise and a -91 % gain change was named
    unknown = sorted({g for g in baseline.gain_names + changed.gain_names if g not in gains})
    if unknown:
        raise InputError(f"the gains {', '.join(unknown)} of these runs are unknown, and two runs that differ by an "
                         "unknown change cannot fix them: identify them first (`identify` of runs with a known "
                         "payload or a known gain) and give that result with --params, or give the gains in the "
                         "recording descriptions", key="--baseline")
    base = _side(mechanism, baseline, given, gains)
    other = _side(mechanism, changed, given, gains)
    if base.shared.shape[-1] != other.shared.shape[-1]:
        raise InputError("the baseline and the changed runs give the model other columns", key="--baseline")
    if len(base.tau) * len(coordinates) < base.shared.shape[-1] + 20:
        raise InputError(f"{len(base.tau)} baseline samples cannot fit the shared model's {base.shared.shape[-1]} "
                         "columns: give longer baseline runs", key="--baseline")
    return coordinates, base, other


def _tested_rows(residual_base: np.ndarray, residual_other: np.ndarray, partner: np.ndarray, matched: np.ndarray,
                 share: float, f: int, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The changed samples tested and the difference there: the changed residual minus its
    baseline partner's when the runs share their motion, else the changed residual alone."""
    if share >= PAIRED_SHARE:
        rows = np.flatnonzero(matched)
        difference = residual_other[rows] - residual_base[partner[rows]]
        if share < 1.0:
            notes.append(f"{100 * (1 - share):.0f} % of the changed samples have no baseline sample in the same state "
                         f"(within {100 * PAIR_DISTANCE:.0f} % of each spread): left out of the tests")
    else:
        rows = np.arange(len(residual_other))
        difference = residual_other
        notes.append(f"the runs do not share their motion ({100 * share:.0f} % of the changed samples have a baseline "
                     "sample in the same state): what the model lacks in both does not cancel, and a change is "
                     "tested on the changed runs' residual against the baseline's model; record both sides "
                     "along the same trajectory to cancel it")
    if len(rows) * f < 40:
        raise InputError(f"{len(rows)} changed samples can be compared with the baseline: too few to test a "
                         "change", key="DATA")
    return rows, difference


def _search(raw: list[Candidate], rows: np.ndarray, delay: float, data: MeasuredData, difference: np.ndarray,
            alpha: float, notes: list[str], paired: bool) -> tuple[Search, set, dict, float]:
    """The named changes among the candidates at the shared model's delay, searched again at
    the lag the named changes' force shows when it misses it: (search, kept, gate, delay).
    Each coordinate's whitened noise is brought to unit variance only when ``paired``: then
    the difference is noise; between other motions it is the shared model's error, whose
    predictability is no noise level (so weighted, the real TX40's halves named an 85 %
    gain change on joint 5)."""
    # a change's force reaches the torques through the same lag
    candidates = [c.rows(rows) for c in delayed_all(raw, delay, data)]
    chosen, kept, gate = named_changes(candidates, difference, alpha, notes, unit=paired)
    lag = _change_lag(chosen, kept, difference, data, rows)
    if abs(lag) > DELAY_TOLERANCE * float(np.median(np.diff(data.t))):
        # the lag that the changed force shows, when the shared model's delay misses it: a
        # delay off by 2 ms left 0.4 noise SDs of a 45 g payload's force on the PUMA's wrist,
        # and torque gains were named for it; searched again, the candidates late by it too
        delay += lag
        notes.append(f"the named changes' force lags by {1e3 * delay:.3g} ms (the shared model's delay corrected by "
                     f"{1e3 * lag:+.3g} ms); the candidates were searched again at that lag")
        candidates = [c.rows(rows) for c in delayed_all(raw, delay, data)]
        retry: list[str] = []
        chosen, kept, gate = named_changes(candidates, difference, alpha, retry, unit=paired)
        notes += retry
    return chosen, kept, gate, delay


# Rounds of the search without the changes no robot makes that it named (changeplausible).
PLAUSIBLE_ROUNDS = 3


def _plausible_search(mechanism: Mechanism, given: Given | None, theta: np.ndarray, raw: list[Candidate],
                      rows: np.ndarray, delay: float, data: MeasuredData, difference: np.ndarray, alpha: float,
                      notes: list[str], paired: bool,
                      floored: Callable[[Search, set, float], tuple[set, list, np.ndarray]]
                      ) -> tuple[Search, set, dict, float, list[dict], np.ndarray]:
    """:func:`_search` and ``floored`` (the changes kept above the shared model's error, with
    those below it and that floor), again without each change no robot makes (a friction
    left below zero, a body beyond any physical scale: :mod:`.changeplausible`), until none is."""
    shared = shared_values(mechanism, shared_effects(mechanism), theta, 0 if given is not None
                           else len(mechanism.parameters))
    limits = body_limits(mechanism)
    empty = np.zeros((len(rows), difference.shape[1], 0))
    for round_ in range(PLAUSIBLE_ROUNDS):
        said: list[str] = []
        chosen, kept, gate, found = _search(raw, rows, delay, data, difference, alpha, said, paired)
        kept, below, floor = floored(chosen, kept, found)
        named = [(c.kind, c.coordinate) for i, c in enumerate(chosen.candidates) if i in kept and i in chosen.in_model]
        judged = any(key in shared or (limits and key[0] in ("body", "mass")) for key in named)
        refused = impossible_changes(_entries(chosen, difference, empty, kept)[0], shared, limits) if judged else []
        if not refused:
            break
        out = {(kind, coordinate) for kind, coordinate, _ in refused}
        if round_ == PLAUSIBLE_ROUNDS - 1:       # the last round: not named, not searched again
            kept = {i for i in kept if (chosen.candidates[i].kind, chosen.candidates[i].coordinate) not in out}
            notes += [why.replace("searched for without it", "not named") for _, _, why in refused]
            break
        raw = [c for c in raw if (c.kind, c.coordinate) not in out]
        notes += [why for _, _, why in refused]
    notes += said
    return chosen, kept, gate, found, below, floor


def _rest_and_verdict(chosen: Search, kept: set, difference: np.ndarray, empty: np.ndarray, weights: np.ndarray,
                      named: bool, paired: bool, alpha: float,
                      notes: list[str]) -> tuple[np.ndarray, dict, str]:
    """The difference after the named changes, the test of what the other candidates leave
    in it, and the verdict: (after, rest, verdict)."""
    final = [chosen.candidates[i].columns for i in chosen.in_model if i in kept]
    model_after = np.concatenate([empty] + final, axis=-1)
    after = difference - (model_after @ _plain_fit(model_after, difference, weights).coefficients
                          if model_after.shape[-1] else 0.0)
    left = [c.columns for i, c in enumerate(chosen.candidates) if i not in kept]
    rest = rest_test(after, np.concatenate(left, axis=-1), model_after, weights, unit=chosen.unit) if left else \
        {"stat": 0.0, "df": 0, "pvalue": 1.0}
    # other motions: what both lack stays in the difference, and a test of it says nothing of a change
    # and "structure" is what predicts held-out blocks, not only what a test calls significant
    if left and rest["pvalue"] <= alpha / UNEXPLAINED_BAR:
        rest["held_out_gain"] = held_out_gain(after, np.concatenate(left, axis=-1), weights).tolist()
    structure = paired and rest["pvalue"] <= alpha / UNEXPLAINED_BAR and \
        predicts(np.asarray(rest.get("held_out_gain", [0.0])))
    verdict = ("partly explained" if structure else "changed") if named else \
        ("unexplained" if structure else "nothing changed")
    if not named and not structure and rest["pvalue"] <= alpha:
        why = (f"below the bar for a change with nothing named ({alpha / UNEXPLAINED_BAR:.2g})"
               if rest["pvalue"] > alpha / UNEXPLAINED_BAR else
               "that does not predict held-out blocks of the difference" if paired else
               "the runs are of other motions")
        notes.append(f"the difference leans on the candidates together (p = {rest['pvalue']:.2g}), but {why}")
    whiten = Whitening.of(after)
    if whiten is not None and np.max(whiten.rho) > 0.5:
        notes.append("the difference's noise is coloured (lag-1 autocorrelation up to "
                     f"{float(np.max(whiten.rho)):.2f}); the tests whiten it")
    return after, rest, verdict


def _plain_fit(model: np.ndarray, y: np.ndarray, weights: np.ndarray) -> LinearFit:
    return WeightedLinearModel(model, y).fit(weights)


def _transfer_error(base: _Side, given: Given | None, delay: float, width: int) -> np.ndarray:
    """Per coordinate, what the shared model misses on baseline motions it was not fitted to,
    beyond what it misses on those it was: each of BLOCKS contiguous blocks predicted from
    the others, the largest excess of its RMS error over the fitted residual's, in quadrature
    (0 where the model transfers). The largest, not the mean: the changed runs' motion is one
    more block, and as novel as the most novel one (the TX40's last 3 s missed by 1.3 NRMS
    what the mean of two halves of its first 6 s put at 0.8 N m on joint_4)."""
    shared = shifted(base.shared, base.data, delay)
    y = base.tau - shifted(base.known, base.data, delay)
    n, f = y.shape
    fitted = y - shared @ WeightedLinearModel(shared, y).fit().coefficients
    edges = np.linspace(0, n, BLOCKS + 1).astype(int)
    worst = np.zeros(f)
    for a, b in zip(edges[:-1], edges[1:]):
        train = np.r_[0:a, b:n]
        if len(train) * f < width + 20 or b <= a:
            continue
        coefficients = WeightedLinearModel(shared[train], y[train]).fit().coefficients
        missed = np.mean((y[a:b] - shared[a:b] @ coefficients) ** 2, axis=0) - np.mean(fitted[a:b] ** 2, axis=0)
        worst = np.maximum(worst, missed)
    return np.sqrt(np.maximum(worst, 0.0))


# A change between runs of other motions is named only when its force is this many times what
# the shared model misses on other motions of the baseline, on some coordinate.
DOMINANCE = 2.0


def _above_floor(chosen: Search, y: np.ndarray, floor: np.ndarray,
                 coordinates: tuple[str, ...], start: set) -> tuple[set, list[dict]]:
    """The candidates of the final model whose force (RMS per coordinate, fitted with the
    others) exceeds DOMINANCE times ``floor`` somewhere, with their ambiguous companions; and
    the ones that do not, with their sizes."""
    kept = set(start)
    below: list[dict] = []
    while True:            # refitted without those below: what they shared moves to the others
        more_kept, more_below = _above_floor_once(chosen, kept, y, floor, coordinates)
        below += more_below
        if more_kept == kept:
            return kept, below
        kept = more_kept


def _above_floor_once(chosen: Search, kept: set, y: np.ndarray, floor: np.ndarray,
                      coordinates: tuple[str, ...]) -> tuple[set, list[dict]]:
    weights = chosen.weights
    in_model = [i for i in chosen.in_model if i in kept]
    if not in_model:
        return set(), []
    blocks = [chosen.candidates[i].columns for i in in_model]
    values = WeightedLinearModel(np.concatenate(blocks, axis=-1), y).fit(weights).coefficients
    below, start = [], 0
    sizes = {}
    for i, block in zip(in_model, blocks):
        width = block.shape[-1]
        sizes[i] = np.sqrt(np.mean((block @ values[start:start + width]) ** 2, axis=0))
        start += width
    companions = {j: head for head, rivals in chosen.ambiguous.items() for j in rivals}
    kept = set()
    for i in (i for i in chosen.added if i in in_model):
        group = chosen.group(i)
        size = np.max([sizes[j] for j in group], axis=0)
        if np.any(size > DOMINANCE * floor):
            kept |= set(group)
        else:
            below.append({"candidate": chosen.candidates[i].label,
                          "rms": {c: float(v) for c, v in zip(coordinates, size)}})
    kept |= {j for j in companions if companions[j] in kept}
    return kept, below


def _entries(chosen: Search, y: np.ndarray, empty: np.ndarray, kept: set
             ) -> tuple[list[dict], list[dict], list[int]]:
    """The named changes among ``kept`` (coefficients with HAC standard deviations, a body's
    identifiable combinations) and the ambiguous groups."""
    in_model = [i for i in chosen.in_model if i in kept]
    candidates = chosen.candidates
    weights = chosen.weights
    estimates = dict(zip(in_model, coefficients(empty, candidates, in_model, y, weights)))
    ambiguous_heads = set(chosen.ambiguous)
    changes, groups = [], []
    for i in chosen.added:
        if i not in kept:
            continue
        cand = candidates[i]
        values, stds = estimates[i]
        if i in ambiguous_heads:
            members = [candidates[j] for j in chosen.group(i)]
            groups.append({"candidates": [{"kind": c.kind, "coordinate": c.coordinate} for c in members]})
            continue
        regrouped = None
        if cand.kind == "body":
            others = [candidates[j].columns for j in in_model if j != i]
            X = np.concatenate([empty] + others, axis=-1) * weights[None, :, None]
            columns = cand.columns * weights[None, :, None]
            full = WeightedLinearModel(np.concatenate([empty] + others + [cand.columns], axis=-1), y).fit(
                weights, cov_type="hac")
            width = cand.columns.shape[-1]
            cov = full.covariance[-width:, -width:]
            regrouped = regroup(X.reshape(len(y) * y.shape[1], X.shape[-1]), columns.reshape(-1, width), values, cov)
        coefficient_map = _coefficient_map(cand, values, stds, regrouped)
        single = len(coefficient_map) == 1
        entry = {"kind": cand.kind, "coordinate": cand.coordinate,
                 "value": float(values[0]) if single else {k: v["value"] for k, v in coefficient_map.items()},
                 "std": float(stds[0]) if single else {k: v["std"] for k, v in coefficient_map.items()},
                 "coefficients": coefficient_map,
                 "test": {"pvalue": float(chosen.tests[i]["pvalue"]), "pvalue_holm": float(chosen.tests[i]["pvalue_holm"])},
                 **({"shape": {k: float(v) for k, v in cand.shape.items()}} if cand.shape else {})}
        _physical_text(entry)
        changes.append(entry)
    return changes, groups, in_model
