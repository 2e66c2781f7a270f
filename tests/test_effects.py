"""Model effects: their columns reproduce the force law they document."""

import numpy as np
import pytest

from baseparams import registry

CANONICAL = {"viscous_friction", "coulomb_friction", "stribeck_friction", "offset", "spring", "rotor_inertia"}


def test_canonical_effects_are_registered():
    assert CANONICAL <= set(registry.effects())


@pytest.mark.parametrize("name,coefficients,law", [
    ("viscous_friction", [0.7], lambda q, qd, qdd: 0.7 * qd),
    ("coulomb_friction", [1.3], lambda q, qd, qdd: 1.3 * np.sign(qd)),
    ("offset", [-0.4], lambda q, qd, qdd: -0.4 + 0 * q),
    ("spring", [250.0, 250.0 * 0.12], lambda q, qd, qdd: 250.0 * (q - 0.12)),
    ("rotor_inertia", [0.02], lambda q, qd, qdd: 0.02 * qdd),
    ("stribeck_friction", [0.5], lambda q, qd, qdd: 0.5 * np.sign(qd) * np.exp(-(qd / 0.01) ** 2)),
])
def test_columns_times_coefficients_give_the_force_law(name, coefficients, law):
    effect = registry.effects()[name].item
    rng = np.random.default_rng(1)
    q, qd, qdd = rng.normal(size=(3, 50)) * [[1], [0.02], [5]]
    cols = effect.columns(q, qd, qdd)
    assert len(cols) == len(coefficients) == len(effect.coefficient_names("x"))
    assert np.allclose(sum(c * k for c, k in zip(cols, coefficients)), law(q, qd, qdd))
