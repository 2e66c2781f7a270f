"""Synthetic measured data (baseparams.recordings.simulate), checked against physics computed
another way: the power balance (generalized forces times velocities = the time derivative
of the energy, from the energy forms rather than the regressor), the pendulum's closed
form, the virtual power of an effect on a dependent coordinate, and the noise statistics."""

import numpy as np
import pytest
from scipy import stats

from baseparams.errors import InputError
from baseparams.dynamics.forces import evaluate
from baseparams.identify.physical import pseudo_inertia
from baseparams.recordings.simulate import random_physical_inertia, simulate
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec


def _energy(mech, data, phi):
    t_form, v_form = evaluate(mech, data.motion).energies()
    n = data.count
    T = sum(np.broadcast_to(np.asarray(c, float), (n,)) * p for c, p in zip(t_form, phi))
    V = sum(np.broadcast_to(np.asarray(c, float), (n,)) * p for c, p in zip(v_form, phi))
    return T + V


@pytest.mark.parametrize("make", [lambda: parse_mechanism(generate.serial_chain(4, bodies=3)),
                                  lambda: parse_mechanism(generate.four_bar(3)),
                                  lambda: resolve("slider_crank")], ids=["chain", "four_bar", "slider_crank"])
def test_forces_balance_the_energy(make):
    """sum_j tau_j zd_j = dE/dt (no effects, no noise; loops: constraint forces do no work)."""
    mech = make()
    data, truth = simulate(mech, samples=4001, random_inertia=True, seed=5)
    phi = np.array([truth["parameters"][p] for p in mech.parameters])
    energy = _energy(mech, data, phi)
    power = np.sum(data.tau * data.motion.qd, axis=1)
    derivative = np.gradient(energy, data.motion.t, edge_order=2)
    scale = np.abs(power).max()
    assert np.abs(derivative - power)[2:-2].max() < 1e-4 * scale


def test_pendulum_closed_form():
    mech = resolve("pendulum")             # uniform rod, m 1.2 kg, L 0.5 m, hanging at theta = 0
    data, truth = simulate(mech, samples=50)
    theta, acc = data.motion.q[:, 0], data.motion.qdd[:, 0]
    m, L, g = 1.2, 0.5, 9.81
    expected = m * L ** 2 / 3 * acc + m * g * L / 2 * np.sin(theta)
    np.testing.assert_allclose(data.tau[:, 0], expected, atol=1e-12 * np.abs(expected).max())
    assert truth["noise_sd"] == [0.0] and truth["effects"] == []


def test_effect_on_a_dependent_coordinate_does_virtual_work():
    """A strut spring and damper on the SLA: their forces on the independent coordinates,
    times the independent velocities, equal the strut force times the strut's velocity."""
    mech = resolve("sla_suspension")
    effects = [EffectSpec("spring", "damper_s", {"k": 2000, "kq0": 10}),
               EffectSpec("viscous_friction", "damper_s", {"fv": 300})]
    plain, _ = simulate(mech, samples=80)
    hidden, truth = simulate(mech, samples=80, effects=effects)
    i = mech.coordinates.index("damper_s")
    s = np.asarray(hidden.sample.q[i], float)
    sd = np.asarray(hidden.sample.qd[i], float)
    strut_force = 2000 * s - 10 + 300 * sd
    virtual_power = np.sum((hidden.tau - plain.tau) * hidden.motion.qd, axis=1)
    np.testing.assert_allclose(virtual_power, strut_force * sd, atol=1e-9 * np.abs(strut_force * sd).max())
    assert [e["values"] for e in truth["effects"]] == [{"k": 2000.0, "kq0": 10.0}, {"fv": 300.0}]
    spring_only, _ = simulate(mech, samples=80, effects=effects[:1])
    rms = np.sqrt(np.mean((spring_only.tau - plain.tau) ** 2, axis=0))
    np.testing.assert_allclose(list(truth["rms_effect"][0].values()), rms, rtol=1e-9)


def test_noise_is_gaussian_with_the_given_sd_and_seeded():
    mech = resolve("planar_2r")
    clean, _ = simulate(mech, samples=3000)
    noisy, truth = simulate(mech, samples=3000, noise_sd=[0.2, 0.05], seed=11)
    again, _ = simulate(mech, samples=3000, noise_sd=[0.2, 0.05], seed=11)
    np.testing.assert_array_equal(noisy.tau, again.tau)
    noise = noisy.tau - clean.tau
    np.testing.assert_allclose(noise.std(axis=0), [0.2, 0.05], rtol=0.06)
    for j in range(2):
        assert stats.normaltest(noise[:, j]).pvalue > 1e-4
    assert truth["noise_sd"] == [0.2, 0.05] and truth["seed"] == 11
    with pytest.raises(InputError, match="noise"):
        simulate(mech, noise_sd=[0.1, 0.2, 0.3])
    with pytest.raises(InputError, match="noise"):
        simulate(mech, noise_sd=-1)


@pytest.mark.parametrize("seed", range(4))
def test_random_inertia_is_physically_consistent(seed):
    mech = parse_mechanism(generate.tree(seed, bodies=4))
    phi = random_physical_inertia(mech, np.random.default_rng(seed))
    for b in range(len(mech.bodies)):
        body = phi[10 * b: 10 * b + 10]
        assert body[0] > 0
        assert np.linalg.eigvalsh(pseudo_inertia(body))[0] > 0          # Wensing et al.: J > 0
        com = body[1:4] / body[0]
        ixx, ixy, ixz, iyy, iyz, izz = body[4:]
        tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        at_com = tensor - body[0] * (com @ com * np.eye(3) - np.outer(com, com))
        principal = np.linalg.eigvalsh(at_com)
        assert principal[0] > 0 and principal[0] + principal[1] > principal[2]


def test_truth_never_goes_into_the_data(tmp_path):
    from click.testing import CliRunner
    from baseparams.cli import main
    out, truth = tmp_path / "d.csv", tmp_path / "truth.json"
    result = CliRunner().invoke(main, ["simulate", "pendulum", "-o", str(out), "--truth", str(truth),
                                       "--effect", "viscous_friction:theta=0.3", "--noise", "0.01"])
    assert result.exit_code == 0, result.output
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["t", "q_theta", "qd_theta", "qdd_theta", "tau_theta"]
    assert "0.3" in truth.read_text() and "fv" in truth.read_text()
