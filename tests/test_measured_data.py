"""Measured data (baseparams.recordings.data): the CSV layout read and written exactly, and the
Savitzky-Golay derivatives checked against the trajectory's exact derivatives."""

from pathlib import Path

import numpy as np
import pytest

from baseparams.errors import InputError
from baseparams.recordings.data import (MIN_SAMPLES, MeasuredData, atomic_write, read_measured,
                                      savgol_derivatives, savgol_window, write_measured)
from baseparams.dynamics.forces import Motion
from baseparams.recordings.simulate import simulate
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate


def _csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def test_round_trip_is_exact(tmp_path):
    mech = parse_mechanism(generate.serial_chain(2, bodies=3))
    data, _ = simulate(mech, samples=60, noise_sd=0.1, seed=1)
    write_measured(tmp_path / "d.csv", data)
    back = read_measured(tmp_path / "d.csv", mech)
    for a, b in ((back.motion.q, data.motion.q), (back.motion.qd, data.motion.qd),
                 (back.motion.qdd, data.motion.qdd), (back.tau, data.tau), (back.motion.t, data.motion.t)):
        np.testing.assert_array_equal(a, b)
    assert back.coordinates == data.coordinates and back.estimated == () and back.notes == ()
    assert back.path == str(tmp_path / "d.csv")


@pytest.mark.parametrize("name, samples, tol_qd, tol_qdd", [
    ("pendulum", 2000, 1e-3, 3e-3), ("puma560", 2000, 1e-3, 3e-3), ("sla_suspension", 4000, 1e-3, 3e-3)])
def test_savitzky_golay_matches_exact_derivatives(tmp_path, name, samples, tol_qd, tol_qdd):
    """Positions only: qd and qdd estimated, compared with the trajectory's exact derivatives
    (relative to each coordinate's largest value; the window's bias target is 1e-3 on qdd at
    the bandwidth); the ends, half a window each, are dropped."""
    mech = resolve(name)
    data, _ = simulate(mech, samples=samples)
    write_measured(tmp_path / "d.csv", data, derivatives=False)
    back = read_measured(tmp_path / "d.csv", mech)
    assert back.estimated == ("qd", "qdd")
    assert any("Savitzky-Golay" in n and "window" in n for n in back.notes)
    rows = np.searchsorted(data.motion.t, back.motion.t)
    assert 0 < rows[0] and rows[-1] < data.count - 1 and np.all(np.diff(rows) == 1)
    np.testing.assert_array_equal(back.tau, data.tau[rows])
    for est, exact, tol in ((back.motion.qd, data.motion.qd[rows], tol_qd),
                            (back.motion.qdd, data.motion.qdd[rows], tol_qdd)):
        error = np.abs(est - exact).max(axis=0) / np.abs(exact).max(axis=0)
        assert np.all(error < tol), error


def test_window_smooths_noisy_positions():
    """With noise on the positions, the window the bandwidth rule picks estimates qd far better
    than the shortest window (which only interpolates)."""
    t = np.linspace(0, 10, 5001)
    step = t[1] - t[0]
    q = (np.sin(1.3 * t) + 0.3 * np.sin(4.1 * t))[:, None]
    exact = (1.3 * np.cos(1.3 * t) + 1.23 * np.cos(4.1 * t))[:, None]
    noisy = q + np.random.default_rng(0).normal(0, 1e-4, q.shape)
    window = savgol_window(noisy, step)
    assert window > 2 * MIN_SAMPLES
    chosen = np.sqrt(np.mean((savgol_derivatives(noisy, step, window)[0] - exact) ** 2))
    shortest = np.sqrt(np.mean((savgol_derivatives(noisy, step, 5)[0] - exact) ** 2))
    assert chosen < shortest / 10


def test_unknown_columns_are_noted_and_order_is_free(tmp_path):
    mech = resolve("pendulum")
    rows = [(0.1 * k, 0.5, 0.01 * k, 0.0, 1.0 + k, 7) for k in range(12)]
    path = _csv(tmp_path / "d.csv", ["t", "qd_theta", "q_theta", "qdd_theta", "tau_theta", "temperature"], rows)
    data = read_measured(path, mech)
    assert any("temperature" in n for n in data.notes)
    np.testing.assert_array_equal(data.motion.q[:, 0], [0.01 * k for k in range(12)])
    np.testing.assert_array_equal(data.tau[:, 0], [1.0 + k for k in range(12)])


def test_non_uniform_sampling_needs_given_derivatives(tmp_path):
    mech = resolve("pendulum")
    t = np.cumsum(np.r_[0, np.full(19, 0.1)])
    t[10:] += 0.05
    rows = [(tk, np.sin(tk), 0.0) for tk in t]
    path = _csv(tmp_path / "d.csv", ["t", "q_theta", "tau_theta"], rows)
    with pytest.raises(InputError) as info:
        read_measured(path, mech)
    assert "row 12, column t" in str(info.value) and "uniformly sampled" in str(info.value)
    rows = [(tk, np.sin(tk), np.cos(tk), -np.sin(tk), 0.0) for tk in t]
    path = _csv(tmp_path / "e.csv", ["t", "q_theta", "qd_theta", "qdd_theta", "tau_theta"], rows)
    assert read_measured(path, mech).estimated == ()


def test_positions_that_cannot_close_name_the_row(tmp_path):
    mech = resolve("sla_suspension")
    data, _ = simulate(mech, samples=30)
    q = data.motion.q.copy()
    q[17, 0] = 2.5                                    # the lower arm swung far out of reach
    broken = MeasuredData(Motion(data.motion.t, q, data.motion.qd, data.motion.qdd), data.tau, data.coordinates)
    write_measured(tmp_path / "d.csv", broken)
    with pytest.raises(InputError) as info:
        read_measured(tmp_path / "d.csv", mech)
    message = str(info.value)
    assert str(tmp_path / "d.csv") in message and "row 19" in message and "sla_suspension" in message


def test_take_keeps_the_layout():
    mech = resolve("planar_2r")
    data, _ = simulate(mech, samples=40)
    part = data.take(slice(10, 20))
    assert part.count == 10 and part.coordinates == data.coordinates and part.sample is None
    np.testing.assert_array_equal(part.tau, data.tau[10:20])


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_writing_to_a_device_never_replaces_it():
    """atomic_write renames a temporary file over its target; a device (/dev/full) must be
    written in place, and its error reported, not replaced by a regular file."""
    with pytest.raises(InputError, match="cannot write"):
        atomic_write("/dev/full", "t,q_theta,tau_theta\n")
    assert not Path("/dev/full").is_file()
