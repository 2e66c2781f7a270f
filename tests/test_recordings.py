"""Recordings as robots write them (baseparams.recordings.recording), on data made with known
truth: raw logs on the motor side (negative gear ratios, a coupled wrist, a differential),
currents with gains, degrees and sign conventions, zero offsets, a measured velocity without
acceleration, irregular time stamps, two runs with a seam, a known payload; identification
through the description must recover what made the data."""

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify, predict
from baseparams.dynamics.forces import Motion, design, effect_values
from baseparams.recordings.recording import read_data, read_recording
from baseparams.recordings.simulate import random_physical_inertia
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec
from baseparams.numeric.backends import Float64

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
from diagnose_campaign import RECORDING_MOTORS  # noqa: E402

RATE = 1000.0          # Hz of the synthetic logs
# q1..q3 from columns a, b, c and their forces from x, y, z
CHANNELS_ABC = '[position]\nq1 = "a"\nq2 = "b"\nq3 = "c"\n[torque]\nq1 = "x"\nq2 = "y"\nq3 = "z"\n'


def _chain(seed: int, bodies: int = 3, motors: str = "") -> str:
    return generate.serial_chain(seed, bodies=bodies, types="R") + motors


def _truth(mech, t, phi, effects=()):
    """Exact motion and forces at the times ``t`` (the mechanism's trajectory)."""
    z, zd, zdd = Trajectory.default(mech).independent_values(mech, Float64(), np.asarray(t, float))
    motion = Motion(np.asarray(t, float), *(np.stack([np.broadcast_to(np.asarray(v, float), t.shape)
                                                       for v in a], axis=1) for a in (z, zd, zdd)))
    inertial, columns = design(mech, motion, effects)
    tau = inertial.matrix @ phi
    if effects:
        tau = tau + columns.matrix @ effect_values(mech, effects)
    return motion, tau


def _write(path: Path, header, columns) -> str:
    table = np.column_stack(columns)
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in table) + "\n")
    return path.name


def _base(mech):
    return BaseModel.from_result(registry.solvers()["dp"].item.solve(mech), mech)


def _check_base(result, base, phi, rtol):
    """The base estimates against B phi, relative to the largest base parameter."""
    truth = base.values(phi)
    error = np.abs(result.base_estimates - truth).max() / np.abs(truth).max()
    assert error < rtol, (error, result.base_estimates, truth)


MOTORS_3 = RECORDING_MOTORS       # mot1 = -50 q1, mot2 = 80 q2, mot3 = 30 (q2 + q3): the campaign's robot


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_motor_side_log_with_negative_ratio_coupling_gains_degrees_and_offsets(tmp_path, seed):
    """Motor encoders in degrees, motor currents with gains, one inverted sign, a joint zero
    offset: the description undoes all of it and the base parameters come back."""
    mech = parse_mechanism(_chain(seed, motors=MOTORS_3))
    phi = random_physical_inertia(mech, np.random.default_rng(seed))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    ratios = np.array([[-50, 0, 0], [0, 80, 0], [0, 30, 30.0]])
    zero = 0.25                                        # the log's q3 zero is 0.25 rad off
    logged_q = motion.q.copy()
    logged_q[:, 2] -= zero
    motor_q = np.degrees(logged_q @ ratios.T)
    motor_tau = np.linalg.solve(ratios.T, tau.T).T      # tau = N^T tau_motor
    gains = np.array([0.5, 2.0, 0.8])
    current = motor_tau / gains
    current[:, 1] *= -1                                 # the drive counts mot2's current the other way
    _write(tmp_path / "enc.csv", ["e1", "e2", "e3"], motor_q.T)
    _write(tmp_path / "cur.csv", ["i1", "i2", "i3"], current.T)
    (tmp_path / "rec.toml").write_text(f"""
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
mot2 = {{ column = "i2", gain = -2.0 }}
mot3 = {{ column = "cur:i3", gain = 0.8 }}
[zero]
q3 = {zero}
""")
    data, model = read_data([str(tmp_path / "rec.toml")], mech)
    assert data.reduced and data.count < len(t) / 5
    assert any("drive chain" in n for n in data.notes) and any("low-passed" in n for n in data.notes)
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)
    assert result.nrms.max() < 2e-3


def test_differential_transmission(tmp_path):
    """Two motors driving two joints through a differential: a = 40 (q1 + q2), b = 40 (q1 - q2)."""
    motors = ('\n[[motors]]\nname = "ma"\nratios = { q1 = 40, q2 = 40 }\n'
              '[[motors]]\nname = "mb"\nratios = { q1 = 40, q2 = -40 }\n')
    mech = parse_mechanism(_chain(5, bodies=2, motors=motors))
    phi = random_physical_inertia(mech, np.random.default_rng(5))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    n = np.array([[40, 40], [40, -40.0]])
    _write(tmp_path / "log.csv", ["pa", "pb", "ta", "tb"],
           [*(motion.q @ n.T).T, *np.linalg.solve(n.T, tau.T)])
    (tmp_path / "rec.toml").write_text(f"""
[recording]
step = {1 / RATE}
[[runs]]
file = "log.csv"
[position]
ma = "pa"
mb = "pb"
[torque]
ma = "ta"
mb = "tb"
""")
    data, model = read_recording(tmp_path / "rec.toml", mech)
    np.testing.assert_allclose(data.tau, data.reduce(tau), rtol=1e-9, atol=1e-9 * np.abs(tau).max())
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)


def test_effects_on_a_coupled_motor_are_identified(tmp_path):
    """Rotor inertia and Coulomb friction of motor mot3, which turns with q2 + q3: its
    acceleration and the sign of its speed act on both joints through the ratios."""
    mech = parse_mechanism(_chain(3, motors=MOTORS_3))
    phi = random_physical_inertia(mech, np.random.default_rng(3))
    hidden = [EffectSpec("rotor_inertia", "mot3", {"Ia": 2e-4}), EffectSpec("coulomb_friction", "mot3", {"fc": 0.05}),
              EffectSpec("viscous_friction", "q1", {"fv": 0.4})]
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi, hidden)
    # the columns by hand: mot3's force 30 * (Ia * 30 (qdd2 + qdd3) + fc sign(30 (qd2 + qd3))) on q2 and q3
    hand = 30 * (2e-4 * 30 * (motion.qdd[:, 1] + motion.qdd[:, 2]) + 0.05 * np.sign(motion.qd[:, 1] + motion.qd[:, 2]))
    inertial, _ = design(mech, motion)
    np.testing.assert_allclose(tau[:, 2] - inertial.matrix[:, 2] @ phi, hand, atol=1e-9)
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, model = read_data([str(tmp_path / "rec.toml")], mech)
    result = identify(model, data, base=_base(mech), effects=[EffectSpec(s.kind, s.coordinate) for s in hidden])
    assert result.value("Ia_mot3") == pytest.approx(2e-4, rel=0.02)
    assert result.value("fc_mot3") == pytest.approx(0.05, rel=0.02)
    assert result.value("fv_q1") == pytest.approx(0.4, rel=0.02)


