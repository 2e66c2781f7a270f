"""The candidate library of diagnosis: every registered effect (third parties' included) on
every tree coordinate, or a user's selection ``KIND[:COORD]``, minus the effects the
mechanism already has. Columns come from :func:`baseparams.dynamics.forces.effect_columns`,
so an effect on a dependent coordinate (a strut spring) reaches the independent ones
through R^T exactly as simulation and identification model it.

Spring and offset: a spring's columns are q and -1 (coefficients k and k q0), and on an
independent coordinate its -1 column is exactly an offset there. Both stay candidates;
selection (:mod:`.selection`) tests what each adds beyond the current model, prefers the
offset when the spring's q column adds nothing significant beyond it, and once either is in
the model the other is tested only on what it still adds (an offset is then absorbed).
"""

import itertools
from collections.abc import Callable, Sequence

import numpy as np

from baseparams import registry
from baseparams.dynamics.evaluator import Sample
from baseparams.errors import InputError
from baseparams.diagnose import derived
from baseparams.dynamics.forces import CoordinateMotion, coordinate_motion, coordinate_speed_rms, effect_columns
from baseparams.diagnose.selection import Candidate
from baseparams.model.mechanism import EffectSpec, Mechanism


def parse_selection(mechanism: Mechanism, specs: Sequence[str], given: bool = False) -> list[tuple[str, str]]:
    """``KIND[:PLACE]`` strings -> (kind, place) pairs; a bare KIND means every place it
    acts on (tree coordinates and coupled motors; for the derived kinds of
    :mod:`.derived` the independent coordinates, the bodies, or 'all'). Unknown kinds or
    places are InputErrors naming the option; body and gain kinds need ``given``
    parameters (--params)."""
    effects = registry.effects()
    known_kinds = sorted(effects) + list(derived.TORQUE_KINDS) + (list(derived.GIVEN_KINDS) if given else [])
    independent = tuple(mechanism.independent or mechanism.coordinates)
    out: list[tuple[str, str]] = []
    for spec in specs:
        kind, _, place = spec.partition(":")
        kind, place = kind.strip(), place.strip()
        if kind in derived.GIVEN_KINDS and not given:
            raise InputError(f"{kind!r} in {spec!r} is a candidate only when the inertial parameters are "
                             "given (--params)", key="--candidates")
        if kind not in known_kinds:
            raise InputError(f"unknown effect {kind!r} in {spec!r}; known: {', '.join(known_kinds)}",
                             key="--candidates")
        if kind in derived.KINDS:
            places = derived.places(mechanism, kind, independent)
        else:
            places = tuple(mechanism.coordinates) + tuple(mechanism.motor_names)
        if place and place not in places:
            raise InputError(f"{place!r} in {spec!r} is not a place of {kind} on {mechanism.name} "
                             f"(one of: {', '.join(places)})", key="--candidates")
        default = derived.default_places(mechanism, kind, independent) if kind in derived.KINDS \
            else _places(mechanism, kind)
        for c in ([place] if place else default):
            if (kind, c) not in out:
                out.append((kind, c))
    return out


def all_pairs(mechanism: Mechanism) -> list[tuple[str, str]]:
    """Every registered effect on every tree coordinate and every coupled motor (an angular
    effect on angles only, :func:`_places`)."""
    return [(kind, c) for kind in registry.effects() for c in _places(mechanism, kind)]


def _places(mechanism: Mechanism, kind: str) -> tuple[str, ...]:
    """Where a registered effect acts by default: every tree coordinate, and the motors that
    turn with several coordinates (a coupled wrist, a differential). A motor on one joint
    moves as the joint scaled: its friction, offset or inertia is the joint's own column
    times its ratio, the same candidate under a second name (name it with KIND:MOTOR to test
    it anyway). An angular effect (harmonics of q) only where q is an angle: on a prismatic
    leg it was Coulomb friction plus a slope, and named for either (name it with KIND:COORD
    to test it anyway)."""
    places = tuple(mechanism.coordinates) + tuple(m.name for m in mechanism.motors if len(m.ratios) > 1)
    if getattr(registry.effects()[kind].item, "angular", False):     # optional for a third party's kind
        places = tuple(c for c in places if mechanism.is_angle(c))
    return places


def known_effect(spec: EffectSpec) -> bool:
    """Whether a mechanism's effect has every coefficient given (its force is known and
    subtracted from the measurements), not fitted with the inertial model."""
    return all(name in spec.values for name in registry.effects()[spec.kind].item.coefficients)


def known_values(mechanism: Mechanism, kind: str, coordinate: str) -> dict[str, float]:
    """The coefficients of the mechanism's known effect of ``kind`` on ``coordinate`` (what a
    named effect of that kind there corrects); {} when it has none."""
    for spec in mechanism.effects:
        if spec.kind == kind and spec.coordinate == coordinate and known_effect(spec):
            return {name: float(spec.values[name]) for name in registry.effects()[kind].item.coefficients}
    return {}


