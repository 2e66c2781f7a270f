"""Built-in model effects with their canonical names (docs/design.md), registered by hook."""

import numpy as np

from baseparams.dynamics.effects import Effect
from baseparams.hookspecs import hookimpl


def _stribeck(q, qd, qdd, velocity=0.01):
    """Stribeck bump with a fixed characteristic velocity: linear in its coefficient."""
    return [np.sign(qd) * np.exp(-(qd / velocity) ** 2)]


EFFECTS = [
    Effect("viscous_friction", "tau = fv * qd", ("fv",), lambda q, qd, qdd: [qd]),
    Effect("coulomb_friction", "tau = fc * sign(qd)", ("fc",), lambda q, qd, qdd: [np.sign(qd)]),
    Effect("stribeck_friction", "tau = fs * sign(qd) * exp(-(qd/vs)^2), vs fixed (default 0.01)",
           ("fs",), _stribeck),
    Effect("offset", "tau = off (a constant: sensor or actuator offset)", ("off",),
           lambda q, qd, qdd: [np.ones_like(q)]),
    Effect("spring", "tau = k * (q - q0): linear stiffness about a rest position; columns q and -1 "
           "with coefficients k and k*q0", ("k", "kq0"), lambda q, qd, qdd: [q, -np.ones_like(q)]),
    Effect("rotor_inertia", "tau = Ia * qdd (actuator rotor inertia reflected to the joint)", ("Ia",),
           lambda q, qd, qdd: [qdd]),
]


@hookimpl
def baseparams_effects():
    return list(EFFECTS)