def test_measured_velocity_without_acceleration(tmp_path):
    """Positions and velocities logged, no acceleration: the velocity is filtered and
    differentiated once (not re-derived from the positions)."""
    mech = parse_mechanism(_chain(4))
    phi = random_physical_inertia(mech, np.random.default_rng(4))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    wrong_q = motion.q + 1e-3 * np.sin(2 * np.pi * 0.7 * t)[:, None]     # positions with a slow error
    _write(tmp_path / "log.csv", ["t", *"abc", "va", "vb", "vc", *"xyz"], [t, *wrong_q.T, *motion.qd.T, *tau.T])
    (tmp_path / "rec.toml").write_text("""
[recording]
time = "t"
[[runs]]
file = "log.csv"
[position]
q1 = "a"
q2 = "b"
q3 = "c"
[velocity]
q1 = "va"
q2 = "vb"
q3 = "vc"
[torque]
q1 = "x"
q2 = "y"
q3 = "z"
""")
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert data.estimated == ("qdd",)
    rows = data.kept_rows()
    inside = slice(len(rows) // 10, -len(rows) // 10)
    # qd is the logged velocity (filtered), not the derivative of the disturbed positions
    np.testing.assert_allclose(data.motion.qd[rows][inside], motion.qd[rows][inside], atol=1e-5)
    scale = np.abs(motion.qdd).max()
    assert np.abs(data.motion.qdd[rows][inside] - motion.qdd[rows][inside]).max() < 1e-3 * scale


def test_irregular_time_stamps_are_resampled(tmp_path):
    """Time steps between 0.7 and 8.8 ms (as a Franka logs them): resampled, said so, and the
    base parameters come back."""
    mech = parse_mechanism(_chain(6))
    phi = random_physical_inertia(mech, np.random.default_rng(6))
    rng = np.random.default_rng(0)
    steps = np.where(rng.random(6000) < 0.1, rng.uniform(0.7e-3, 8.8e-3, 6000), 1e-3)
    t = np.concatenate([[0], np.cumsum(steps)])
    t = t[t < 10]
    motion, tau = _truth(mech, t, phi)
    _write(tmp_path / "log.csv", ["time_ms", "a", "b", "c", "x", "y", "z"], [t * 1e3, *motion.q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "time_ms"\ntime_unit = "ms"\n[[runs]]\n'
                                       'file = "log.csv"\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert any("irregular time steps" in n and "resampled" in n for n in data.notes)
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 5e-3)


def test_an_irregular_clock_evaluates_the_model_where_the_torques_were_measured(tmp_path):
    """A ROS-like clock (100 Hz, steps 7.7-12.3 ms, as the TIAGo's published logs) with Coulomb
    friction: the torque jumps at each reversal. Interpolated onto a uniform grid, a torque
    sample straddling a jump took a value between the two sides that the model's sign(qd) at
    that grid point did not (one sample a reversal, up to 2 fc), which the fit left as
    structure at the reversals: diagnose called exact data with white noise "unexplained".
    The torques are now not resampled: the model is evaluated at each sample's own time and
    filtered alike, so the jittered clock fits as well as a regular one."""
    mech = parse_mechanism(_chain(4))
    phi = random_physical_inertia(mech, np.random.default_rng(4))
    friction = [EffectSpec("coulomb_friction", c, {"fc": 0.3}) for c in ("q1", "q2", "q3")]
    rng = np.random.default_rng(1)
    residuals = {}
    for clock in ("regular", "jittered"):
        jitter = np.clip(0.0012 * rng.standard_normal(3000), -0.0023, 0.0023)
        steps = 0.01 + (jitter if clock == "jittered" else 0 * jitter)
        t = np.concatenate([[0], np.cumsum(steps)])
        t = t[t < 20]
        motion, tau = _truth(mech, t, phi, friction)
        folder = tmp_path / clock
        folder.mkdir()
        _write(folder / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
        (folder / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
        data, model = read_recording(folder / "rec.toml", mech)
        assert any("irregular time steps" in n for n in data.notes) == (clock == "jittered")
        result = identify(model, data, base=_base(mech), effects=[EffectSpec(e.kind, e.coordinate) for e in friction])
        np.testing.assert_allclose(result.estimates[np.array(result.kinds) != "base"], 0.3, rtol=2e-3)
        residuals[clock] = result.nrms.max()
    # before: the jumps smeared by the interpolation left a residual 300 times the regular clock's
    assert residuals["jittered"] < 3 * residuals["regular"] + 1e-4, residuals


def _two_runs(tmp_path, mech, phi, seam_as_one: bool):
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    halves = [slice(0, 4000), slice(6000, 10000)]       # two windows of the motion: a jump between
    header = ["t", "a", "b", "c", "x", "y", "z"]
    for k, rows in enumerate(halves):
        _write(tmp_path / f"run{k}.csv", header, [t[rows] - t[rows][0] + (4.001 * k if seam_as_one else 0),
                                                   *motion.q[rows].T, *tau[rows].T])
    if seam_as_one:                                     # what a user did by hand: one file
        a = np.loadtxt(tmp_path / "run0.csv", delimiter=",", skiprows=1)
        b = np.loadtxt(tmp_path / "run1.csv", delimiter=",", skiprows=1)
        _write(tmp_path / "joined.csv", header, np.vstack([a, b]).T)
        runs = '[[runs]]\nfile = "joined.csv"\n'
    else:
        runs = '[[runs]]\nname = "first"\nfile = "run0.csv"\n[[runs]]\nname = "second"\nfile = "run1.csv"\n'
    (tmp_path / "rec.toml").write_text(f"""
[recording]
time = "t"
{runs}
{CHANNELS_ABC}
""")
    return read_recording(tmp_path / "rec.toml", mech)


def test_two_runs_are_filtered_apart(tmp_path):
    """Two runs fitted together keep their seam: no filter crosses it, and the fit is as good
    as on each run; the same rows joined by hand into one file smear the jump into the fit."""
    mech = parse_mechanism(_chain(7))
    phi = random_physical_inertia(mech, np.random.default_rng(7))
    data, model = _two_runs(tmp_path, mech, phi, seam_as_one=False)
    assert data.runs == ("first", "second") and len(data.segments) == 2
    assert set(data.run_of_row()) == {0, 1}
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)
    joined, model = _two_runs(tmp_path, mech, phi, seam_as_one=True)
    bad = identify(model, joined, base=_base(mech))
    assert bad.nrms.max() > 20 * result.nrms.max()


def test_known_payload_on_one_run(tmp_path):
    """Run 2 carries a 2.5 kg load on the last body; declared as a known payload, both runs
    fit the payload-free parameters; undeclared, the fit is visibly worse."""
    mech = parse_mechanism(_chain(8))
    phi = random_physical_inertia(mech, np.random.default_rng(8))
    mass, com = 2.5, np.array([0.05, -0.02, 0.1])
    inertia_com = np.diag([0.004, 0.005, 0.003])
    at_origin = inertia_com + mass * (com @ com * np.eye(3) - np.outer(com, com))
    load = np.array([mass, *(mass * com), at_origin[0, 0], at_origin[0, 1], at_origin[0, 2],
                     at_origin[1, 1], at_origin[1, 2], at_origin[2, 2]])
    loaded = phi.copy()
    loaded[20:30] += load
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    _, tau_loaded = _truth(mech, t, loaded)
    header = ["t", "a", "b", "c", "x", "y", "z"]
    _write(tmp_path / "empty.csv", header, [t, *motion.q.T, *tau.T])
    _write(tmp_path / "loaded.csv", header, [t, *motion.q.T, *tau_loaded.T])
    channels = CHANNELS_ABC
    payload = ("[runs.payload]\nbody = 3\nmass = 2.5\ncom = [0.05, -0.02, 0.1]\n"
               "inertia = [0.004, 0, 0, 0.005, 0, 0.003]\n")
    for declared in (True, False):
        (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "empty.csv"\n'
                                           '[[runs]]\nfile = "loaded.csv"\n' + (payload if declared else "")
                                           + channels)
        data, model = read_recording(tmp_path / "rec.toml", mech)
        result = identify(model, data, base=_base(mech))
        if declared:
            _check_base(result, _base(mech), phi, 2e-3)
            assert result.nrms.max() < 2e-3
        else:
            assert result.nrms.max() > 0.01


def test_validate_prediction_matches_a_hand_computation(tmp_path):
    """identify --validate on the pendulum: the prediction error it prints equals the closed
    form tau = Izz1 qdd + g (mx1 sin(theta) + my1 cos(theta)) + fv qd evaluated by hand with
    the printed estimates on the held-out file's own q, qd, qdd."""
    runner = CliRunner()
    fit_csv, other_csv = tmp_path / "fit.csv", tmp_path / "other.csv"
    for path, seed in ((fit_csv, 1), (other_csv, 2)):
        result = runner.invoke(main, ["simulate", "pendulum", "-o", str(path), "--noise", "0.02",
                                      "--seed", str(seed), "--samples", "400",
                                      "--effect", "viscous_friction:theta=0.05"])
        assert result.exit_code == 0, result.output
    result = runner.invoke(main, ["identify", "pendulum", str(fit_csv), "--solver", "dp", "--effect",
                                  "viscous_friction:theta", "--validate", str(other_csv), "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    out = json.loads(result.stdout)
    value = {}
    for entry in out["base"]:
        (name, coefficient), = entry["expression"].items()
        value[name] = entry["value"] / float(coefficient)
    fv = out["effects"][0]["coefficients"][0]["value"]
    table = np.loadtxt(other_csv, delimiter=",", skiprows=1)
    header = other_csv.read_text().splitlines()[0].split(",")
    col = {name: table[:, header.index(name)] for name in header}
    theta, qd, qdd = col["q_theta"], col["qd_theta"], col["qdd_theta"]
    hand = (value["Izz1"] * qdd + 9.81 * (value["mx1"] * np.sin(theta) + value.get("my1", 0) * np.cos(theta))
            + fv * qd)
    rms = np.sqrt(np.mean((col["tau_theta"] - hand) ** 2))
    validation = out["validation"][0]
    assert validation["samples"] == len(theta)
    assert validation["rms"]["theta"] == pytest.approx(rms, rel=1e-9)
    assert 0.015 < rms < 0.025                      # about the noise's SD, 0.02


BAD = [
    ("[[motors]]\nname = 'mx'\nratios = { q1 = 0 }\n", "motors[0].ratios.q1", "gear ratio of 0"),
    ("[[motors]]\nname = 'ma'\nratios = { q1 = 2, q2 = 2 }\n[[motors]]\nname = 'mb'\nratios = { q1 = 3, q2 = 3 }\n",
     "position", "singular"),
    ("", "row 5", "not finite"),
    ("", "row 4", "does not increase"),
    ("", "header", "no column 'nope'"),
    ("[[motors]]\nname = 'q1'\nratios = { q1 = 1 }\n", "motors[0].name", "joint coordinate"),
    ("", "row 5, column t", "time is not finite"),
]


@pytest.mark.parametrize("case", range(len(BAD)))
def test_bad_recordings_are_named(tmp_path, case):
    """Each bad input is one error line naming the file, the key or row, and the reason; exit 2."""
    motors, where, reason = BAD[case]
    mech_path = tmp_path / "m.toml"
    mech_path.write_text(_chain(2, bodies=2))
    rows = [[k * 0.01, 0.1 * k, 0.2 * k, 1.0, 2.0] for k in range(30)]
    if case == 2:
        rows[3][1] = "inf"           # NaN and empty fields are missing samples (test_missing_values_...)
    if case == 3:
        rows[2][0] = 0.0
    if case == 6:
        rows[3][0] = "nan"            # a missing time stamp: no sample can be placed
    (tmp_path / "log.csv").write_text("t,a,b,x,y\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    position = 'q1 = "a"\nq2 = "b"\n' if case != 1 else 'ma = "a"\nmb = "b"\n'
    if case == 4:
        position = 'q1 = "nope"\nq2 = "b"\n'
    (tmp_path / "rec.toml").write_text(f'[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n{motors}'
                                       f'[position]\n{position}[torque]\nq1 = "x"\nq2 = "y"\n')
    before = (tmp_path / "log.csv").read_bytes()
    result = CliRunner().invoke(main, ["identify", str(mech_path), str(tmp_path / "rec.toml"), "--solver", "dp"])
    assert result.exit_code == 2, result.output
    line = result.stderr.strip()
    assert line.startswith("error: ") and "\n" not in line and "Traceback" not in result.output
    assert where in line and reason in line, line
    assert (tmp_path / "log.csv").read_bytes() == before          # the raw log is never rewritten


def test_mechanism_file_motors_round_trip_and_errors(tmp_path):
    """[[motors]] in a mechanism file: read exactly, written back, checked like everything else."""
    from baseparams.io.toml_writer import mechanism_toml
    mech = parse_mechanism(_chain(0, motors=MOTORS_3))
    assert [m.name for m in mech.motors] == ["mot1", "mot2", "mot3"]
    assert dict(mech.motor("mot3").ratios) == {"q2": 30, "q3": 30}
    back = parse_mechanism(mechanism_toml(mech))
    assert back.motors == mech.motors
    for text, key in (('[[motors]]\nname = "mot9"\nratios = { q7 = 2 }\n', "motors[0].ratios.q7"),
                      ('[[motors]]\nname = "mot9"\nratios = { q1 = "0" }\n', "motors[0].ratios.q1"),
                      ('[[motors]]\nname = "mot9"\nratios = {}\n', "motors[0].ratios"),
                      ('[[effects]]\nkind = "rotor_inertia"\ncoordinate = "m8"\n', "effects[0].coordinate")):
        with pytest.raises(InputError) as info:
            parse_mechanism(_chain(0) + text)
        assert key in str(info.value)


URDF_TRANSMISSIONS = """<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><mass value="1"/><origin xyz="0.1 0 0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="l2"><inertial><mass value="1"/><origin xyz="0.1 0 0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="fix" type="fixed"><parent link="l2"/><child link="tool"/></joint>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="j1"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>-100.5</mechanicalReduction></actuator></transmission>
  <transmission name="t2"><plugin>transmission_interface/DifferentialTransmission</plugin>
    <actuator name="a1" role="actuator1"><mechanical_reduction>10</mechanical_reduction></actuator>
    <actuator name="a2" role="actuator2"><mechanical_reduction>10</mechanical_reduction></actuator>
    <joint name="j1" role="joint1"/>
    <joint name="j2" role="joint2"><mechanical_reduction>2</mechanical_reduction></joint></transmission>
  <transmission name="t3"><type>transmission_interface/FourBarLinkageTransmission</type>
    <actuator name="w1"><mechanicalReduction>3</mechanicalReduction></actuator>
    <actuator name="w2"><mechanicalReduction>5</mechanicalReduction></actuator>
    <joint name="j1"/><joint name="j2"/></transmission>
  <transmission name="t4"><type>transmission_interface/Weird</type><joint name="j2"/><actuator name="x"/></transmission>
  <transmission name="t5"><type>transmission_interface/SimpleTransmission</type><joint name="fix"/>
    <actuator name="y"/></transmission>
</robot>
"""


def test_urdf_transmissions_become_motors(tmp_path):
    """ros_control's simple (a negative, decimal reduction), differential and four-bar linkage
    transmissions, in the ROS 1 and ros2_control forms, read exactly; others noted and skipped;
    the motors survive a conversion to the TOML format."""
    from fractions import Fraction

    from baseparams.io.toml_writer import mechanism_toml
    from baseparams.plugins.urdf.reader import read_urdf
    path = tmp_path / "two.urdf"
    path.write_text(URDF_TRANSMISSIONS)
    result = read_urdf(path)
    motors = {m.name: dict(m.ratios) for m in result.mechanism.motors}
    assert motors == {"motor_m1": {"j1": Fraction(-201, 2)},            # m1 is a parameter's name
                      "a1": {"j1": 10, "j2": 20}, "a2": {"j1": 10, "j2": -20},
                      "w1": {"j1": 3}, "w2": {"j1": 5, "j2": 5}}
    assert any("t4" in n and "ignored" in n for n in result.notes)
    assert any("t5" in n and "not a moving joint" in n for n in result.notes)
    back = parse_mechanism(mechanism_toml(result.mechanism))
    assert back.motors == result.mechanism.motors


def test_unknown_current_gains_fixed_by_a_known_payload_run(tmp_path):
    """Currents with unknown gains on every joint: the run with a known payload fixes their
    scale, so the gains and the base parameters both come back; without it, an error says so."""
    mech = parse_mechanism(_chain(9))
    phi = random_physical_inertia(mech, np.random.default_rng(9))
    load = np.zeros(10)
    load[0], load[1:4] = 3.0, 3.0 * np.array([0.02, 0.03, 0.08])
    load[[4, 7, 9]] = [0.01, 0.012, 0.008]
    load[4:] += 3.0 * np.array([0.03 ** 2 + 0.08 ** 2, -0.02 * 0.03, -0.02 * 0.08,
                                0.02 ** 2 + 0.08 ** 2, -0.03 * 0.08, 0.02 ** 2 + 0.03 ** 2])
    loaded = phi.copy()
    loaded[20:30] += load
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    _, tau_loaded = _truth(mech, t, loaded)
    gains = np.array([0.7, 1.9, 0.35])
    header = ["t", "a", "b", "c", "x", "y", "z"]
    _write(tmp_path / "empty.csv", header, [t, *motion.q.T, *(tau / gains).T])
    _write(tmp_path / "loaded.csv", header, [t, *motion.q.T, *(tau_loaded / gains).T])
    com, inertia = [0.02, 0.03, 0.08], [0.01, 0, 0, 0.012, 0, 0.008]
    payload = f"[runs.payload]\nbody = 3\nmass = 3\ncom = {com}\ninertia = {inertia}\n"
    channels = ('[position]\nq1 = "a"\nq2 = "b"\nq3 = "c"\n[torque]\n'
                + "".join(f'{q} = {{ column = "{c}", gain = "unknown" }}\n' for q, c in zip(("q1", "q2", "q3"), "xyz")))
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "empty.csv"\n'
                                       '[[runs]]\nfile = "loaded.csv"\n' + payload + channels)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert data.gain_names == ("gain_q1", "gain_q2", "gain_q3")
    result = identify(model, data, base=_base(mech))
    np.testing.assert_allclose([result.value(g) for g in data.gain_names], gains, rtol=2e-3)
    _check_base(result, _base(mech), phi, 3e-3)
    assert [g["name"] for g in result.to_json()["gains"]] == list(data.gain_names)
    # the fit's own prediction from its residual is predict's from the columns made again
    from baseparams.identify.fit import fitted
    again, own = predict(result, model, data), fitted(result, data)
    np.testing.assert_allclose(own.predicted, again.predicted, rtol=0, atol=1e-9 * np.abs(again.measured).max())
    assert np.array_equal(own.measured, again.measured)
    # through the command, predicting its own data and another recording of the same currents
    # (both were a ValueError: the prediction looked for the gains among the model's columns)
    (tmp_path / "mech.toml").write_text(_chain(9))
    cli = CliRunner().invoke(main, ["identify", str(tmp_path / "mech.toml"), str(tmp_path / "rec.toml"),
                                    "--solver", "dp", "--validate", str(tmp_path / "rec.toml"), "--format", "json"])
    assert cli.exit_code == 0, cli.stderr
    report = json.loads(cli.stdout)           # stdout only: progress lines (after 2 s) go to stderr
    forces = np.concatenate([tau, tau_loaded])
    assert max(report["rms"].values()) < 1e-2 * np.abs(forces).max()
    assert max(report["validation"][0]["rms"].values()) < 1e-2 * np.abs(forces).max()
    # diagnose needs forces: refused without the gains (it had diagnosed zeros), converted with
    # the identify result's when held as given
    refused = CliRunner().invoke(main, ["diagnose", str(tmp_path / "mech.toml"), str(tmp_path / "rec.toml")])
    assert refused.exit_code == 2 and "gain_q1, gain_q2, gain_q3 of these data are unknown" in refused.stderr
    (tmp_path / "id.json").write_text(cli.stdout)
    held = CliRunner().invoke(main, ["diagnose", str(tmp_path / "mech.toml"), str(tmp_path / "rec.toml"),
                                     "--params", str(tmp_path / "id.json"), "--format", "json"])
    assert held.exit_code in (0, 1), held.stderr
    diagnosis = json.loads(held.stdout)
    (note,) = [n for n in diagnosis["notes"] if "converted with the identify result's: gain_q1 = " in n]
    assert abs(float(note.split("gain_q1 = ")[1].split(",")[0]) - 0.7) < 2e-3, note
    assert diagnosis["gap"]["before"] < 1e-2 and not [e for e in diagnosis["effects"] if e["kind"] == "body"]
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "empty.csv"\n' + channels)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    with pytest.raises(InputError, match="known payload"):
        identify(model, data, base=_base(mech))


@pytest.mark.parametrize("delimiter, sep, comment", [("auto", " ", "#"), ("space", "   ", None),
                                                     ("auto", ";", None), ("tab", "\t", "%")])
def test_logs_with_other_delimiters_and_comments(tmp_path, delimiter, sep, comment):
    """Loggers write spaces (UR's RTDE), aligned columns, semicolons, tabs and comment lines."""
    mech = parse_mechanism(_chain(2, bodies=2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    lines = ([f"{comment} logged by a robot", f"{comment} units: rad, N m"] if comment else [])
    lines.append(sep.join(["timestamp", "q_0", "q_1", "tau_0", "tau_1"]))
    lines += [sep.join(f"{v:.17g}" for v in row) for row in np.column_stack([t, motion.q, tau])]
    (tmp_path / "log.txt").write_text("\n".join(lines) + "\n")
    extra = f'delimiter = "{delimiter}"\n' + (f'comment = "{comment}"\n' if comment else "")
    (tmp_path / "rec.toml").write_text(f'[recording]\ntime = "timestamp"\n{extra}[[runs]]\nfile = "log.txt"\n'
                                       '[position]\nq1 = "q_0"\nq2 = "q_1"\n[torque]\nq1 = "tau_0"\nq2 = "tau_1"\n')
    data, model = read_recording(tmp_path / "rec.toml", mech)
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)


def test_long_data_are_built_chunk_by_chunk_with_the_same_result(tmp_path, monkeypatch):
    """Model columns built in chunks (bounded memory on long recordings) reduce to the same
    rows as the whole at once: the margins outlast the zero-phase filter's transient. On the
    real TX40 subset (two runs, filtered and decimated) and a payload run."""
    from baseparams.recordings import data as data_module
    from baseparams.io.loader import load_mechanism
    tx40 = Path(__file__).parent / "data" / "tx40"
    mech = load_mechanism(tx40 / "tx40_mdh_modified.urdf")
    effects = [EffectSpec("viscous_friction", f"joint_{k}") for k in range(1, 7)] + \
        [EffectSpec("coulomb_friction", "motor_6")]
    results = []
    for rows in (data_module.CHUNK_ROWS, 700):
        monkeypatch.setattr(data_module, "CHUNK_ROWS", rows)
        data, model = read_recording(tx40 / "recording.toml", mech)
        assert (data.sample is None) == (rows == 700)
        results.append(identify(model, data, base=_base(mech), effects=effects))
    np.testing.assert_allclose(results[1].estimates, results[0].estimates, rtol=1e-8,
                               atol=1e-10 * np.abs(results[0].estimates).max())
    np.testing.assert_allclose(results[1].residual, results[0].residual, atol=1e-8)


def test_a_gap_in_the_log_splits_the_run(tmp_path):
    """A logger that stopped for 0.5 s: the run is split at the gap and each piece filtered on
    its own (a filter across it would smear the jump), a piece too short for the filter is
    dropped with a note, and the base parameters come back."""
    mech = parse_mechanism(_chain(10))
    phi = random_physical_inertia(mech, np.random.default_rng(10))
    t = np.arange(0, 10, 1 / RATE)
    keep = (t < 4) | ((t > 4.5) & (t < 4.53)) | (t > 5)      # a 30 ms piece between two gaps
    t = t[keep]
    motion, tau = _truth(mech, t, phi)
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert any("split at 2 gap(s)" in n for n in data.notes), data.notes
    assert any("dropped" in n and "too short" in n for n in data.notes), data.notes
    assert len(data.segments) == 2 and data.runs == ("log.csv",)
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)



def test_missing_values_leave_their_samples_out(tmp_path):
    """Empty and NaN fields in the channels used (as a logger that merges topics, or drops a
    packet, writes them): those samples are left out with a note naming the first row; a few
    scattered ones are resampled across, 50 in a row split the run; a NaN in a column the
    description does not use costs nothing; the base parameters come back. An infinite
    value is still an error (test_bad_recordings_are_named)."""
    mech = parse_mechanism(_chain(11))
    phi = random_physical_inertia(mech, np.random.default_rng(11))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    table = np.column_stack([t, *motion.q.T, *tau.T, np.zeros_like(t)]).astype(object)
    table[[700, 2100, 6300], 2] = ""                         # b (q2) empty in three rows
    table[4000:4050, 5] = "NaN"                               # y (tau2) missing for 50 ms
    table[::7, 7] = "nan"                                     # an unused column
    lines = [",".join(v if isinstance(v, str) else f"{v:.17g}" for v in row) for row in table]
    (tmp_path / "log.csv").write_text("t,a,b,c,x,y,z,unused\n" + "\n".join(lines) + "\n")
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert any(n.startswith("53 sample(s) with a missing value") and "first at row 702" in n for n in data.notes), \
        data.notes
    assert any("split at 1 gap(s)" in n for n in data.notes) and any("resampled" in n for n in data.notes)
    assert len(data.segments) == 2
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 2e-3)


@pytest.mark.parametrize("settings", ["", "[filter]\ndecimate = 1\n"], ids=["decimated", "filtered only"])
def test_stated_standard_deviations_match_the_spread_on_filtered_data(tmp_path, settings):
    """Filtered rows are correlated: over 12 noisy recordings the base estimates' errors in
    units of their stated std have an SD near 1 (the classical s^2 (A^T A)^-1 gave 1.3 when
    decimated and 10 when only filtered; the HAC sandwich 1.2 for both)."""
    mech = parse_mechanism(_chain(3))
    phi = random_physical_inertia(mech, np.random.default_rng(3))
    base = _base(mech)
    truth = base.values(phi)
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    sd = 0.02 * np.abs(tau).max(axis=0)
    z = []
    for seed in range(12):
        noisy = tau + np.random.default_rng(seed).normal(0, 1, tau.shape) * sd
        _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *noisy.T])
        (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n' + settings + '[[runs]]\nfile = "log.csv"\n'
                                           + CHANNELS_ABC)
        data, model = read_recording(tmp_path / "rec.toml", mech)
        result = identify(model, data, base=base)
        z.append((result.base_estimates - truth) / result.std[:base.rank])
    spread = np.std(z, axis=0)
    assert 0.7 < np.median(spread) < 1.5, spread


@pytest.mark.parametrize("still", ["constant", "jitter"])
def test_a_joint_held_still_does_not_set_the_filter(tmp_path, still):
    """A joint that does not move (a gripper held still: constant, or an encoder jittering by
    a count or two) has a flat spectrum; the positions' bandwidth, and so the low-pass and
    the decimation, are the moving joints'. (One still Panda finger made the bandwidth 12 Hz
    instead of 0.57: the filter kept 121 Hz, the decimation was 3 instead of 70, every
    joint's residual was 3.5 times its noise and diagnose took 28 s instead of 5.)"""
    from baseparams.recordings.data import bandwidth
    mech = parse_mechanism(_chain(12))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, random_physical_inertia(mech, np.random.default_rng(12)))
    q = motion.q.copy()
    rng = np.random.default_rng(3)
    q[:, 2] = 0.3 if still == "constant" else 0.3 + 1e-5 * np.round(rng.standard_normal(len(t)) * 1.5)
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    moving = bandwidth(motion.q[:, :2], 1 / RATE)
    assert 0 < moving < 2.0
    assert any(f"positions' bandwidth {moving:.3g} Hz" in n for n in data.notes), data.notes
    assert bandwidth(q, 1 / RATE) == moving
    # alone, a still coordinate keeps the old answer: 0 when constant, its noise's band else
    assert bandwidth(q[:, 2:], 1 / RATE) == (0.0 if still == "constant" else pytest.approx(0.5 * RATE, rel=0.05))


def test_a_logs_columns_no_channel_uses_are_not_read(tmp_path, monkeypatch):
    """A robot's log has many columns a description does not use, some of them text (a UR's
    RTDE log: robot mode, safety status): they are not read, so their content is no error
    and costs no memory; the columns used come back exactly, parsed in batches of rows; a
    bad field in a used column still names its row and column, in whichever batch."""
    from baseparams.recordings import delimited
    mech = parse_mechanism(_chain(11))
    phi = random_physical_inertia(mech, np.random.default_rng(11))
    t = np.arange(0, 4, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    table = np.column_stack([t, *motion.q.T, *tau.T, np.arange(len(t))])
    lines = ["t,a,b,c,x,y,z,counter,robot_mode,comment"]
    lines += [",".join(f"{v:.17g}" for v in row) + ",RUNNING,ok; 1_0 inf" for row in table]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    whole, _ = read_recording(tmp_path / "rec.toml", mech)
    monkeypatch.setattr(delimited, "PARSE_BATCH_ROWS", 7)
    batched, model = read_recording(tmp_path / "rec.toml", mech)
    assert np.array_equal(batched.motion.q, whole.motion.q) and np.array_equal(batched.tau, whole.tau)
    # the columns read are the columns written, to the last bit (before any filtering)
    header, values, rows = delimited.read_columns("log.csv", (tmp_path / "log.csv").read_text(),
                                                    wanted={"t", "a", "z"})
    assert header[-1] == "comment" and set(values) == {"t", "a", "z"} and rows[:2] == [2, 3]
    assert np.array_equal(values["a"], motion.q[:, 0]) and np.array_equal(values["z"], tau[:, 2])
    result = identify(model, batched, base=_base(mech))
    _check_base(result, _base(mech), phi, 1e-3)
    # a bad field in a used column, in a later batch: its row and column
    lines[1000] = lines[1000].replace(lines[1000].split(",")[5], "1_0", 1)
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key == "row 1001, column y" and "not a number" in str(error.value)


def test_files_on_their_own_clocks_are_read_on_the_torques_clock(tmp_path):
    """A logger that writes one file per topic stamps each on arrival: the torques' file has
    its own time column, other stamps and another row count. With ``time`` in every file, the
    positions are interpolated onto the torques' clock (cubic; samples outside their span left
    out) and the base parameters come back; files that share one clock read as one file."""
    mech = parse_mechanism(_chain(12))
    phi = random_physical_inertia(mech, np.random.default_rng(12))
    rng = np.random.default_rng(3)
    t = np.arange(0, 8, 1 / RATE)
    motion, _ = _truth(mech, t, phi)
    grid = np.arange(0, 7.9, 1 / 700)
    stamps = 0.013 + grid + rng.uniform(0, 2e-4, len(grid))   # 700 Hz, late by 13 ms, jittered
    _, tau_own = _truth(mech, stamps, phi)                  # the torques at their own stamps (700 Hz)
    _write(tmp_path / "joints.csv", ["stamp", "a", "b", "c"], [t, *motion.q.T])
    _write(tmp_path / "effort.csv", ["stamp", "x", "y", "z", "mode"], [stamps, *tau_own.T, np.zeros(len(stamps))])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "stamp"\n[[runs]]\n'
                                       'files = { pos = "joints.csv", eff = "effort.csv" }\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert any("joints.csv: its columns interpolated onto the clock of effort.csv" in n for n in data.notes)
    assert data.motion.t[0] >= stamps[0] - 1e-12 and data.motion.t[-1] <= stamps[-1] + 1e-12
    np.testing.assert_allclose(np.diff(data.motion.t).min(), np.diff(stamps).min(), rtol=1e-9)   # the torques' own
    result = identify(model, data, base=_base(mech))
    _check_base(result, _base(mech), phi, 5e-3)
    later = t >= 0.5                                    # positions from 0.5 s: the torques before are left out
    _write(tmp_path / "joints.csv", ["stamp", "a", "b", "c"], [t[later], *motion.q[later].T])
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert any("joints.csv" in n and "outside its span left out" in n for n in data.notes), data.notes
    assert data.motion.t[0] >= 0.5
    # positions split over the files: the first file's positions interpolated onto the second's clock
    motion_own, _ = _truth(mech, stamps, phi)
    _write(tmp_path / "joints.csv", ["stamp", "a"], [t, motion.q[:, 0]])
    _write(tmp_path / "effort.csv", ["stamp", "b", "c", "x", "y", "z"], [stamps, *motion_own.q[:, 1:].T, *tau_own.T])
    data, model = read_recording(tmp_path / "rec.toml", mech)
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 5e-3)
    _write(tmp_path / "joints.csv", ["stamp", "a", "b", "c"], [t, *motion.q.T])
    # the same clock in both files (a logger that stamps both alike): read as before, no note
    _, tau = _truth(mech, t, phi)
    _write(tmp_path / "effort.csv", ["stamp", "x", "y", "z"], [t, *tau.T])
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert not any("interpolated" in n for n in data.notes)
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)
    # files of different lengths without a clock each: refused, saying how they would be read
    _write(tmp_path / "effort.csv", ["x", "y", "z"], [*tau_own.T])
    with pytest.raises(InputError, match="must have the same rows .* or each its own time column"):
        read_recording(tmp_path / "rec.toml", mech)
    # a clock that goes back in the other file names its row there
    stamps[100] = stamps[98]
    _write(tmp_path / "effort.csv", ["stamp", "x", "y", "z", "mode"], [stamps, *tau_own.T, np.zeros(len(stamps))])
    with pytest.raises(InputError) as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key == "row 102, column stamp" and error.value.file.endswith("effort.csv")


