"""Model effects: their columns obey the physics their names promise.

The checks are properties, not the formulas restated: friction dissipates power, Coulomb
friction does not depend on speed, the Stribeck bump vanishes at speed, a spring's force
vanishes at its rest position and grows with slope k, conservative effects do no net work
over a period.
"""

import numpy as np
import pytest

from baseparams import registry

CANONICAL = {"viscous_friction", "coulomb_friction", "stribeck_friction", "offset", "spring", "rotor_inertia"}


def force(name, coefficients, q, qd, qdd):
    effect = registry.effects()[name].item
    cols = effect.columns(q, qd, qdd)
    assert len(cols) == len(coefficients) == len(effect.coefficient_names("x"))
    return sum(c * k for c, k in zip(cols, coefficients))


@pytest.fixture
def states():
    rng = np.random.default_rng(1)
    return rng.normal(size=500), rng.normal(size=500) * 0.3, rng.normal(size=500) * 5


def test_canonical_effects_are_registered():
    assert CANONICAL <= set(registry.effects())


@pytest.mark.parametrize("name", ["viscous_friction", "coulomb_friction", "stribeck_friction"])
def test_friction_dissipates(name, states):
    q, qd, qdd = states
    power = force(name, [0.8], q, qd, qdd) * qd
    assert np.all(power >= 0) and np.any(power > 0)


def test_viscous_friction_is_proportional_to_speed(states):
    q, qd, qdd = states
    assert np.allclose(force("viscous_friction", [0.8], q, 2 * qd, qdd), 2 * force("viscous_friction", [0.8], q, qd, qdd))


def test_coulomb_friction_does_not_depend_on_speed(states):
    q, qd, qdd = states
    f = force("coulomb_friction", [1.3], q, qd, qdd)
    assert np.allclose(np.abs(f), 1.3)
    assert np.allclose(force("coulomb_friction", [1.3], q, 10 * qd, qdd), f)


def test_stribeck_bump_is_full_at_rest_and_gone_at_speed():
    f = lambda qd: force("stribeck_friction", [0.5], 0.0, qd, 0.0)  # noqa: E731
    assert f(1e-6) == pytest.approx(0.5, rel=1e-6) and f(-1e-6) == pytest.approx(-0.5, rel=1e-6)
    assert abs(f(0.1)) < 1e-40                     # ten characteristic velocities (0.01)


def test_spring_force_vanishes_at_rest_and_grows_with_stiffness():
    k, rest = 250.0, 0.12
    f = lambda q: force("spring", [k, k * rest], q, 0.0, 0.0)  # noqa: E731
    assert f(rest) == pytest.approx(0.0, abs=1e-12)
    assert (f(rest + 1e-3) - f(rest - 1e-3)) / 2e-3 == pytest.approx(k)


def test_offset_is_a_constant(states):
    q, qd, qdd = states
    assert np.allclose(force("offset", [-0.4], q, qd, qdd), -0.4)


@pytest.mark.parametrize("name,coefficients", [("spring", [250.0, 30.0]), ("rotor_inertia", [0.02])])
def test_conservative_effects_do_no_net_work_over_a_period(name, coefficients):
    t = np.linspace(0, 2 * np.pi, 20001)
    q, qd, qdd = 0.3 * np.sin(t), 0.3 * np.cos(t), -0.3 * np.sin(t)
    integrate = getattr(np, "trapezoid", None) or np.trapz      # numpy >= 2 renamed it
    work = integrate(force(name, coefficients, q, qd, qdd) * qd, t)
    dissipated = integrate(force("viscous_friction", [0.8], q, qd, qdd) * qd, t)
    assert abs(work) < 1e-6 * dissipated
