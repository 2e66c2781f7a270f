"""Built-in model effects with their canonical names (docs/design.md), registered by hook."""

import numpy as np

from baseparams.dynamics.effects import Effect, EffectKind, FloatArray, Shape
from baseparams.hookspecs import hookimpl

# Transition speeds diagnosis tries, as multiples of the coordinate's RMS speed (0: sign).
COULOMB_GRID = (0.0, 0.003, 0.01, 0.03, 0.1, 0.3)
STRIBECK_GRID = (0.01, 0.03, 0.1, 0.3)


def _coulomb(q: FloatArray, qd: FloatArray, qdd: FloatArray, vs: float = 0.0) -> list[FloatArray]:
    """sign(qd), or tanh(qd / vs) with a transition speed vs > 0 (a smooth Coulomb law)."""
    return [np.tanh(qd / vs) if vs > 0 else np.sign(qd)]


def _stribeck(q: FloatArray, qd: FloatArray, qdd: FloatArray, vs: float = 0.01) -> list[FloatArray]:
    """Stribeck bump sign(qd) exp(-(qd/vs)^2): linear in its coefficient at a given vs."""
    return [np.sign(qd) * np.exp(-(qd / vs) ** 2)]


EFFECTS = [
    Effect("viscous_friction", "tau = fv * qd", ("fv",), lambda q, qd, qdd: [qd]),
    Effect("coulomb_friction", "tau = fc * sign(qd), or fc * tanh(qd / vs) with a transition speed vs "
           "(given, or fitted by diagnose; 0 or absent: sign)", ("fc",), _coulomb,
           (Shape("vs", 0.0, COULOMB_GRID, "speed"),)),
    Effect("stribeck_friction", "tau = fs * sign(qd) * exp(-(qd/vs)^2), vs given (default 0.01) or fitted "
           "by diagnose", ("fs",), _stribeck, (Shape("vs", 0.01, STRIBECK_GRID, "speed"),)),
    Effect("offset", "tau = off (a constant: sensor or actuator offset)", ("off",),
           lambda q, qd, qdd: [np.ones_like(q)]),
    Effect("spring", "tau = k * (q - q0): linear stiffness about a rest position; columns q and -1 "
           "with coefficients k and k*q0", ("k", "kq0"), lambda q, qd, qdd: [q, -np.ones_like(q)]),
    Effect("rotor_inertia", "tau = Ia * qdd (actuator rotor inertia reflected to the joint)", ("Ia",),
           lambda q, qd, qdd: [qdd]),
    Effect("position_friction", "tau = sign(qd) * (fcc cos q + fcs sin q): Coulomb friction that varies "
           "with position (a bearing's eccentricity, a seal)", ("fcc", "fcs"),
           lambda q, qd, qdd: [np.sign(qd) * np.cos(q), np.sign(qd) * np.sin(q)],
           generalises=("coulomb_friction",), angular=True),
    Effect("cogging", "tau = c1 sin q + d1 cos q + c2 sin 2q + d2 cos 2q: a position-periodic torque "
           "(cogging, an unbalanced gear) in its two lowest harmonics", ("c1", "d1", "c2", "d2"),
           lambda q, qd, qdd: [np.sin(q), np.cos(q), np.sin(2 * q), np.cos(2 * q)],
           generalises=("offset", "spring", "mass", "payload", "body"),    # gravity of a mass: harmonics of q
           angular=True),
]


@hookimpl
def baseparams_effects() -> list[EffectKind]:
    return list(EFFECTS)