def test_samples_stamped_twice_are_left_out_and_a_clock_going_back_is_an_error(tmp_path):
    """A logger that writes a sample twice, or stamps two samples alike: each sample with the
    time of the one before is left out with a note (a zero step cannot be differentiated) and
    the base parameters come back; a time that goes back is still an error naming its row."""
    mech = parse_mechanism(_chain(13))
    phi = random_physical_inertia(mech, np.random.default_rng(13))
    t = np.arange(0, 8, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    table = np.column_stack([t, *motion.q.T, *tau.T])
    twice = np.sort(np.random.default_rng(4).choice(np.arange(10, len(t) - 10), 25, replace=False))
    rows = np.insert(table, twice + 1, table[twice], axis=0)          # 25 rows written twice
    rows[twice[0] + 1, 1:] += 0.5                                      # one of them with other values
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], rows.T)
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    (note,) = [n for n in data.notes if "stamped with the time of the sample before" in n]
    assert note.startswith("25 sample(s)") and f"first at row {twice[0] + 3}" in note, note
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)
    rows[500, 0] = rows[498, 0]
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], rows.T)
    with pytest.raises(InputError, match="does not increase") as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key in ("row 502", "row 501"), error.value.key


def test_an_angle_logged_modulo_a_turn_is_unwrapped(tmp_path):
    """An encoder or a topic that logs an angle modulo 2 pi jumps by a turn where the joint
    passes pi: the jumps are undone (a note gives their count and first row) and the base
    parameters come back; a length is never unwrapped."""
    mech = parse_mechanism(_chain(14))
    phi = random_physical_inertia(mech, np.random.default_rng(14))
    t = np.arange(0, 8, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    shift = np.pi - np.median(motion.q[:, 0])                    # the first joint swings about pi
    wrapped = np.angle(np.exp(1j * (motion.q[:, 0] + shift)))
    jumps = np.flatnonzero(np.abs(np.diff(wrapped)) > np.pi) + 1
    assert jumps.size >= 2
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, wrapped, *motion.q[:, 1:].T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC
                                       + f"[zero]\nq1 = {-float(shift)!r}\n")
    data, model = read_recording(tmp_path / "rec.toml", mech)
    (note,) = [n for n in data.notes if "unwrapped" in n]
    assert note.startswith(f"q1: {jumps.size} jump(s) of a turn") and f"first at row {jumps[0] + 2}" in note, note
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)


