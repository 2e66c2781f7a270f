"""The identification model: the generalized forces on the independent coordinates, linear
in the inertial parameters and in the effects' coefficients,

    tau(t) = K(q, qd, qdd) phi + sum over effects e of C_e(q, qd, qdd) theta_e,

with K the regressor (closed loops: R^T K_tree) and C_e an effect's columns on its joint
coordinate mapped to the independent coordinates by R^T (a spring on a suspension strut's
sliding coordinate acts on the wheel's travel through the loop). Simulation, identification
and diagnosis all build their matrices here, so they cannot disagree on the model.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from baseparams import registry
from baseparams.dynamics.effects import EffectKind
from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.dynamics.trajectory import check_limits
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import EffectSpec, Mechanism
from baseparams.numeric.backends import Float64


@dataclass(frozen=True)
class Motion:
    """Independent coordinates over time, float64: ``t`` (N,), ``q``, ``qd``, ``qdd`` (N, f),
    columns in ``mechanism.independent`` order (all tree coordinates for an open chain)."""
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    @property
    def count(self) -> int:
        return len(self.t)

    def take(self, rows: np.ndarray | slice) -> "Motion":
        """The samples ``rows`` (a training part, a holdout block)."""
        return Motion(self.t[rows], self.q[rows], self.qd[rows], self.qdd[rows])


def independent_names(mechanism: Mechanism) -> tuple[str, ...]:
    """The coordinates measured data gives: the independent ones (all, for an open chain)."""
    return tuple(mechanism.independent or mechanism.coordinates)


def evaluate(mechanism: Mechanism, motion: Motion, where: str = "") -> Sample:
    """Every sample at once in float64, loops closed: first each sample by continuation from
    the reference configuration, and if that fails, sample after sample in time (each Newton
    from the previous solution), which names the first sample that cannot close."""
    ev = Evaluator(mechanism, Float64())
    z, zd, zdd = ([np.ascontiguousarray(a[:, j]) for j in range(a.shape[1])]
                  for a in (motion.q, motion.qd, motion.qdd))
    try:
        sample = ev.sample(z, zd, zdd, None, where=where)
    except KinematicsError:
        if not mechanism.loops:
            raise
        guess, q = [], None
        for k in range(motion.count):
            q = ev.assemble([float(v[k]) for v in z], q, where=f"{where}at t = {motion.t[k]:.6g} s: ")
            guess.append([float(v) for v in q])
        sample = ev.sample(z, zd, zdd, [np.array(c) for c in zip(*guess)], where=where)
    check_limits(mechanism, sample.q, motion.t)
    return sample


def _as_batch(value: object, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (n,))


def inertial_columns(sample: Sample, n: int) -> np.ndarray:
    """K: (N, f, 10 * bodies), the columns of the standard inertial parameters."""
    k = sample.regressor_array()
    return np.broadcast_to(k, (n,) + k.shape[-2:]) if k.ndim == 2 else k


def checked_effect(mechanism: Mechanism, kind: str, coordinate: str, key: str = "effect") -> EffectKind:
    """The registered effect ``kind``, once ``coordinate`` is known to be a tree coordinate
    or a motor of ``mechanism`` (InputError naming ``key`` otherwise)."""
    effects = registry.effects()
    if kind not in effects:
        raise InputError(f"unknown effect {kind!r}; registered: {', '.join(sorted(effects))}", key=key)
    if coordinate not in mechanism.coordinates and coordinate not in mechanism.motor_names:
        motors = f"; motors: {', '.join(mechanism.motor_names)}" if mechanism.motors else ""
        raise InputError(f"{coordinate!r} is not a joint coordinate or a motor of {mechanism.name} "
                         f"(coordinates: {', '.join(mechanism.coordinates)}{motors})", key=key)
    return effects[kind].item


def drive_rows(mechanism: Mechanism, names: Sequence[str]) -> np.ndarray:
    """(len(names), tree coordinates): each name's position as a linear map of the tree
    coordinates: a unit row for a joint coordinate, the gear ratios for a motor."""
    out = np.zeros((len(names), len(mechanism.coordinates)))
    for k, name in enumerate(names):
        if name in mechanism.coordinates:
            out[k, mechanism.coordinates.index(name)] = 1.0
        else:
            for coordinate, ratio in mechanism.motor(name).ratios:
                out[k, mechanism.coordinates.index(coordinate)] += float(ratio)
    return out


def effect_columns(mechanism: Mechanism, sample: Sample, n: int, kind: str, coordinate: str,
                   key: str = "effect", shape: dict | None = None,
                   motion: "CoordinateMotion | None" = None) -> tuple[list[str], np.ndarray]:
    """An effect's coefficient names and columns (N, f, c) on the independent coordinates,
    at the ``shape`` parameters given (name -> value; the effect's defaults otherwise);
    ``motion``: the coordinate's, when already made (:func:`coordinate_motion`).

    On a motor the effect sees the motor's position, velocity and acceleration (the gear
    ratios times the joints'), and its force reaches each joint coordinate times that
    joint's ratio (power balance), then the independent coordinates by R^T."""
    effect = checked_effect(mechanism, kind, coordinate, key)
    q, qd, qdd, reach = coordinate_motion(mechanism, sample, n, coordinate) if motion is None else motion
    with np.errstate(all="ignore"):
        columns = effect.columns(q, qd, qdd, **(shape or {}))
    out = np.stack([reach * c[:, None] for c in columns], axis=-1)               # (N, f, c)
    return effect.coefficient_names(coordinate), out


# A coordinate's (or motor's) position, velocity, acceleration (N,) and the factor (N, f) by which a
# force on it reaches each independent coordinate.
CoordinateMotion = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def coordinate_motion(mechanism: Mechanism, sample: Sample, n: int, coordinate: str) -> CoordinateMotion:
    """What every effect on ``coordinate`` is built from (:func:`effect_columns`), made once
    for the many shapes of one effect."""
    row = drive_rows(mechanism, [coordinate])[0]
    used = np.nonzero(row)[0]

    def combined(values: Sequence[object]) -> np.ndarray:
        return np.sum([row[i] * _as_batch(values[int(i)], n) for i in used], axis=0)

    q, qd, qdd = (combined(values) for values in (sample.q, sample.qd, sample.qdd))
    reach = sum(row[i] * np.stack([_as_batch(v, n) for v in sample.projection[i]], axis=-1) for i in used)
    return q, qd, qdd, reach


def coordinate_speed_rms(mechanism: Mechanism, sample: Sample, n: int, coordinate: str) -> float:
    """RMS speed of a joint coordinate or a motor over the samples (the scale of friction
    shapes: a transition speed is a fraction of it)."""
    row = drive_rows(mechanism, [coordinate])[0]
    qd = np.sum([row[i] * _as_batch(sample.qd[int(i)], n) for i in np.nonzero(row)[0]], axis=0)
    return float(np.sqrt(np.mean(np.square(qd))))


@dataclass(frozen=True)
class Design:
    """The model's columns at some samples: names and the matrix (N, f, p)."""
    names: tuple[str, ...]
    matrix: np.ndarray

    def stacked(self) -> np.ndarray:
        """(N * f, p), sample-major (the f coordinates of sample 1, then of sample 2 ...)."""
        n, f, p = self.matrix.shape
        return self.matrix.reshape(n * f, p)


def design(mechanism: Mechanism, motion: Motion, effects: Sequence[EffectSpec] = (),
           sample: Sample | None = None) -> tuple[Design, Design]:
    """(inertial, effects): the standard-parameter columns K and the named effects' columns."""
    sample = sample if sample is not None else evaluate(mechanism, motion)
    return Design(tuple(mechanism.parameters), inertial_columns(sample, motion.count)), \
        effects_design(mechanism, sample, motion.count, effects)


def effects_design(mechanism: Mechanism, sample: Sample, n: int, effects: Sequence[EffectSpec]) -> Design:
    """The named effects' columns (n, f, c) at the ``sample``'s n rows."""
    names, blocks = [], []
    for spec in effects:
        shape = registry.effects()[spec.kind].item.shape_values(spec.values)
        cnames, block = effect_columns(mechanism, sample, n, spec.kind, spec.coordinate, shape=shape)
        names.extend(cnames)
        blocks.append(block)
    matrix = np.concatenate(blocks, axis=-1) if blocks else np.zeros((n, len(independent_names(mechanism)), 0))
    return Design(tuple(names), matrix)


def standard_parameters(mechanism: Mechanism) -> np.ndarray:
    """The file's inertial parameters (every body must give them) as float64, in order."""
    missing = [b.label for b in mechanism.bodies if b.inertia is None]
    if missing:
        raise InputError(f"bodies {missing} have no inertia: give mass, com and inertia_com (or "
                         "inertia), or use random physically consistent ones", file=mechanism.path,
                         key="bodies")
    return np.array([float(v) for b in mechanism.bodies for v in b.inertia or ()])


def effect_values(mechanism: Mechanism, effects: Sequence[EffectSpec]) -> np.ndarray:
    """The known coefficients of ``effects`` in column order (every one must be given)."""
    out = []
    for spec in effects:
        coefficients = registry.effects()[spec.kind].item.coefficients
        for name in coefficients:
            if name not in spec.values:
                raise InputError(f"{spec.kind} on {spec.coordinate}: no value for {name}",
                                 file=mechanism.path, key="effects")
            out.append(float(spec.values[name]))
    return np.array(out)
