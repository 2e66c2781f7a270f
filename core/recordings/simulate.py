"""Synthetic measured data with a known truth: the proof bench of identification and diagnosis.

Along the mechanism's default exciting trajectory (its exact derivatives), the generalized
forces are ``tau = K phi + sum_e C_e theta_e + noise``: K and C_e from
:mod:`baseparams.dynamics.forces` (the same model the fit uses), phi the file's inertial
parameters or random physically consistent ones, the effects' coefficients as given, and
independent Gaussian noise of a given SD on each coordinate's tau. The truth is returned
separately and never written into the data.
"""

from collections.abc import Sequence

import numpy as np
import sympy
from scipy.spatial.transform import Rotation

from baseparams import registry
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError
from baseparams.recordings.data import MeasuredData
from baseparams.dynamics.forces import (Motion, design, effect_values, evaluate, independent_names,
                                       standard_parameters)
from baseparams.model.consistency import require_physical
from baseparams.model.mechanism import EffectSpec, Mechanism
from baseparams.model.params import from_mass_properties
from baseparams.numeric.backends import Float64

# Random bodies: mass uniform in MASS_RANGE (kg); the mass's second moments along random
# principal axes are m (u L)^2 with u uniform in SPREAD_RANGE and L the body's size (the
# farthest joint point on it); the centre of mass uniform in the ball of radius L/2.
MASS_RANGE = (0.5, 5.0)
SPREAD_RANGE = (0.05, 0.6)
SMALLEST_SIZE = 0.05


def trajectory_motion(mechanism: Mechanism, samples: int | None = None) -> Motion:
    """The default exciting trajectory's samples with its exact derivatives, float64."""
    trajectory = Trajectory.default(mechanism, samples=samples)
    t = np.array([float(x) for x in trajectory.times])
    z, zd, zdd = trajectory.independent_values(mechanism, Float64(), t)
    q, qd, qdd = (np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in values], axis=1)
                  for values in (z, zd, zdd))
    return Motion(t, q, qd, qdd)


def body_sizes(mechanism: Mechanism) -> dict[int, float]:
    """Each moving body's size: the distance of its farthest joint point from its origin."""
    geometry = {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator)
                for k, v in mechanism.geometry.items()}
    sizes = {b.label: SMALLEST_SIZE for b in mechanism.bodies}
    for joint in mechanism.joints:
        for body, frame in ((joint.parent, joint.parent_frame), (joint.child, joint.child_frame)):
            if body in sizes:
                point = [float(sympy.sympify(c).subs(geometry)) for c in frame.point]
                sizes[body] = max(sizes[body], float(np.linalg.norm(point)))
    return sizes


def random_physical_inertia(mechanism: Mechanism, rng: np.random.Generator) -> np.ndarray:
    """Random physically consistent standard parameters, body after body: mass > 0, and the
    inertia tensor at the centre of mass positive definite with strict triangle inequalities
    (principal moments d2+d3, d1+d3, d1+d2 of positive second moments d1, d2, d3 of the mass)."""
    sizes = body_sizes(mechanism)
    out = []
    for body in mechanism.bodies:
        size = sizes[body.label]
        mass = rng.uniform(*MASS_RANGE)
        direction = rng.standard_normal(3)
        com = direction / np.linalg.norm(direction) * size / 2 * rng.uniform() ** (1 / 3)
        d = mass * (rng.uniform(*SPREAD_RANGE, size=3) * size) ** 2
        rotation = Rotation.random(random_state=rng).as_matrix()
        tensor = rotation @ np.diag([d[1] + d[2], d[0] + d[2], d[0] + d[1]]) @ rotation.T
        entries = [tensor[0, 0], tensor[0, 1], tensor[0, 2], tensor[1, 1], tensor[1, 2], tensor[2, 2]]
        out.extend(from_mass_properties(mass, com, entries))
    return np.array(out, dtype=float)


def _noise_vector(noise_sd: float | Sequence[float], coordinates: tuple[str, ...]) -> np.ndarray:
    sd = np.broadcast_to(np.asarray(noise_sd, dtype=float), (len(coordinates),)) if np.ndim(noise_sd) == 0 \
        else np.asarray(noise_sd, dtype=float)
    if sd.shape != (len(coordinates),):
        raise InputError(f"{len(sd)} noise SDs for {len(coordinates)} coordinates "
                         f"({', '.join(coordinates)})", key="noise")
    if not np.all(np.isfinite(sd)) or np.any(sd < 0):
        raise InputError(f"noise SDs must be finite and >= 0, not {list(sd)}", key="noise")
    return np.array(sd)