def test_a_time_column_of_dates_and_times(tmp_path):
    """A logger that stamps its rows with ISO 8601 dates and times (``time_unit = "iso"``):
    read as seconds, the base parameters come back; a stamp that is not one names its row."""
    mech = parse_mechanism(_chain(15))
    phi = random_physical_inertia(mech, np.random.default_rng(15))
    t = np.arange(0, 8, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    start = np.datetime64("2026-11-26T09:59:58.5", "ns")
    stamps = [str(start + np.timedelta64(int(round(v * 1e9)), "ns")).replace("T", " ") for v in t]
    stamps[1::2] = [s + "Z" for s in stamps[1::2]]                  # UTC marked or not
    lines = ["stamp,a,b,c,x,y,z"] + [",".join([s] + [f"{v:.17g}" for v in row])
                                     for s, row in zip(stamps, np.column_stack([motion.q, tau]))]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "stamp"\ntime_unit = "iso"\n[[runs]]\nfile = "log.csv"\n'
                                       + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    # seconds since the first stamp, exact to the nanosecond (since 1970 they would be rounded)
    assert data.motion.t[0] == 0 and np.abs(data.motion.t - t).max() < 1e-12
    assert not any("resampled" in n for n in data.notes), data.notes
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "stamp"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    with pytest.raises(InputError, match='a date and time: a recording reads them with time_unit = "iso"'):
        read_recording(tmp_path / "rec.toml", mech)               # without time_unit: the way out
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "stamp"\ntime_unit = "iso"\n[[runs]]\nfile = "log.csv"\n'
                                       + CHANNELS_ABC)
    lines[300] = "yesterday" + lines[300][lines[300].index(","):]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="not a date and time") as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key == "row 301, column stamp"


