"""The traps of real logs (issue 48), read side: a torque channel without signal, a motion the
automatic filter misread (a trapezoid, a ramp, a single joint moving), a joint that never
moves, a time column of sample indices. Each on data made with a known truth and on a
decimated subset of a real Kinova Gen3 recording (tests/data/kinova_gen3, README there):
every trap is refused with one line naming the file, the key and the reason (exit 2), or
read right with a note."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError
from baseparams.identify.base import BaseModel
from baseparams.recordings.data import bandwidth
from baseparams.identify.fit import identify, predict
from baseparams.dynamics.forces import Motion, design, effect_values
from baseparams.recordings.recording import read_data, read_recording
from baseparams.recordings.simulate import random_physical_inertia
from baseparams.io.loader import load_mechanism, parse_mechanism
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec
from baseparams.numeric.backends import Float64

KINOVA = Path(__file__).parent / "data" / "kinova_gen3"
RATE = 1000.0
JOINTS = range(1, 8)


def _kinova(tmp_path: Path, runs: str, torque: str = "TorqueSm", head: str = 'time = "Time"\ntime_unit = "samples"\n'
            'rate = 1000\n', extra: str = "") -> Path:
    """A description of the Kinova subset's files (every second row of the 1 kHz logs; Time
    is the original sample index)."""
    position = "".join(f'joint_{j} = "Position{j}"\n' for j in JOINTS)
    torques = "".join(f'joint_{j} = "{torque}{j}"\n' for j in JOINTS)
    path = tmp_path / "kinova.toml"
    path.write_text(f"[recording]\n{head}{runs}[position]\n{position}[torque]\n{torques}{extra}")
    return path


def _run(name: str, skip: str = "") -> str:
    return f'[[runs]]\nname = "{name}"\nfile = "{(KINOVA / name).as_posix()}.csv"\n{skip}'


@pytest.fixture(scope="module")
def gen3():
    return load_mechanism(str(KINOVA / "gen3.urdf"))


@pytest.fixture(scope="module")
def gen3_base(gen3):
    return BaseModel.from_result(registry.solvers()["dp"].item.solve(gen3), gen3)


# ----- dead torque channels ------------------------------------------------------------------
def test_kinova_dead_joint_sensor_is_refused_naming_run_channel_and_share(tmp_path):
    """RunTrajectory1's joint-1 torque sensor is 0 in every row: one line, exit 2, naming the
    description, the channel's key, the run, the column and the share, and the ways out."""
    path = _kinova(tmp_path, _run("RunTrajectory1"))
    result = CliRunner().invoke(main, ["identify", str(KINOVA / "gen3.urdf"), str(path), "--solver", "dp"])
    assert result.exit_code == 2, result.output
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith(f"error: {path}: torque.joint_1: run 'RunTrajectory1': joint_1 (column 'TorqueSm1') "
                           "is 0 in 100 % of its 971 rows"), line
    assert 'skip = ["joint_1"]' in line and 'dead = "skip"' in line and "joint_2" not in line.partition(":")[2][:60]


def test_kinova_dead_sensor_left_out_of_its_run_the_others_fitted(tmp_path, gen3, gen3_base):
    """skip = ["joint_1"]: RunTrajectory1's joints 2-7 join the fit; joint 1's rows of that run
    are not fitted (torque and model columns zero there), its motion still drives the others;
    the prediction says joint 1 is not measured instead of "NRMS 0"."""
    path = _kinova(tmp_path, _run("opti_traj_testing2") + _run("RunTrajectory1", 'skip = ["joint_1"]\n'))
    data, model = read_data([str(path)], gen3)
    rows = data.measured()
    run = data.run_of_row()
    assert not rows[run == 1, 0].any() and rows[run == 1, 1:].all() and rows[run == 0].all()
    assert np.all(data.tau[run == 1, 0] == 0)
    assert any("no measured force on joint_1 in run 'RunTrajectory1'" in n for n in data.notes)
    result = identify(model, data, base=gen3_base,
                      effects=[EffectSpec(k, f"joint_{j}") for k in ("coulomb_friction", "viscous_friction")
                               for j in JOINTS])
    assert np.all(result.residual[run == 1, 0] == 0)           # nothing fitted there
    assert np.all(np.isfinite(result.estimates))
    # the same run alone, predicted by that model: joint 1 unmeasured, the others sane
    alone, _ = read_data([str(_kinova(tmp_path, _run("RunTrajectory1", 'skip = ["joint_1"]\n')))], gen3)
    prediction = predict(result, model, alone)
    assert prediction.unmeasured == ("joint_1",)
    assert "joint_1: not measured" in prediction.to_text()
    assert prediction.to_json()["unmeasured"] == ["joint_1"]
    assert prediction.nrms[1:].max() < 1.0