def simulate(mechanism: Mechanism, *, samples: int | None = None, noise_sd: float | Sequence[float] = 0.0,
             seed: int = 0, effects: Sequence[EffectSpec] = (), random_inertia: bool = False
             ) -> tuple[MeasuredData, dict]:
    """(data, truth): measured data along the default trajectory and what produced it.

    ``noise_sd``: one SD for every coordinate's tau or one per independent coordinate;
    ``effects``: hidden effects, each with all its coefficients in ``values``. The truth:
    {"mechanism", "parameters": {name: value}, "effects": [{"kind", "coordinate", "values"}],
    "noise_sd": [...], "seed", "samples", "random_inertia", "rms_tau": {coordinate: RMS of
    the noise-free tau}, "rms_effect": [{coordinate: RMS of that effect's force}]}.
    """
    rng = np.random.default_rng(seed)
    coordinates = independent_names(mechanism)
    sd = _noise_vector(noise_sd, coordinates)
    motion = trajectory_motion(mechanism, samples)
    sample = evaluate(mechanism, motion)
    if not random_inertia:
        require_physical(mechanism, "simulate (the file's inertias make the torques)")
    phi = random_physical_inertia(mechanism, rng) if random_inertia else standard_parameters(mechanism)
    effects = list(effects)
    inertial, columns = design(mechanism, motion, effects, sample)
    theta = effect_values(mechanism, effects)
    clean = inertial.matrix @ phi
    rms_effect, start = [], 0
    for spec in effects:
        width = len(registry.effects()[spec.kind].item.coefficients)
        force = columns.matrix[:, :, start:start + width] @ theta[start:start + width]
        rms_effect.append(dict(zip(coordinates, _rms(force).tolist())))
        clean = clean + force
        start += width
    tau = clean + rng.standard_normal(clean.shape) * sd
    data = MeasuredData(motion, tau, coordinates, None, (), (), sample)
    truth = {
        "mechanism": mechanism.name,
        "parameters": dict(zip(mechanism.parameters, phi.tolist())),
        "effects": [{"kind": spec.kind, "coordinate": spec.coordinate,
                     "values": {name: float(spec.values[name])
                                for name in registry.effects()[spec.kind].item.coefficients}}
                    for spec in effects],
        "noise_sd": sd.tolist(),
        "seed": seed,
        "samples": motion.count,
        "random_inertia": random_inertia,
        "rms_tau": dict(zip(coordinates, _rms(clean).tolist())),
        "rms_effect": rms_effect,
    }
    return data, truth


def _rms(values: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.asarray(values) ** 2, axis=0))


# The model errors common to both sides of :func:`simulate_change`: Coulomb friction of a
# smooth law (tanh, transition at this fraction of the coordinate's RMS speed) and viscous
# friction, each this fraction of the coordinate's largest torque, and a delay in samples.
COMMON_COULOMB, COMMON_VISCOUS, COMMON_TRANSITION, COMMON_DELAY = 0.05, 0.02, 0.1, 2
NOISE_KINDS = ("white", "ar1", "lowpass")


def coloured_noise(rng: np.random.Generator, shape: tuple[int, int], kind: str) -> np.ndarray:
    """Unit-SD noise (n, f): white, AR(1) at 0.9, or white noise through a 4th-order
    Butterworth low-pass at 5 % of the Nyquist frequency (a drive's or a logger's filter)."""
    from scipy.signal import butter, lfilter
    if kind not in NOISE_KINDS:
        raise InputError(f"noise kind {kind!r} is not one of {', '.join(NOISE_KINDS)}", key="noise")
    burn = 1000
    e = rng.standard_normal((shape[0] + burn, shape[1]))
    if kind == "ar1":
        e = lfilter([1.0], [1.0, -0.9], e, axis=0)
    elif kind == "lowpass":
        b, a = butter(4, 0.05)
        e = lfilter(b, a, e, axis=0)
    e = e[burn:]
    return e / np.std(e, axis=0)


