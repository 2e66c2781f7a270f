"""The noise model of ``diagnose --baseline``'s tests (core/diagnose/changesearch.py,
noise_filters): an autoregression fitted to a residual that slow columns were fitted out of,
corrected for what that projection takes in expectation, each coordinate whitened to unit
innovation variance; checked against closed forms, direct sums and simulated noise whose
truth is known, and on the datasets where the uncorrected noise model named changes that
never happened or missed one (issue 42)."""

import numpy as np
import pytest
from scipy.linalg import toeplitz
from scipy.signal import lfilter

from baseparams.diagnose.change import diagnose_change
from baseparams.diagnose.changesearch import _filtered, ar_autocovariance, noise_filters, toeplitz_times
from baseparams.diagnose.lagged import lagged_cross
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.recordings.simulate import simulate_change


def test_ar_autocovariance_is_the_closed_form_of_an_ar1():
    phi, variance = 0.9, 0.3
    expected = variance * phi ** np.arange(50) / (1 - phi ** 2)
    assert np.allclose(ar_autocovariance(np.array([1.0, -phi]), variance, 50), expected, rtol=1e-9, atol=1e-12)


def test_toeplitz_times_is_the_dense_product():
    rng = np.random.default_rng(0)
    g, x = rng.standard_normal(37), rng.standard_normal((37, 3))
    assert np.allclose(toeplitz_times(g, x), toeplitz(g) @ x, atol=1e-10)


def test_lagged_cross_is_the_direct_sum():
    rng = np.random.default_rng(1)
    A, B, top = rng.standard_normal((40, 3)), rng.standard_normal((40, 3)), 5
    direct = np.array([[sum(A[t - i] @ B[t - l] for t in range(top, 40)) for l in range(top + 1)]
                       for i in range(top + 1)])
    assert np.allclose(lagged_cross(A, B, top), direct, atol=1e-12)


def _slow_design(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    t = np.arange(n) / n
    return np.stack([np.sin(2 * np.pi * rng.uniform(0.5, 6) * t + rng.uniform(0, 6)) for _ in range(k)], axis=1)


def _phi(filters: list[np.ndarray]) -> float:
    """The lag-1 coefficient of a coordinate's filter (scaled by 1/SD: over its leading one)."""
    return float(-filters[0][1] / filters[0][0])


def test_the_projection_correction_removes_the_autoregression_bias():
    """AR(1) 0.9 on 1000 samples, 20 slow columns fitted out: the plain fit of the residual
    is biased low by about 0.05 (a standard error of the mean over 100 datasets is 0.002);
    corrected, its mean is that of a fit of the noise itself (whose own small-sample bias,
    -(1 + 3 phi) / n = -0.004, stays), and every innovation variance is one."""
    rng = np.random.default_rng(0)
    n, phi = 1000, 0.9
    design = _slow_design(n, 20, rng)[:, None, :]
    empty = design[:, :, :0]
    plain, corrected, own, scale = [], [], [], []
    for _ in range(100):
        e = lfilter([1.0], [1.0, -phi], rng.standard_normal(n + 500))[500:, None] * 3.0
        residual = e - (design[:, 0] @ np.linalg.lstsq(design[:, 0], e[:, 0], rcond=None)[0])[:, None]
        plain.append(_phi(noise_filters(residual, empty, order=1)))
        filters = noise_filters(e, design, order=1)
        corrected.append(_phi(filters))
        own.append(_phi(noise_filters(e, empty, order=1)))
        scale.append(np.var(_filtered(filters, e)))
    assert np.mean(own) - np.mean(plain) > 0.03
    assert abs(np.mean(corrected) - np.mean(own)) < 0.006
    assert abs(np.mean(scale) - 1.0) < 0.05


def test_each_coordinate_is_whitened_to_unit_variance():
    """Two coordinates, AR(1) 0.95 at SD 1 and white noise at SD 0.01: each whitened one has
    variance one (an F test pools them)."""
    rng = np.random.default_rng(2)
    n = 4000
    slow = lfilter([1.0], [1.0, -0.95], rng.standard_normal(n))
    noise = np.stack([slow / np.std(slow), 0.01 * rng.standard_normal(n)], axis=1)
    white = _filtered(noise_filters(noise, np.zeros((n, 2, 0))), noise)
    assert np.allclose(np.var(white, axis=0), 1.0, atol=0.05)


@pytest.mark.parametrize("noise, generator, seed", [("ar1", 11, 5), ("ar1", 11, 7), ("lowpass", 11, 7),
                                                   ("lowpass", 12, 8)])
def test_generated_chain_with_nothing_changed(noise, generator, seed):
    """Generated RRRR chains with random inertias (the benchmark's, generator seeds 11 and
    12) where a body on body4, a viscous friction on q4 or an ambiguous group was named with
    nothing changed: the noise model, fitted to the residual of every candidate, was too
    weak at low frequencies."""
    mechanism = parse_mechanism(generate.serial_chain(generator, bodies=4, types="RRRR", samples=600), "chain.toml")
    before, after, _ = simulate_change(mechanism, samples=1000, seed=seed, noise=noise, random_inertia=True)
    result = diagnose_change(mechanism, before, after)
    assert result.verdict == "nothing changed", (result.changes, result.ambiguous, result.steps[:1])


def test_ur5_friction_drift_under_low_passed_noise_is_named():
    """A viscous friction drift on the UR5's shoulder (10 % of its largest torque at the
    largest speed), low-passed noise, torques quantised to 0.01 N m: a perfect-model fit with
    the true noise puts it at t = 37; the shoulder's whitened noise, far below the wrist's
    quantisation, buried it in a pooled F test (unseen in 20 of 20 datasets)."""
    mechanism = resolve("tests/data/urdf/ur5.urdf")
    for seed in (0, 1):
        before, after, truth = simulate_change(mechanism, samples=1000, seed=seed, noise="lowpass", quantum=0.01,
                                               friction_drift=0.1, drift_coordinate=1)
        result = diagnose_change(mechanism, before, after)
        names = [(e["kind"], e["coordinate"]) for e in result.changes]
        assert names == [("viscous_friction", "shoulder_lift_joint")], (seed, names, result.notes)
        value = result.changes[0]["value"]
        assert abs(value - truth["friction_drift"]["fv"]) < 0.15 * truth["friction_drift"]["fv"]