def test_kinova_dead_channels_skipped_by_policy_and_all_dead_refused(tmp_path, gen3):
    """dead = "skip" leaves every channel without signal out of its run, with a note naming
    it and its share; a run with no channel left is refused."""
    head = 'time = "Time"\ntime_unit = "samples"\nrate = 1000\ndead = "skip"\n'
    data, _ = read_recording(_kinova(tmp_path, _run("RunTrajectory1"), head=head), gen3)
    assert data.segments[0].skip == (0,)
    assert any("left out of run 'RunTrajectory1'" in n and "joint_1 (column 'TorqueSm1') is 0 in 100 %" in n
               for n in data.notes)
    for name in ("Trajectory1", "joint_2_trapez"):                   # every sensor torque 0
        with pytest.raises(InputError, match=f"no torque is measured in run '{name}'"):
            read_recording(_kinova(tmp_path, _run(name), head=head), gen3)


def test_kinova_trajectory1_sensor_torques_are_refused(tmp_path, gen3):
    """Trajectory1's sensor torques are all 0 (it said "noise SD 1e-100", NRMS 0, exit 0):
    refused, every channel named with its share, the first channel's key."""
    with pytest.raises(InputError) as error:
        read_recording(_kinova(tmp_path, _run("Trajectory1")), gen3)
    assert error.value.key == "torque.joint_1"
    assert all(f"joint_{j} (column 'TorqueSm{j}') is 0 in 100 % of its 486 rows" in error.value.reason
               for j in JOINTS), error.value.reason


def _chain(seed: int, bodies: int = 3) -> str:
    return generate.serial_chain(seed, bodies=bodies, types="R")


def _truth(mech, t, phi, effects=(), still: tuple[int, ...] = ()):
    """Exact motion and forces at the times ``t`` (the mechanism's trajectory; the ``still``
    coordinates held at their first value)."""
    z, zd, zdd = Trajectory.default(mech).independent_values(mech, Float64(), np.asarray(t, float))
    q, qd, qdd = (np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in a], axis=1).copy()
                  for a in (z, zd, zdd))
    for j in still:
        q[:, j], qd[:, j], qdd[:, j] = q[0, j], 0.0, 0.0
    motion = Motion(np.asarray(t, float), q, qd, qdd)
    inertial, columns = design(mech, motion, effects)
    tau = inertial.matrix @ phi
    if effects:
        tau = tau + columns.matrix @ effect_values(mech, effects)
    return motion, tau


def _write(path: Path, header, columns) -> None:
    table = np.column_stack(columns)
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in table) + "\n")


CHANNELS = '[position]\nq1 = "a"\nq2 = "b"\nq3 = "c"\n[torque]\nq1 = "x"\nq2 = "y"\nq3 = "z"\n'