def simulate_change(mechanism: Mechanism, *, samples: int | None = None, seed: int = 0, noise: str = "ar1",
                    noise_level: float = 0.01, payload: float = 0.0, friction_drift: float = 0.0,
                    drift_coordinate: int = 0, common_errors: bool = True, random_inertia: bool = False,
                    payload_mass: float | None = None, load_friction: float = 0.0, quantum: float = 0.0,
                    payload_body: int | None = None, payload_at: Sequence[float] = (0.0, 0.0, 0.0)
                    ) -> tuple[MeasuredData, MeasuredData, dict]:
    """(baseline, changed, truth): two recordings of the default trajectory, the second after
    a change, for the proof of ``diagnose --baseline``. ``payload``: a rigid point load of this
    fraction of the last body's mass, at a random point within 5 cm of its frame's origin;
    ``friction_drift``: viscous friction added on coordinate ``drift_coordinate``, its force
    at the largest speed this fraction of that coordinate's largest torque. Both sides share
    the model errors a real robot's model has (``common_errors``: a smooth Coulomb law,
    viscous friction, a delay; none of them in the mechanism), and carry independent noise
    of one ``noise`` kind (:func:`coloured_noise`) at ``noise_level`` times each coordinate's
    RMS torque. ``payload_mass``: the payload in kg instead (a last body of no mass, a tool
    frame, has none to scale). ``load_friction``: gear friction mu |tau| sign(qd) on every
    coordinate, common to both runs, so a payload's torque changes it too (as on a real
    gearbox). ``quantum``: torques rounded to this step (N m), as a drive reports them.
    ``payload_body``: the index (0-based, file order) of the body that carries the payload
    instead of the last (a parallelogram's link, issue 49); ``payload_at``: the centre of the
    payload's 5 cm ball in that body's axes (its frame's origin by default; a link's middle,
    where the origin is on a fixed pivot and a load there moves nothing)."""
    rng = np.random.default_rng(seed)
    coordinates = independent_names(mechanism)
    motion = trajectory_motion(mechanism, samples)
    sample = evaluate(mechanism, motion)
    phi = random_physical_inertia(mechanism, rng) if random_inertia else standard_parameters(mechanism)
    inertial, _ = design(mechanism, motion, [], sample)
    K = inertial.matrix
    clean = K @ phi
    peak = np.max(np.abs(clean), axis=0)
    qd = motion.qd
    speed = np.sqrt(np.mean(qd ** 2, axis=0))
    speed = np.where(speed > 0, speed, 1.0)
    common = np.zeros_like(clean)
    if common_errors:
        common = COMMON_COULOMB * peak * np.tanh(qd / (COMMON_TRANSITION * speed)) + \
            COMMON_VISCOUS * peak * qd / np.max(np.abs(qd), axis=0, initial=1e-300)

    def late(x: np.ndarray) -> np.ndarray:
        k = COMMON_DELAY if common_errors else 0
        return np.concatenate([np.repeat(x[:1], k, axis=0), x[:len(x) - k]]) if k else x

    change = np.zeros_like(phi)
    last = len(mechanism.bodies) - 1 if payload_body is None else payload_body
    mass = payload * phi[10 * last] if payload_mass is None else payload_mass
    direction = rng.standard_normal(3)
    centre = np.asarray(payload_at, dtype=float) + direction / np.linalg.norm(direction) * 0.05 * rng.uniform() ** (1 / 3)
    if mass:
        x, y, z = centre
        change[10 * last:10 * last + 10] = mass * np.array([1.0, x, y, z, y * y + z * z, -x * y, -x * z,
                                                            x * x + z * z, -y * z, x * x + y * y])
    drift = np.zeros_like(clean)
    fv = 0.0
    if friction_drift:
        j = drift_coordinate
        fv = friction_drift * peak[j] / max(float(np.max(np.abs(qd[:, j]))), 1e-300)
        drift[:, j] = fv * qd[:, j]
    sd = noise_level * np.sqrt(np.mean(clean ** 2, axis=0))

    def gear(rigid: np.ndarray) -> np.ndarray:
        return load_friction * np.abs(rigid) * np.tanh(qd / (COMMON_TRANSITION * speed))

    def reported(x: np.ndarray) -> np.ndarray:
        return np.round(x / quantum) * quantum if quantum > 0 else x

    loaded = clean + K @ change
    before = reported(late(clean + common + gear(clean)) + coloured_noise(rng, clean.shape, noise) * sd)
    after = reported(late(loaded + common + gear(loaded) + drift) + coloured_noise(rng, clean.shape, noise) * sd)
    truth = {"payload": {"body": last, "mass": mass, "centre": centre.tolist()} if mass else None,
             "friction_drift": {"coordinate": coordinates[drift_coordinate], "fv": fv} if friction_drift else None,
             "noise": noise, "noise_sd": sd.tolist(), "delay": COMMON_DELAY * float(np.median(np.diff(motion.t)))
             if common_errors else 0.0, "seed": seed}
    return (MeasuredData(motion, before, coordinates, None, (), (), sample),
            MeasuredData(motion, after, coordinates, None, (), (), sample), truth)