def _array_logs(tmp_path, mech, phi):
    """The same samples as a CSV log, a NumPy .npz (q saved channels x samples) and a MATLAB
    .mat with a struct ``log``; a description for each."""
    import scipy.io
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    np.savez(tmp_path / "log.npz", t=t, q=motion.q.T, tau=tau, note=np.array("a text variable"))
    scipy.io.savemat(tmp_path / "log.mat", {"log": {"t": t, "q": motion.q, "tau": tau, "robot": "R3"}})
    (tmp_path / "csv.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    arrays = '[position]\nq1 = "{p}q[0]"\nq2 = "{p}q[1]"\nq3 = "{p}q[2]"\n[torque]\nq1 = "{p}tau[0]"\n' \
             'q2 = "{p}tau[1]"\nq3 = "{p}tau[2]"\n'
    (tmp_path / "npz.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.npz"\n' + arrays.format(p=""))
    (tmp_path / "mat.toml").write_text('[recording]\ntime = "log.t"\n[[runs]]\nfile = "log.mat"\n'
                                       + arrays.format(p="log."))


def test_logs_saved_as_npz_or_mat_arrays_read_as_their_csv(tmp_path):
    """A .npz (a 2-D variable saved either way round: ``q[0]``..) and a MATLAB .mat (a struct's
    fields: ``log.q[0]``) read as named columns: identify gives the CSV log's estimates to
    the last bit (the CSV holds the same float64 values)."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    _array_logs(tmp_path, mech, phi)
    results = {}
    for kind in ("csv", "npz", "mat"):
        data, model = read_recording(tmp_path / f"{kind}.toml", mech)
        results[kind] = identify(model, data, base=_base(mech)).estimates
    np.testing.assert_array_equal(results["npz"], results["csv"])
    np.testing.assert_array_equal(results["mat"], results["csv"])
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)


@pytest.mark.parametrize("change, message", [
    ("column", "no column 'q[3]' (columns: t, q[0], q[1], q[2], tau[0], tau[1], tau[2])"),
    ("inf", "row 5, column q[1]: inf is not a finite number"),
    ("lengths", "the columns used have different lengths"),
    ("text", "column q[0]: holds <U1 values, not numbers"),
    ("corrupt", "cannot read as a NumPy .npz file"),
    ("v73", "a MATLAB v7.3 (HDF5) file, which is not read: save it with -v7"),
    ("direct", "a log saved as arrays is read through a recording description"),
])
def test_a_bad_array_log_is_bad_input_naming_what(tmp_path, change, message):
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    _array_logs(tmp_path, mech, phi)
    arrays = dict(np.load(tmp_path / "log.npz"))
    description = "npz.toml"
    if change == "column":
        (tmp_path / "npz.toml").write_text((tmp_path / "npz.toml").read_text().replace('"q[2]"', '"q[3]"'))
    elif change == "inf":
        arrays["q"][1, 4] = np.inf
    elif change == "lengths":
        arrays["tau"] = arrays["tau"][:-1]
    elif change == "text":
        arrays["q"] = np.full(arrays["q"].shape, "x")
    if change in ("inf", "lengths", "text"):
        np.savez(tmp_path / "log.npz", **arrays)
    if change == "corrupt":
        (tmp_path / "log.npz").write_bytes(b"PK\x03\x04 not a zip archive")
    if change == "v73":
        (tmp_path / "log.mat").write_bytes(b"MATLAB 7.3 MAT-file".ljust(128, b" ") + b"\x89HDF\r\n" + bytes(400))
        description = "mat.toml"
    if change == "direct":
        description = "log.npz"
    (tmp_path / "mech.toml").write_text(_chain(2))
    result = CliRunner().invoke(main, ["identify", str(tmp_path / "mech.toml"), str(tmp_path / description),
                                       "--quiet"])
    assert result.exit_code == 2, result.output + result.stderr
    assert message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("position, torque, to_position, to_torque", [
    ("rev", '{ column = "x", unit = "mA", gain = 2.5 }', 1 / (2 * np.pi), 1000 / 2.5),
    ("deg", '{ column = "x", unit = "Nm" }', 180 / np.pi, 1.0),
    ("rad", '{ column = "x", unit = "N mm" }', 1.0, 1000.0),
])
def test_units_of_positions_and_torques_read_as_the_model_s(tmp_path, position, torque, to_position, to_torque):
    """A log in turns and milliamperes (a drive's), in degrees and 'Nm', in N mm: read as in
    radians and N m (q1's channels in those units, the others in the model's)."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    q, f = motion.q.copy(), tau.copy()
    q[:, 0] *= to_position
    f[:, 0] *= to_torque
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *q.T, *f.T])
    (tmp_path / "units.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n'
                                         + CHANNELS_ABC.replace('q1 = "a"', f'q1 = {{ column = "a", unit = "{position}" }}')
                                         .replace('q1 = "x"', f"q1 = {torque}"))
    _write(tmp_path / "plain.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    (tmp_path / "plain.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "plain.csv"\n' + CHANNELS_ABC)
    read, _ = read_recording(tmp_path / "units.toml", mech)
    plain, _ = read_recording(tmp_path / "plain.toml", mech)
    np.testing.assert_allclose(read.motion.q, plain.motion.q, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(read.tau, plain.tau, rtol=1e-9, atol=1e-9 * np.abs(plain.tau).max())


def test_a_log_printed_to_six_decimals_is_not_taken_as_quantised(tmp_path):
    """Values printed with 6 decimals lie on a grid of 1e-6, a millionth of their size or
    less: not rounding a diagnosis must allow for, and no note says so."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    table = np.column_stack([t, motion.q, tau * 10.0])
    np.savetxt(tmp_path / "log.csv", table, delimiter=",", header="t,a,b,c,x,y,z", comments="", fmt="%.6f")
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC)
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert data.quanta is None and not any("quantised" in n for n in data.notes), data.notes


def test_a_logged_velocity_that_lags_the_positions_is_noted(tmp_path):
    """A controller's velocity, a first-order filter of the position difference (the TIAGo's:
    v = 0.95 v + 0.05 dq/dt at 100 Hz, a 0.19 s time constant): the note says it differs from
    the positions' derivative and lags by about the time constant; the exact velocity gives
    no note."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 30, 0.01)
    motion, tau = _truth(mech, t, phi)
    lagged = np.zeros_like(motion.q)
    for i in range(1, len(t)):
        lagged[i] = 0.95 * lagged[i - 1] + 0.05 * (motion.q[i] - motion.q[i - 1]) / 0.01
    notes = {}
    for name, velocity in (("exact", motion.qd), ("lagged", lagged)):
        _write(tmp_path / f"{name}.csv", ["t", "a", "b", "c", "va", "vb", "vc", "x", "y", "z"],
               [t, *motion.q.T, *velocity.T, *tau.T])
        (tmp_path / f"{name}.toml").write_text(f'[recording]\ntime = "t"\n[[runs]]\nfile = "{name}.csv"\n'
                                               + CHANNELS_ABC + '[velocity]\nq1 = "va"\nq2 = "vb"\nq3 = "vc"\n')
        data, _ = read_recording(tmp_path / f"{name}.toml", mech)
        notes[name] = [n for n in data.notes if n.startswith("measured velocities differ")]
    assert notes["exact"] == []
    [note] = notes["lagged"]
    lags = [float(m) for m in re.findall(r"lags by ([\d.]+) ms", note)]
    assert len(lags) == 3 and all(150 <= lag <= 230 for lag in lags), note


def test_a_log_of_merged_topics_is_read_on_the_torques_rows(tmp_path):
    """A logger that merges topics into one table fills each row from one topic: positions on
    even rows, torques on odd ones, the rest empty. Every row missed a channel and all were
    left out ("0 samples"); now the torques' rows are the samples and the positions are
    interpolated onto their times (cubic): the base parameters come back as from a full log.
    A column missing on a few rows (a dropped packet) still leaves those samples out."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    q, f = motion.q.copy(), tau.copy()
    q[1::2], f[0::2] = np.nan, np.nan
    _write(tmp_path / "merged.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *q.T, *f.T])
    text = (tmp_path / "merged.csv").read_text().replace("nan", "")
    (tmp_path / "merged.csv").write_text(text)
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "merged.csv"\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert any("topics merged into one table" in n and "read on the 5000 rows of x, y, z" in n for n in data.notes)
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)
    sporadic = tau.copy()
    sporadic[100:103] = np.nan                         # three dropped packets: left out, not filled
    _write(tmp_path / "merged.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *sporadic.T])
    (tmp_path / "merged.csv").write_text((tmp_path / "merged.csv").read_text().replace("nan", ""))
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert not any("topics merged" in n for n in data.notes)
    assert any("3 sample(s) with a missing value" in n for n in data.notes), data.notes


def test_torques_on_their_own_clock_are_not_interpolated_across_friction_jumps(tmp_path):
    """Positions at 1 kHz and torques with Coulomb friction at 100 Hz, jittered, each file on
    its own clock: read on the torques' clock, the fit is as good as one regular log's (read
    on the positions' clock, the torques interpolated across each reversal's jump left a
    residual 130 times larger)."""
    mech = parse_mechanism(_chain(4))
    phi = random_physical_inertia(mech, np.random.default_rng(4))
    friction = [EffectSpec("coulomb_friction", c, {"fc": 0.3}) for c in ("q1", "q2", "q3")]
    rng = np.random.default_rng(5)
    t = np.arange(0, 20, 1 / RATE)
    motion, _ = _truth(mech, t, phi, friction)
    stamps = np.cumsum(np.clip(0.01 + 0.0012 * rng.standard_normal(2100), 0.0077, 0.0123))
    stamps = stamps[stamps < 19.9]
    _, tau = _truth(mech, stamps, phi, friction)
    _write(tmp_path / "joints.csv", ["stamp", "a", "b", "c"], [t, *motion.q.T])
    _write(tmp_path / "effort.csv", ["stamp", "x", "y", "z"], [stamps, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "stamp"\n[[runs]]\n'
                                       'files = { pos = "joints.csv", eff = "effort.csv" }\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    effects = [EffectSpec(e.kind, e.coordinate) for e in friction]
    result = identify(model, data, base=_base(mech), effects=effects)
    np.testing.assert_allclose(result.estimates[np.array(result.kinds) != "base"], 0.3, rtol=3e-3)
    motion_own, tau_own = _truth(mech, stamps, phi, friction)
    _write(tmp_path / "one.csv", ["stamp", "a", "b", "c", "x", "y", "z"], [stamps, *motion_own.q.T, *tau_own.T])
    (tmp_path / "one.toml").write_text('[recording]\ntime = "stamp"\n[[runs]]\nfile = "one.csv"\n' + CHANNELS_ABC)
    one, one_model = read_recording(tmp_path / "one.toml", mech)
    reference = identify(one_model, one, base=_base(mech), effects=effects).nrms.max()
    assert result.nrms.max() < 3 * reference + 1e-4, (result.nrms.max(), reference)


def test_a_robot_mounted_tilted_is_read_with_the_descriptions_gravity(tmp_path):
    """A robot mounted on a wall or at an angle: its model (a URDF) has gravity along -z of
    its base, the recording does not. ``[recording] gravity`` (the base's axes) gives the
    mounting: the base parameters of the tilted mechanism come back; without it the fit
    misses by far."""
    text = _chain(2)
    upright = parse_mechanism(text)
    assert 'gravity = ["0", "0", "-9.81"]' in text
    tilted = parse_mechanism(text.replace('gravity = ["0", "0", "-9.81"]', 'gravity = ["0", "-6.9367", "-6.9367"]'))
    phi = random_physical_inertia(upright, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(tilted, t, phi)
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    plain = '[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS_ABC
    (tmp_path / "plain.toml").write_text(plain)
    (tmp_path / "tilted.toml").write_text(plain.replace('time = "t"\n', 'time = "t"\ngravity = [0, -6.9367, "-6.9367"]\n'))
    data, model = read_recording(tmp_path / "tilted.toml", upright)
    assert model.gravity == tilted.gravity
    _check_base(identify(model, data, base=_base(model)), _base(tilted), phi, 2e-3)
    data, model = read_recording(tmp_path / "plain.toml", upright)
    assert identify(model, data, base=_base(model)).nrms.max() > 0.05
    with pytest.raises(InputError, match="another gravity than the descriptions before it"):
        read_data([str(tmp_path / "tilted.toml"), str(tmp_path / "plain.toml")], upright)


def test_runs_by_rows_split_a_log_whose_clock_was_reset(tmp_path):
    """Two experiments logged end to end, the clock restarting at 0 for the second: the file
    is refused (time goes back) with the way out, and two runs of rows ``[first, last]`` read
    it, each filtered on its own: the base parameters come back."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    a, b = slice(0, 4000), slice(5000, 10000)
    clock = np.concatenate([t[a], t[b] - t[b][0]])        # the second part's clock starts again at 0
    q, f = np.vstack([motion.q[a], motion.q[b]]), np.vstack([tau[a], tau[b]])
    _write(tmp_path / "joined.csv", ["t", "a", "b", "c", "x", "y", "z"], [clock, *q.T, *f.T])
    (tmp_path / "one.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "joined.csv"\n' + CHANNELS_ABC)
    with pytest.raises(InputError, match=r"does not increase .*rows = \[first, last\]") as error:
        read_recording(tmp_path / "one.toml", mech)
    assert error.value.key == "row 4002"
    (tmp_path / "two.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "joined.csv"\nrows = [2, 4001]\n'
                                       '[[runs]]\nfile = "joined.csv"\nrows = [4002, 9001]\n' + CHANNELS_ABC)
    data, model = read_recording(tmp_path / "two.toml", mech)
    assert len(data.runs) == 2
    _check_base(identify(model, data, base=_base(mech)), _base(mech), phi, 2e-3)