def _two_runs(tmp_path, seed: int = 4, dead_share: float = 1.0):
    """A 3R chain's two runs (0-6 s and 6-12 s of its trajectory), q1's torque dead in the
    second (0 in ``dead_share`` of its rows)."""
    mech = parse_mechanism(_chain(seed))
    phi = random_physical_inertia(mech, np.random.default_rng(seed))
    for k, (a, b) in enumerate(((0, 6), (6, 12))):
        t = np.arange(a, b, 1 / RATE)
        motion, tau = _truth(mech, t, phi)
        if k == 1:
            dead = np.random.default_rng(1).random(len(t)) < dead_share
            tau[dead, 0] = 0.0
        _write(tmp_path / f"run{k}.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    return mech, phi


@pytest.mark.parametrize("how", ["skip", "policy"])
def test_a_dead_channel_left_out_of_one_run_the_truth_comes_back(tmp_path, how):
    """Known truth: run 2's q1 torque is zero throughout. Refused as it is; left out (skip,
    or dead = "skip"), the base parameters come back from run 1 and run 2's q2, q3 as when
    the channel was good. Fitted as measured (the old way) they did not."""
    mech, phi = _two_runs(tmp_path)
    runs = '[[runs]]\nname = "one"\nfile = "run0.csv"\n[[runs]]\nname = "two"\nfile = "run1.csv"\n'
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n' + runs + CHANNELS)
    with pytest.raises(InputError) as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key == "torque.q1" and "run 'two': q1 (column 'x') is 0 in 100 % of its 6000 rows" in \
        error.value.reason
    skip, policy = ('skip = ["q1"]\n', "") if how == "skip" else ("", 'dead = "skip"\n')
    (tmp_path / "rec.toml").write_text(f'[recording]\ntime = "t"\n{policy}' + runs + skip + CHANNELS)
    data, model = read_recording(tmp_path / "rec.toml", mech)
    assert data.masked and not data.measured()[data.run_of_row() == 1, 0].any()
    base = BaseModel.from_result(registry.solvers()["dp"].item.solve(mech), mech)
    result = identify(model, data, base=base)
    truth = base.values(phi)
    assert np.abs(result.base_estimates - truth).max() / np.abs(truth).max() < 2e-3
    # the model columns of run 2's q1 rows are zero, not only its torque
    full = data.reduce(np.ones((data.motion.count, 3, 2)))
    assert np.all(full[data.run_of_row() == 1, 0] == 0) and np.allclose(full[data.run_of_row() == 0], 1)
    assert np.allclose(full[data.run_of_row() == 1, 1:], 1)


def test_a_channel_zero_in_most_rows_is_dead_and_a_channel_none_is_never_read(tmp_path):
    """A channel 0 in 85 % of its rows (a TIAGo's wrist efforts: no signal) is dead; q1 =
    "none" in [torque] leaves q1's force out of every run, and its column is not read."""
    mech, _ = _two_runs(tmp_path, dead_share=0.85)
    runs = '[[runs]]\nname = "one"\nfile = "run0.csv"\n[[runs]]\nname = "two"\nfile = "run1.csv"\n'
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n' + runs + CHANNELS)
    with pytest.raises(InputError, match=r"run 'two': q1 \(column 'x'\) is 0 in 8[45]\.\d+ % of its 6000 rows"):
        read_recording(tmp_path / "rec.toml", mech)
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n' + runs + CHANNELS.replace('q1 = "x"', 'q1 = "none"'))
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert not data.measured()[:, 0].any() and data.measured()[:, 1:].all()
    assert all(s.skip == (0,) for s in data.segments)
    (tmp_path / "m.toml").write_text(_chain(4))               # KIND:* leaves the unmeasured q1 out
    result = CliRunner().invoke(main, ["identify", str(tmp_path / "m.toml"), str(tmp_path / "rec.toml"), "--solver",
                                       "dp", "--effect", "viscous_friction:*", "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert {c["name"] for e in out["effects"] for c in e["coefficients"]} == {"fv_q2", "fv_q3"}
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n' + runs + 'skip = ["q9"]\n' + CHANNELS)
    with pytest.raises(InputError, match="'q9' is not a torque channel") as error:
        read_recording(tmp_path / "rec.toml", mech)
    assert error.value.key == "runs[1].skip[0]"


# ----- the automatic filter ---------------------------------------------------------------
def test_bandwidth_of_a_noisy_trapezoid_and_ramp_is_the_motions():
    """A trapezoidal velocity profile (a ramp of position between rests) with an encoder's
    noise: the old 99.99 % rule found the noise's band (hundreds of Hz); the spectrum above
    the noise gives the motion's, a few Hz. A clean multisine keeps its highest frequency."""
    t = np.arange(0, 4, 1 / RATE)
    speed = np.clip(np.minimum(t - 0.5, 3.0 - t) / 0.3, 0, 1)        # up 0.3 s, cruise, down 0.3 s
    q = np.cumsum(speed) / RATE
    rng = np.random.default_rng(0)
    noisy = q + 2e-6 * rng.standard_normal(len(t))
    band = bandwidth(noisy[:, None], 1 / RATE)
    assert 0.5 < band < 10.0, band
    still = 1e-6 * np.round(rng.standard_normal(len(t)))              # a joint at rest: encoder ticks
    assert bandwidth(np.column_stack([noisy, still]), 1 / RATE) == band
    clean = sum(np.sin(2 * np.pi * f * t) / f for f in (0.5, 1.0, 2.0, 3.0))
    assert bandwidth(clean[:, None], 1 / RATE) == pytest.approx(3.0, abs=1.0)


def test_kinova_single_joint_and_ramp_files_are_filtered_by_default(tmp_path):
    """On the Kinova's joint-2 trapezoid and on RunTrajectory1 (joint 1 ramps from -pi/2) the
    positions' bandwidth was 250 and 144 Hz on this subset (500 and 223 Hz at 1 kHz), so
    nothing was filtered; now 2-6 Hz, a cut-off of 20-60 Hz (20 Hz by hand gave sane fits)."""
    for name, torque, skip in (("joint_2_trapez", "TorqueCur", ""), ("RunTrajectory1", "TorqueSm",
                                                                     'skip = ["joint_1"]\n')):
        path = _kinova(tmp_path, _run(name, skip), torque=torque)
        data, _ = read_recording(path, load_mechanism(str(KINOVA / "gen3.urdf")))
        note = next(n for n in data.notes if "low-passed at" in n)
        cutoff = float(note.split("low-passed at ")[1].split(" Hz")[0])
        assert 20 <= cutoff <= 60, note


def test_kinova_joints_that_never_move_get_no_friction(tmp_path, gen3, gen3_base):
    """joint_2_trapez moves joint 2 only (the others within 0.24 mrad, two not at all): they
    are held still (velocity and acceleration exactly 0, a note), so KIND:* leaves their
    friction out; before, joint 7 got fv = -1.4e18 +- 1.4e17 with exit 0."""
    path = _kinova(tmp_path, _run("joint_2_trapez"), torque="TorqueCur")
    result = CliRunner().invoke(main, ["identify", str(KINOVA / "gen3.urdf"), str(path), "--solver", "dp",
                                       "--effect", "coulomb_friction:*", "--effect", "viscous_friction:*",
                                       "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    coefficients = {c["name"]: c["value"] for e in out["effects"] for c in e["coefficients"]}
    assert set(coefficients) == {"fc_joint_2", "fv_joint_2"}, coefficients
    assert all(abs(v) < 100 for v in coefficients.values()), coefficients
    assert any("held still in run" in n and "joint_7 (0 rad)" in n and "joint_4 (0.000235 rad)" in n
               for n in out["notes"])


def test_a_joint_held_still_in_a_simulated_log_has_velocity_zero(tmp_path):
    """Known truth: q3 held at its first value; q1, q2 move. q3's velocity and acceleration
    are exactly 0 after the filter (not rounding noise), q1 and q2's viscous friction comes
    back and q3's is left out by KIND:*."""
    mech = parse_mechanism(_chain(7))
    phi = random_physical_inertia(mech, np.random.default_rng(7))
    effects = [EffectSpec("viscous_friction", c, {"fv": v}) for c, v in (("q1", 0.3), ("q2", 0.2))]
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi, effects, still=(2,))
    _write(tmp_path / "log.csv", ["t", "a", "b", "c", "x", "y", "z"], [t, *motion.q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nname = "r"\nfile = "log.csv"\n' + CHANNELS)
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert np.all(data.motion.qd[:, 2] == 0) and np.all(data.motion.qdd[:, 2] == 0)
    assert any("held still in run 'r'" in n and "q3 (0 rad)" in n for n in data.notes)
    mech_path = tmp_path / "m.toml"
    mech_path.write_text(_chain(7))
    result = CliRunner().invoke(main, ["identify", str(mech_path), str(tmp_path / "rec.toml"), "--solver", "dp",
                                       "--effect", "viscous_friction:*", "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    fv = {c["name"]: c["value"] for e in out["effects"] for c in e["coefficients"]}
    assert set(fv) == {"fv_q1", "fv_q2"}
    assert fv["fv_q1"] == pytest.approx(0.3, rel=1e-2) and fv["fv_q2"] == pytest.approx(0.2, rel=1e-2)


# ----- time columns -------------------------------------------------------------------------
def test_kinova_time_column_of_sample_indices_is_refused_or_scaled(tmp_path, gen3):
    """The Kinova's Time counts samples: read as seconds (no unit) it is refused with the way
    out; time_unit = "samples" with rate = 1000 places every row at its index / 1000 s (this
    subset keeps every second row: a 2 ms step); time_unit = "samples" without a rate is
    refused; with time_unit = "s" said, it is taken as seconds (the user's word)."""
    path = _kinova(tmp_path, _run("joint_2_trapez"), torque="TorqueCur", head='time = "Time"\n')
    with pytest.raises(InputError) as error:
        read_recording(path, gen3)
    assert error.value.key == "recording.time"
    assert "counts samples (0, 2, 4, ... in steps of 2)" in error.value.reason
    assert 'time_unit = "samples" and rate = HZ' in error.value.reason
    data, _ = read_recording(_kinova(tmp_path, _run("joint_2_trapez"), torque="TorqueCur"), gen3)
    assert np.diff(data.motion.t) == pytest.approx(0.002)
    path = _kinova(tmp_path, _run("joint_2_trapez"), torque="TorqueCur", head='time = "Time"\ntime_unit = "samples"\n')
    with pytest.raises(InputError, match="needs the time column and one of rate"):
        read_recording(path, gen3)


def test_sample_index_time_read_with_its_rate_gives_the_true_friction(tmp_path):
    """Known truth fv = 0.3, 0.2, 0.1: a time column of sample indices is refused without a
    unit (it made viscous friction 1000 times too large, exit 0); with time_unit = "samples"
    and the rate the friction comes back."""
    mech = parse_mechanism(_chain(3))
    phi = random_physical_inertia(mech, np.random.default_rng(3))
    effects = [EffectSpec("viscous_friction", c, {"fv": v}) for c, v in (("q1", 0.3), ("q2", 0.2), ("q3", 0.1))]
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi, effects)
    _write(tmp_path / "log.csv", ["n", "a", "b", "c", "x", "y", "z"], [np.arange(len(t)), *motion.q.T, *tau.T])
    runs = '[[runs]]\nfile = "log.csv"\n'
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "n"\n' + runs + CHANNELS)
    mech_path = tmp_path / "m.toml"
    mech_path.write_text(_chain(3))
    args = ["identify", str(mech_path), str(tmp_path / "rec.toml"), "--solver", "dp", "--effect", "viscous_friction:*",
            "--format", "json", "--quiet"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2 and "counts samples" in result.stderr
    (tmp_path / "rec.toml").write_text(f'[recording]\ntime = "n"\ntime_unit = "samples"\nrate = {RATE}\n'
                                       + runs + CHANNELS)
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    fv = {c["name"]: c["value"] for e in json.loads(result.stdout)["effects"] for c in e["coefficients"]}
    assert fv == pytest.approx({"fv_q1": 0.3, "fv_q2": 0.2, "fv_q3": 0.1}, rel=1e-2)


def test_a_motion_slower_than_a_tenth_of_a_hertz_is_said(tmp_path):
    """Seconds given as milliseconds (time_unit left "s" on a column in ms): the motion seems
    1000 times slower, and the filter's note asks whether the time is in the right unit."""
    mech = parse_mechanism(_chain(2))
    phi = random_physical_inertia(mech, np.random.default_rng(2))
    t = np.arange(0, 10, 1 / RATE)
    motion, tau = _truth(mech, t, phi)
    _write(tmp_path / "log.csv", ["ms", "a", "b", "c", "x", "y", "z"], [t * 1000 + 0.5, *motion.q.T, *tau.T])
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "ms"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS)
    data, _ = read_recording(tmp_path / "rec.toml", mech)
    assert any("slower than 0.1 Hz over the whole log" in n and "right unit" in n for n in data.notes), data.notes