def library(mechanism: Mechanism, sample: Sample, n: int, pairs: Sequence[tuple[str, str]] | None = None,
            reduce: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[list[Candidate], list[str]]:
    """(candidates, notes): the candidates' columns at ``n`` samples (then ``reduce``d to the
    fit's rows, as measured data's parallel filter does), without the mechanism's own
    effects; an effect whose columns are not finite on this data (a plugin's bug) is left
    out with a note rather than stopping the diagnosis."""
    pairs = all_pairs(mechanism) if pairs is None else pairs
    still: dict[str, int] = {}
    # an effect fitted with the model has its columns in it; a known one (every value given,
    # subtracted) leaves the candidate of its kind free to correct its value
    present = {(e.kind, e.coordinate) for e in mechanism.effects if not known_effect(e)}
    out, notes = [], []
    motions: dict[str, CoordinateMotion] = {}          # each coordinate's, made once for all its effects
    for kind, coordinate in pairs:
        if (kind, coordinate) in present:
            continue
        shapes = shape_grid(mechanism, sample, n, kind, coordinate)
        if coordinate not in motions:
            motions[coordinate] = coordinate_motion(mechanism, sample, n, coordinate)
        if _still(motions[coordinate]):
            still[coordinate] = still.get(coordinate, 0) + 1
            continue
        variants = []
        for shape in shapes:
            names, columns = effect_columns(mechanism, sample, n, kind, coordinate, shape=shape,
                                            motion=motions[coordinate])
            columns = np.ascontiguousarray(columns, dtype=float)
            if not np.all(np.isfinite(columns)):
                break
            variants.append(_reduced(columns, reduce) if reduce is not None else columns)
        if len(variants) < len(shapes):
            notes.append(f"candidate {kind}:{coordinate} left out: its columns are not finite on this data")
            continue
        general = registry.effects()[kind].item.generalises
        if len(variants) == 1:
            out.append(Candidate(kind, coordinate, tuple(names), variants[0], shape=dict(shapes[0]),
                                 generalises=general))
        else:
            out.append(Candidate(kind, coordinate, tuple(names), variants[0], tuple(variants), tuple(shapes),
                                 dict(shapes[0]), general,
                                 _maker(mechanism, sample, n, kind, coordinate, reduce, motions[coordinate])))
    for coordinate, count in still.items():
        notes.append(f"{coordinate} does not move with the independent coordinates on this data (its speed per "
                     f"unit of theirs is at rounding, under {STILL:g}): a force there never reaches the measured "
                     f"ones; its {count} candidate{'s' if count != 1 else ''} left out")
    return out, notes


# A coordinate whose reach (its speed per unit of the independent coordinates' speeds, R; an
# independent coordinate's own is 1) stays under this over the data does not move with them:
# any effect's columns on it are rounding (the SLA's passive hub_b: 1e-15 to 1e-30), which
# selection scales to unit directions of rounding noise. They were named: viscous friction on
# hub_b, fv = 2.5e34 +- 8.9e33, the cross-validated gap 0.549 -> 1.259 (docs/diagnosis.md,
# "Issue 42's campaign faults").
STILL = 1e-9


def _still(motion: CoordinateMotion) -> bool:
    """Whether a coordinate's effects cannot reach the independent coordinates: the RMS over
    the samples of its reach's norm (``motion``'s R row, :func:`coordinate_motion`) under STILL."""
    reach = np.asarray(motion[3], dtype=float)
    if reach.size == 0:
        return False
    return bool(np.sqrt(np.mean(np.sum(reach.reshape(reach.shape[0], -1) ** 2, axis=1))) < STILL)


def shape_grid(mechanism: Mechanism, sample: Sample, n: int, kind: str, coordinate: str) -> list[dict]:
    """The shape parameters diagnosis tries for an effect on a coordinate: one empty dict for
    an effect without shapes; else each grid value (times the coordinate's RMS speed where
    the shape is a speed)."""
    effect = registry.effects()[kind].item
    if not effect.shapes:
        return [{}]
    speed = coordinate_speed_rms(mechanism, sample, n, coordinate)
    grids = []
    for shape in effect.shapes:
        scale = speed if shape.relative == "speed" and speed > 0 else 1.0
        grids.append([(shape.name, float(v) * scale) for v in (shape.grid or (shape.default,))])
    return [dict(combo) for combo in itertools.product(*grids)]


def _reduced(columns: np.ndarray, reduce: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``reduce`` applied to an effect's columns (N, f, c), contiguous (the filter skips the
    coordinates they do not act on: :func:`~baseparams.recordings.data.zero_phase`)."""
    return np.ascontiguousarray(reduce(columns))


def _maker(mechanism: Mechanism, sample: Sample, n: int, kind: str, coordinate: str,
           reduce: Callable[[np.ndarray], np.ndarray] | None, motion: CoordinateMotion) -> Callable[[dict], np.ndarray]:
    """The columns of a shaped effect at any shape value (reduced like the data), each value's
    made once: the search between grid points meets the same values again at later steps
    (selection.SHAPE_STEP), and each making filters the full-rate columns. ``motion``: the
    coordinate's (:func:`~baseparams.dynamics.forces.coordinate_motion`)."""
    made: dict[tuple, np.ndarray] = {}

    def make(shape: dict) -> np.ndarray:
        key = tuple(sorted(shape.items()))
        if key not in made:
            columns = np.ascontiguousarray(effect_columns(mechanism, sample, n, kind, coordinate, shape=shape,
                                                          motion=motion)[1], dtype=float)
            made[key] = _reduced(columns, reduce) if reduce is not None else columns
        return made[key]
    return make
