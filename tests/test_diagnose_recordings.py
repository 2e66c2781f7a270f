"""diagnose through a recording as a robot writes it (issue 21 on the recordings issue):
motor-side encoders in degrees, currents with gains, a coupled motor, noise in the currents,
the recording's default low-pass and decimation. The reduction colours the noise at the fit's
rows, which the whiteness test and the noise level must expect (else "structure remains"
with nothing missing); what was hidden must be named with its value."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.signal import butter

from baseparams.cli import main
from baseparams.identify.data import Segment
from baseparams.identify.simulate import random_physical_inertia
from baseparams.identify.whiteness import coloured_noise
from baseparams.io.loader import parse_mechanism
from baseparams.model.mechanism import EffectSpec
from test_recordings import MOTORS_3, RATE, _chain, _truth, _write

RATIOS = np.array([[-50, 0, 0], [0, 80, 0], [0, 30, 30.0]])      # MOTORS_3: motor q = N q
GAINS = np.array([0.5, 2.0, 0.8])


def _autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    x = x - x.mean()
    return np.array([np.dot(x[:len(x) - k], x[k:]) for k in range(lags + 1)]) / np.dot(x, x)


def test_reduced_noise_correlation_is_the_sample_autocorrelation():
    """White noise through a segment's zero-phase filter and decimation: its autocorrelation
    at the kept rows is what Segment.noise_correlation computes from the impulse response."""
    fs, cutoff, factor = 1000.0, 6.0, 66                 # as the recordings below: 1 kHz -> 15 Hz
    segment = Segment(0, 2_000_000, sos=butter(4, cutoff, fs=fs, output="sos"), factor=factor,
                      edge=int(3 * fs / cutoff))
    r = segment.noise_correlation()
    sample = _autocorrelation(segment.reduce(np.random.default_rng(0).standard_normal(2_000_000)), 3)
    assert r[0] == 1.0 and r[1] > 0.2                   # correlated at the fit's rows
    np.testing.assert_allclose(r[:4], sample, atol=0.02)
    assert list(Segment(0, 100).noise_correlation()) == [1.0]


def test_coloured_noise_has_the_autocorrelation_asked_for():
    target = np.array([1.0, 0.33, -0.16, 0.03])
    noise = coloured_noise(np.random.default_rng(1), 20_000, (3,), target)
    for j in range(3):
        np.testing.assert_allclose(_autocorrelation(noise[:, j], 5), np.r_[target, 0, 0], atol=0.03)


def _recording(folder: Path, seed: int, hidden: list[tuple[str, str, str]], delay: float = 0.0
               ) -> list[tuple[str, str, float]]:
    """A motor-side log of a generated 3-R chain with a coupled motor (MOTORS_3): encoders in
    degrees, currents (noise 2 % of each motor's RMS torque), each hidden effect scaled to
    effect/noise 5 on the motor it shows most on; the torques lag ``delay`` seconds. Writes
    mech.toml and rec.toml; returns the hidden effects with their values."""
    mech = parse_mechanism(_chain(seed, motors=MOTORS_3))
    rng = np.random.default_rng(seed)
    phi = random_physical_inertia(mech, rng)
    t = np.arange(0, 10, 1 / RATE)
    motion, clean = _truth(mech, t, phi)
    sd = 0.02 * np.sqrt(np.mean(np.linalg.solve(RATIOS.T, clean.T) ** 2, axis=1))
    tau, values = clean.copy(), []
    for kind, coordinate, name in hidden:
        force = _truth(mech, t, phi, [EffectSpec(kind, coordinate, {name: 1.0})])[1] - clean
        value = 5.0 / np.max(np.sqrt(np.mean(np.linalg.solve(RATIOS.T, force.T) ** 2, axis=1)) / sd)
        tau += value * force
        values.append((kind, coordinate, float(value)))
    if delay:
        tau = np.stack([np.interp(t - delay, t, tau[:, j]) for j in range(3)], axis=1)
    current = (np.linalg.solve(RATIOS.T, tau.T).T + rng.standard_normal(tau.shape) * sd) / GAINS
    _write(folder / "enc.csv", ["e1", "e2", "e3"], np.degrees(motion.q @ RATIOS.T).T)
    _write(folder / "cur.csv", ["i1", "i2", "i3"], current.T)
    (folder / "mech.toml").write_text(_chain(seed, motors=MOTORS_3))
    (folder / "rec.toml").write_text(f"""
[recording]
rate = {RATE}
[[runs]]
files = {{ enc = "enc.csv", cur = "cur.csv" }}
[position]
mot1 = {{ column = "e1", unit = "deg" }}
mot2 = {{ column = "e2", unit = "deg" }}
mot3 = {{ column = "e3", unit = "deg" }}
[torque]
mot1 = {{ column = "i1", gain = 0.5 }}
mot2 = {{ column = "i2", gain = 2.0 }}
mot3 = {{ column = "i3", gain = 0.8 }}
""")
    return values


def _diagnose(folder: Path) -> dict:
    result = CliRunner().invoke(main, ["diagnose", str(folder / "mech.toml"), str(folder / "rec.toml"),
                                       "--format", "json", "--quiet"])
    assert result.exit_code in (0, 1), result.output
    return json.loads(result.stdout)


def test_nothing_hidden_in_a_filtered_recording_is_nothing_missing(tmp_path):
    """White current noise, reduced by the recording's filter and decimation (r1 = 0.33 at the
    fit's rows): the verdict was "unexplained: structure remains" in 3 of 3 (Ljung-Box p
    0.004-0.008, residual 1.26-1.33 times the noise level); with the filter's colour expected,
    "nothing missing" and the residual at the noise level (11 of 12 seeds measured)."""
    for seed in range(3):
        folder = tmp_path / str(seed)
        folder.mkdir()
        _recording(folder, seed, [])
        report = _diagnose(folder)
        assert report["effects"] == [] and report["verdict"] == "nothing missing", report["verdict"]
        ratios = report["unexplained"]["ratio"]
        assert all(0.8 < r < 1.15 for r in ratios.values()), ratios


@pytest.mark.parametrize("seed", [0, 1])
def test_friction_on_a_coupled_motor_is_named_through_the_recording(tmp_path, seed):
    """Viscous friction of the coupled motor mot3 (it turns with q2 + q3) and Coulomb friction
    on joint 1, hidden in the currents: both named, values within 5 %, the gap closed."""
    hidden = _recording(tmp_path, seed, [("viscous_friction", "mot3", "fv"), ("coulomb_friction", "q1", "fc")])
    report = _diagnose(tmp_path)
    named = {(e["kind"], e["coordinate"]): e["value"] for e in report["effects"]}
    assert set(named) == {(kind, coordinate) for kind, coordinate, _ in hidden}
    for kind, coordinate, value in hidden:
        assert named[kind, coordinate] == pytest.approx(value, rel=0.05)
    assert report["verdict"] == "explained"


def test_a_delay_in_the_currents_is_named_through_the_recording(tmp_path):
    """The currents lag the encoders by 3 ms (3 samples at 1 kHz; the fit's rows are 66 ms
    apart): named a delay of 3 ms within 15 %, nothing else."""
    _recording(tmp_path, 0, [], delay=0.003)
    report = _diagnose(tmp_path)
    assert [(e["kind"], e["coordinate"]) for e in report["effects"]] == [("delay", "all")]
    assert report["effects"][0]["value"] == pytest.approx(0.003, rel=0.15)
