"""Logs as robots write them, round two (issue 44): headerless and stacked logs read by a
description alone, ROS bags (ROS 1 and ROS 2, written here with rosbags itself), one pipeline
for the project's CSV layout and descriptions, and the checks that catch a bad setup. Every
log is made from a simulated mechanism with a known truth, which identification recovers."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.errors import InputError
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.recordings.recording import read_data, read_recording
from baseparams.recordings.simulate import simulate

SEED = 3
CHANNELS = '[position]\nq1 = "q1"\nq2 = "q2"\nq3 = "q3"\n[torque]\nq1 = "tau1"\nq2 = "tau2"\nq3 = "tau3"\n'


def _mechanism(seed: int = SEED):
    return parse_mechanism(generate.serial_chain(seed, bodies=3, types="R"))


def _base(mech):
    return BaseModel.from_result(registry.solvers()["dp"].item.solve(mech), mech)


def _simulated(mech, samples: int = 4001, noise: float = 0.0, seed: int = 0):
    """(t, q, qd, tau, truth's base parameters): the mechanism along its trajectory (10 s)."""
    data, truth = simulate(mech, samples=samples, noise_sd=noise, seed=seed, random_inertia=True)
    phi = np.array([truth["parameters"][p] for p in mech.parameters], float)
    m = data.motion
    return m.t, m.q, m.qd, data.tau, _base(mech).values(phi)


def _recovered(path, mech, truth, rtol):
    """The estimates against the truth, as the torques they predict on the data (RMS of the
    difference over the truth's RMS): a measure that does not depend on how the solver scales
    its base parameters (dp's choice of Izz1 with coefficients 144 and -288 instead of Ixy1
    made the largest-component measure 3 times worse for the same fit)."""
    from baseparams.identify.fit import measured_design
    data, model = read_recording(path, mech)
    base = _base(mech)
    result = identify(model, data, base=base)
    K = measured_design(model, data, [], [])[0].matrix
    Kb = np.linalg.lstsq(base.B.T, K.reshape(-1, K.shape[-1]).T, rcond=None)[0].T      # K B^+
    error = np.sqrt(np.mean((Kb @ (result.base_estimates - truth)) ** 2) / np.mean((Kb @ truth) ** 2))
    assert error < rtol, (error, result.base_estimates, truth)
    return data, result


def _cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


# ----- headerless and stacked logs -----------------------------------------------------------
def test_a_headerless_rtde_like_log_is_read_by_names(tmp_path):
    """A controller's export of plain numbers (t, q1..q3, qd1..qd3, i1..i3, spaces, its clock
    at 838 s): the description names its columns and the truth comes back. Before, time = "1"
    said "found in 0 files" and the first row was taken for a header."""
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech)
    gains = np.array([0.11, 0.09, 0.125])
    table = np.column_stack([838.465 + t, q, qd, tau / gains, np.full(len(t), 7)])
    (tmp_path / "rtde.txt").write_text("\n".join(" ".join(f"{v:.17g}" for v in row) for row in table) + "\n")
    names = '["t", "q1", "q2", "q3", "qd1", "qd2", "qd3", "i1", "i2", "i3", "mode"]'
    (tmp_path / "rec.toml").write_text(
        f'[recording]\ntime = "t"\ndelimiter = "space"\n[[runs]]\nfile = {{ path = "rtde.txt", names = {names} }}\n'
        '[position]\nq1 = "q1"\nq2 = "q2"\nq3 = "q3"\n[torque]\n'
        + "".join(f'q{j + 1} = {{ column = "i{j + 1}", gain = {g} }}\n' for j, g in enumerate(gains)))
    _recovered(tmp_path / "rec.toml", mech, truth, 2e-3)
    # without names, the first row of numbers is refused with the way out, naming no CSV layout
    (tmp_path / "bare.toml").write_text((tmp_path / "rec.toml").read_text().replace(
        f'{{ path = "rtde.txt", names = {names} }}', '"rtde.txt"'))
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "bare.toml", "--solver", "dp")
    assert out.exit_code == 2, out.output
    assert "rtde.txt: row 1: its first line (838.465" in out.stderr and "names = [...]" in out.stderr
    assert "q_<coordinate>" not in out.stderr and "Traceback" not in out.output
    # a row with fields beyond the names: the row and the description's names
    (tmp_path / "rtde.txt").write_text((tmp_path / "rtde.txt").read_text() + "1 2 3 4 5 6 7 8 9 10 11 12\n")
    with pytest.raises(InputError, match=r"rtde\.txt: row 4002: 12 fields, the description names 11 columns "
                                         r"\(runs\[0\]\.file of rec\.toml"):
        read_recording(tmp_path / "rec.toml", mech)


def _mech_file(tmp_path, seed: int = SEED) -> Path:
    path = tmp_path / "mech.toml"
    path.write_text(generate.serial_chain(seed, bodies=3, types="R"))
    return path


def test_a_stacked_log_with_time_in_its_own_file(tmp_path):
    """The Panda's published layout: one file per quantity, the joints of a sample on
    consecutive lines, the time in a file of its own, stamps irregular: read by a description
    alone, and the truth comes back."""
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech, samples=6001)
    keep = np.sort(np.random.default_rng(1).choice(len(t), size=4500, replace=False))   # irregular stamps
    t, q, tau = t[keep], q[keep], tau[keep]
    (tmp_path / "time.txt").write_text("\n".join(f"{v:.17g}" for v in t) + "\n")
    (tmp_path / "q.txt").write_text("\n".join(f"{v:.17g}" for v in q.reshape(-1)) + "\n")
    (tmp_path / "tau.txt").write_text("# effort, N m\n" + "\n".join(f"{v:.17g}" for v in tau.reshape(-1)) + "\n")
    (tmp_path / "rec.toml").write_text(
        '[recording]\ntime = "t"\ncomment = "#"\n[[runs]]\n'
        'files = { t = { path = "time.txt", names = ["t"] }, '
        'q = { path = "q.txt", names = ["q1", "q2", "q3"], stacked = true }, '
        'tau = { path = "tau.txt", names = ["tau1", "tau2", "tau3"], stacked = true } }\n' + CHANNELS)
    data, _ = _recovered(tmp_path / "rec.toml", mech, truth, 3e-3)
    assert any("irregular time steps" in n for n in data.notes)
    # a sample cut short: its count, its first row, and what the description asked for
    (tmp_path / "q.txt").write_text((tmp_path / "q.txt").read_text() + "0.5\n")
    with pytest.raises(InputError, match=r"q\.txt: 13501 values are not a whole number of samples of 3 "
                                         r"\(runs\[0\]\.files\.q of rec\.toml: names = \[q1, q2, q3\]\): the last "
                                         r"sample has 1 value\(s\), from row 13501"):
        read_recording(tmp_path / "rec.toml", mech)
    # a bad value: its line and the column it stands for
    lines = (tmp_path / "tau.txt").read_text().splitlines()
    lines[5] = "1.2.3"
    (tmp_path / "tau.txt").write_text("\n".join(lines) + "\n")
    (tmp_path / "q.txt").write_text("\n".join(f"{v:.17g}" for v in q.reshape(-1)) + "\n")
    with pytest.raises(InputError, match=r"tau\.txt: row 6, column tau2: '1\.2\.3' is not a number"):
        read_recording(tmp_path / "rec.toml", mech)


def test_a_one_value_a_line_log_without_stacked_speaks_of_the_description(tmp_path):
    """Before: "the header '0' has one column: not a comma-separated file with columns t,
    q_<coordinate>, tau_<coordinate>". Now the log's first line is named, with the way out."""
    mech = _mechanism()
    (tmp_path / "q.txt").write_text("0\n0.1\n0.2\n" * 20)
    (tmp_path / "rec.toml").write_text('[recording]\nrate = 100\n[[runs]]\nfile = "q.txt"\n' + CHANNELS)
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "rec.toml", "--solver", "dp")
    assert out.exit_code == 2
    assert "q.txt: row 1: its first line (0) holds numbers" in out.stderr and "stacked = true" in out.stderr
    assert "comma-separated" not in out.stderr and "q_<coordinate>" not in out.stderr
    for entry, message in [('{ path = "q.txt", stacked = true }', r"runs\[0\]\.file\.stacked: stacked = true"),
                           ('{ path = "q.txt", names = ["a", "a"] }', r"runs\[0\]\.file\.names\[1\]: 'a' is named twice"),
                           ('{ path = "q.txt", name = ["a"] }', r"runs\[0\]\.file\.name: unknown key"),
                           ('3', r"runs\[0\]\.file: must be a path, or a table")]:
        (tmp_path / "bad.toml").write_text(f'[recording]\nrate = 100\n[[runs]]\nfile = {entry}\n' + CHANNELS)
        with pytest.raises(InputError, match=message):
            read_recording(tmp_path / "bad.toml", mech)
    # an empty log: the log is named, not "a CSV file with a header row"
    (tmp_path / "q.txt").write_text("")
    with pytest.raises(InputError, match=r"q\.txt: empty file: a log with one sample a row with samples"):
        read_recording(tmp_path / "rec.toml", mech)


def test_a_used_column_named_twice_in_a_logs_header_is_an_error(tmp_path):
    """Issue 46: `time_ms,enc,enc,cur` with `enc` used read the first `enc` in silence; now exit
    2 naming the file and the column, as the project's CSV reader does ("appears twice")."""
    (tmp_path / "log.csv").write_text("time_ms,enc,enc,cur\n" + "".join(f"{k},{k * 0.01},{k * 0.02},1\n"
                                                                       for k in range(50)))
    (tmp_path / "mech.toml").write_text(generate.serial_chain(1, bodies=1, types="R"))
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "time_ms"\ntime_unit = "ms"\n[[runs]]\nfile = "log.csv"\n'
                                       '[position]\nq1 = "enc"\n[torque]\nq1 = "cur"\n')
    out = _cli("identify", tmp_path / "mech.toml", tmp_path / "rec.toml", "--solver", "dp")
    assert out.exit_code == 2, out.output
    assert "log.csv: header: column 'enc' appears twice (columns 2 and 3)" in out.stderr
    assert "Traceback" not in out.output
    # an unused duplicate is no error (a logger's repeated status column)
    (tmp_path / "log.csv").write_text("time_ms,enc,st,st,cur\n" + "".join(f"{k},{np.sin(k / 5)},a,b,{np.cos(k / 5)}\n"
                                                                          for k in range(50)))
    read_recording(tmp_path / "rec.toml", parse_mechanism(generate.serial_chain(1, bodies=1, types="R")))


# ----- ROS bags ---------------------------------------------------------------------------------
JOINTS = ["joint_a", "joint_b", "joint_c"]
BAG_CHANNELS = ('[position]\n' + "".join(f'q{j + 1} = "/joint_states.position[{n}]"\n' for j, n in enumerate(JOINTS))
                + '[velocity]\n' + "".join(f'q{j + 1} = "/joint_states.velocity[{n}]"\n' for j, n in enumerate(JOINTS)))


def _write_bag(path: Path, topics: dict[str, list[tuple[float, dict]]], ros1: bool) -> Path:
    """A bag written with rosbags itself: per topic, (stamp in s, JointState fields) messages;
    each message's joints in a shuffled order (a publisher may order them as it likes)."""
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    State = store.types["sensor_msgs/msg/JointState"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(0)
    if ros1:
        from rosbags.rosbag1 import Writer
        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
        plugin = StoragePlugin.MCAP if path.suffix == ".mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path.with_suffix(""), version=9, storage_plugin=plugin)
    with writer:
        for topic, messages in topics.items():
            connection = writer.add_connection(topic, State.__msgtype__, typestore=store)
            for k, (stamp, fields) in enumerate(messages):
                ns = int(round(stamp * 1e9)) + 1_700_000_000 * 10 ** 9      # an epoch clock
                header = dict(stamp=Time(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), frame_id="base")
                order = rng.permutation(len(JOINTS))
                message = State(header=Header(seq=k, **header) if ros1 else Header(**header),
                                name=[JOINTS[i] for i in order],
                                **{f: np.asarray(fields.get(f, []), float)[order] if f in fields else np.zeros(0)
                                   for f in ("position", "velocity", "effort")})
                raw = store.serialize_ros1(message, State.__msgtype__) if ros1 else \
                    store.serialize_cdr(message, State.__msgtype__)
                writer.write(connection, ns + 2_000_000, raw)          # received 2 ms later
    if ros1:
        return path
    written = path.with_suffix("") / (path.with_suffix("").name + path.suffix)
    return written


def test_a_ros1_bag_of_joint_states_recovers_the_truth(tmp_path):
    """sensor_msgs/JointState by joint name (each message's own order), header stamps as the
    clock, a measured velocity: the description alone reads the bag and the truth comes back."""
    pytest.importorskip("rosbags")
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech)
    messages = [(t[k], {"position": q[k], "velocity": qd[k], "effort": tau[k]}) for k in range(len(t))]
    bag = _write_bag(tmp_path / "arm.bag", {"/joint_states": messages}, ros1=True)
    (tmp_path / "rec.toml").write_text(f'[[runs]]\nfile = "{bag.name}"\n' + BAG_CHANNELS + '[torque]\n'
                                       + "".join(f'q{j + 1} = "/joint_states.effort[{n}]"\n' for j, n in enumerate(JOINTS)))
    data, _ = _recovered(tmp_path / "rec.toml", mech, truth, 2e-3)
    assert data.estimated == ("qdd",)
    # through the command, with a typo in a joint and in a topic: exit 2, naming what the bag has
    mech_file = _mech_file(tmp_path)
    out = _cli("identify", mech_file, tmp_path / "rec.toml", "--solver", "dp", "--format", "json")
    assert out.exit_code == 0, out.output
    (tmp_path / "typo.toml").write_text((tmp_path / "rec.toml").read_text().replace("/joint_states.effort[joint_c]",
                                                                                    "/joint_state.effort[joint_c]"))
    out = _cli("identify", mech_file, tmp_path / "typo.toml", "--solver", "dp")
    assert out.exit_code == 2 and "no topic of the bag starts the column '/joint_state.effort[joint_c]' (topics: " \
        "/joint_states (sensor_msgs/msg/JointState))" in out.stderr, out.output
    (tmp_path / "typo.toml").write_text((tmp_path / "rec.toml").read_text().replace("/joint_states.effort[joint_c]",
                                                                                    "/joint_states.efort[joint_c]"))
    out = _cli("identify", mech_file, tmp_path / "typo.toml", "--solver", "dp")
    assert out.exit_code == 2 and "topic /joint_states, message 1: sensor_msgs/msg/JointState has no field 'efort'" \
        in out.stderr, out.output
    (tmp_path / "typo.toml").write_text((tmp_path / "rec.toml").read_text().replace("/joint_states.effort[joint_c]",
                                                                                    "/joint_states.effort[joint_d]"))
    out = _cli("identify", mech_file, tmp_path / "typo.toml", "--solver", "dp")
    assert out.exit_code == 2 and "joint_d" in out.stderr and "Traceback" not in out.output, out.output


@pytest.mark.parametrize("suffix", [".mcap", ".db3"])
def test_a_ros2_bag_with_topics_on_their_own_clocks_recovers_the_truth(tmp_path, suffix):
    """Positions and velocities on /joint_states at 400 Hz, efforts on /joint_efforts at 200
    Hz with stamps of their own (jittered): each topic on its own clock, read on the torques'
    clock, and the truth comes back."""
    pytest.importorskip("rosbags")
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech)
    rng = np.random.default_rng(2)
    states = [(t[k], {"position": q[k], "velocity": qd[k]}) for k in range(len(t))]
    picked = np.sort(rng.choice(np.arange(3, len(t) - 3), size=len(t) // 2, replace=False))
    efforts = [(t[k], {"effort": tau[k]}) for k in picked]
    bag = _write_bag(tmp_path / f"arm{suffix}", {"/joint_states": states, "/joint_efforts": efforts}, ros1=False)
    (tmp_path / "rec.toml").write_text(f'[recording]\ntime = "header.stamp"\n[[runs]]\nfile = "{bag.relative_to(tmp_path)}"\n'
                                       + BAG_CHANNELS + '[torque]\n'
                                       + "".join(f'q{j + 1} = "/joint_efforts.effort[{n}]"\n' for j, n in enumerate(JOINTS)))
    data, _ = _recovered(tmp_path / "rec.toml", mech, truth, 2e-3)
    assert any("interpolated onto the clock of" in n and "/joint_efforts" in n for n in data.notes), data.notes
    # a bag's folder (metadata.yaml beside the storage file) reads the same
    (tmp_path / "dir.toml").write_text((tmp_path / "rec.toml").read_text().replace(
        str(bag.relative_to(tmp_path)), str(bag.parent.relative_to(tmp_path))))
    again, _ = read_recording(tmp_path / "dir.toml", mech)
    assert np.array_equal(again.tau, data.tau)
    # the recorder's clock instead of the stamps (2 ms later, the same steps): the same samples
    (tmp_path / "log.toml").write_text((tmp_path / "rec.toml").read_text().replace('"header.stamp"', '"log_time"'))
    received, _ = read_recording(tmp_path / "log.toml", mech)
    np.testing.assert_allclose(received.tau, data.tau, rtol=0, atol=1e-9 * np.abs(data.tau).max())


# ----- one pipeline ---------------------------------------------------------------------------
def test_the_projects_csv_layout_with_irregular_stamps_is_read_as_a_recording(tmp_path):
    """The Panda's case: t, q_, qd_, tau_ with irregular stamps and no acceleration was refused
    ("qdd can only be estimated from uniformly sampled data"); now it is read through the
    description pipeline, and the same samples read through a written description give the
    same estimates (to 1e-9), and the truth."""
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech, samples=6001, noise=0.01)
    keep = np.sort(np.random.default_rng(4).choice(len(t), size=4800, replace=False))
    coordinates = ("q1", "q2", "q3")
    header = ["t"] + [f"{k}_{c}" for c in coordinates for k in ("q", "qd", "tau")]
    columns = [t[keep]] + [a[keep, j] for j in range(3) for a in (q, qd, tau)]
    (tmp_path / "panda.csv").write_text(",".join(header) + "\n" + "\n".join(
        ",".join(f"{v:.17g}" for v in row) for row in np.column_stack(columns)) + "\n")
    data, model = read_data([str(tmp_path / "panda.csv")], mech)
    assert "irregular time stamps: read as a recording" in data.notes[0]
    assert data.estimated == ("qdd",)
    (tmp_path / "panda.toml").write_text(
        '[recording]\ntime = "t"\n[[runs]]\nfile = "panda.csv"\n'
        + "".join(f'[{q}]\n' + "".join(f'{c} = "{p}_{c}"\n' for c in coordinates)
                  for q, p in (("position", "q"), ("velocity", "qd"), ("torque", "tau"))))
    described, _ = read_recording(tmp_path / "panda.toml", mech)
    base = _base(mech)
    a, b = identify(model, data, base=base), identify(model, described, base=base)
    np.testing.assert_allclose(a.estimates, b.estimates, rtol=0, atol=1e-9 * np.abs(b.estimates).max())
    np.testing.assert_allclose(a.std, b.std, rtol=1e-9)
    error = np.abs(a.base_estimates - truth) / a.std[:len(truth)]
    assert error.max() < 4.5, error
    # through the command: exit 0, where it was exit 2
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "panda.csv", "--solver", "dp", "--format", "json")
    assert out.exit_code == 0, out.output
    # uniform stamps keep Savitzky-Golay (unchanged), and a partial qd_ is still refused
    header_only = ",".join(header[:-1])
    (tmp_path / "partial.csv").write_text(header_only + "\n" + "\n".join(
        ",".join(f"{v:.17g}" for v in row[:-1]) for row in np.column_stack(columns)) + "\n")
    with pytest.raises(InputError, match="missing columns tau_q3"):
        read_data([str(tmp_path / "partial.csv")], mech)


# ----- checks that catch a bad setup ----------------------------------------------------------
def _log(tmp_path, name, t, q, tau, qd=None):
    header = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"] + (["v1", "v2", "v3"] if qd is not None else [])
    table = np.column_stack([t, q, tau] + ([qd] if qd is not None else []))
    (tmp_path / name).write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row)
                                                                     for row in table) + "\n")


def _cutoff(data) -> float:
    (note,) = [n for n in data.notes if "low-passed at" in n]
    return float(note.split("low-passed at ")[1].split(" Hz")[0])


def test_the_cut_off_comes_from_the_positions_never_a_measured_velocitys_noise(tmp_path):
    """A controller's velocity: differenced and low-passed at 40 Hz by the drive, its noise
    filling that band. Before, the cut-off came from its spectrum (the Panda's: 33 Hz, nothing
    filtered); now from the positions, as without [velocity]."""
    from scipy.signal import butter, sosfilt

    from baseparams.recordings.recording import auto_cutoff
    mech = _mechanism()
    t, q, qd, tau, _ = _simulated(mech, samples=10001)
    rng = np.random.default_rng(5)
    read_q = q + 1e-6 * rng.standard_normal(q.shape)                  # an encoder's noise
    band = sosfilt(butter(2, 40, fs=1000, output="sos"), rng.standard_normal(q.shape), axis=0)
    velocity = qd + 0.02 * np.sqrt(np.mean(qd ** 2, axis=0)) * band / band.std(axis=0)
    _log(tmp_path, "log.csv", t, read_q, tau, velocity)
    head = '[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS
    (tmp_path / "q.toml").write_text(head)
    (tmp_path / "v.toml").write_text(head + '[velocity]\nq1 = "v1"\nq2 = "v2"\nq3 = "v3"\n')
    from_positions, _ = read_recording(tmp_path / "q.toml", mech)
    with_velocity, _ = read_recording(tmp_path / "v.toml", mech)
    assert _cutoff(with_velocity) == _cutoff(from_positions)
    assert "the positions' bandwidth" in " ".join(with_velocity.notes)
    # the velocity's own spectrum would have set it far higher (the test has a bad setup to catch)
    assert auto_cutoff(velocity, float(t[1] - t[0]), "velocities")[0] > 3 * _cutoff(from_positions)


def test_gains_at_or_below_zero_and_an_ill_conditioned_fit_are_said_with_their_numbers(tmp_path):
    """A current logged with the other sign fitted with gain = "unknown": a negative gain,
    said on stderr with its number and in JSON warnings (it was exit 0 in silence), and no
    false "tau_X is 0 in every row" note for the channels scaled by unknown gains (six of them on
    every such UR run)."""
    from baseparams.identify.fit import setup_warnings
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech, noise=0.01)
    gains = np.array([0.7, 1.9, 0.35])
    current = tau / gains
    current[:, 1] *= -1                                           # logged with the drive's own sign
    _log(tmp_path, "log.csv", t, q, current)
    (tmp_path / "rec.toml").write_text(
        '[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n[position]\nq1 = "q1"\nq2 = "q2"\nq3 = "q3"\n'
        '[torque]\nq1 = { column = "tau1", gain = 0.7 }\nq2 = { column = "tau2", gain = "unknown" }\n'
        'q3 = { column = "tau3", gain = "unknown" }\n')
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "rec.toml", "--solver", "dp", "--format", "json")
    assert out.exit_code == 0, out.output
    report = json.loads(out.stdout)
    gain = {g["name"]: g for g in report["gains"]}
    assert abs(gain["gain_q2"]["value"] + 1.9) < 0.01 and abs(gain["gain_q3"]["value"] - 0.35) < 0.01
    (warning,) = [w for w in report["warnings"] if w.startswith("gain_q2 = -1.9")]
    assert "negative gain" in warning and f"warning: {warning}" in out.stderr
    assert not [n for n in report["notes"] if "in every row" in n], report["notes"]
    # zero within its noise, and an ill-conditioned fit: each with its number
    names, kinds = ("phi_b01", "gain_q3"), ("base", "gain")
    said = setup_warnings(names, kinds, np.array([1.0, -1.8e-17]), np.diag([1e-4, 9e-6]), 7.45e11)
    assert said[0].startswith("gain_q3 = -1.8e-17 +- 0.003: zero within its noise")
    assert "condition number 7.45e+11" in said[1]
    assert setup_warnings(names, kinds, np.array([1.0, 0.35]), np.diag([1e-4, 9e-6]), 1e3) == []


def test_validation_is_filtered_with_the_fits_filter_and_nrms_is_given_unfiltered_too(tmp_path):
    """The fit's own log given to --validate through a description with another cut-off: read
    with the fit's filter, its prediction is the fit's own (it was on another band). NRMS on
    the unfiltered torques beside the fit band's: white noise of SD s on torques of RMS r gives
    about s / r there, and far less on the band."""
    mech = _mechanism()
    t, q, qd, tau, _ = _simulated(mech, samples=10001, noise=0.0)
    noise = 0.05 * np.random.default_rng(6).standard_normal(tau.shape)
    _log(tmp_path, "log.csv", t, q, tau + noise)
    head = '[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS
    (tmp_path / "fit.toml").write_text(head)
    (tmp_path / "other.toml").write_text(head + "[filter]\ncutoff = 150\n")
    import baseparams as bp
    fit = bp.identify(_mech_file(tmp_path), tmp_path / "fit.toml", solver="dp",
                      validate=[tmp_path / "other.toml"])
    report = fit.to_json()
    (validation,) = report["validation"]
    for c in ("q1", "q2", "q3"):
        assert abs(validation["rms"][c] - report["rms"][c]) <= 1e-9 * report["rms"][c], (validation, report["rms"])
    expected = 0.05 / np.sqrt(np.mean(tau ** 2, axis=0))
    raw = np.array([report["nrms_unfiltered"][c] for c in ("q1", "q2", "q3")])
    np.testing.assert_allclose(raw, expected, rtol=0.1)
    assert all(report["nrms"][c] < 0.5 * report["nrms_unfiltered"][c] for c in ("q1", "q2", "q3"))
    assert validation["nrms_unfiltered"] == pytest.approx(report["nrms_unfiltered"], rel=1e-9)
    assert "NRMS on the unfiltered torques" in fit.to_text()
    # the same samples in the project's CSV layout (uniform: Savitzky-Golay and no filter on their
    # own) are read through the recording pipeline with the fit's filter: the same prediction
    coordinates = ("q1", "q2", "q3")
    header = ["t"] + [f"{k}_{c}" for c in coordinates for k in ("q", "tau")]
    columns = [t] + [a[:, j] for j in range(3) for a in (q, tau + noise)]
    (tmp_path / "same.csv").write_text(",".join(header) + "\n" + "\n".join(
        ",".join(f"{v:.17g}" for v in row) for row in np.column_stack(columns)) + "\n")
    again = bp.identify(_mech_file(tmp_path), tmp_path / "fit.toml", solver="dp", validate=[tmp_path / "same.csv"])
    (layout,) = again.to_json()["validation"]
    for c in coordinates:
        assert abs(layout["rms"][c] - report["rms"][c]) <= 1e-9 * report["rms"][c], (layout, report["rms"])


def test_a_window_outside_the_log_gives_the_logs_span(tmp_path):
    """Before: "0 samples between 0 and 200 s"; the log's clock ran from 838 to 888 s."""
    mech = _mechanism()
    t, q, qd, tau, _ = _simulated(mech, samples=2001)
    _log(tmp_path, "log.csv", 838.4 + t, q, tau)
    (tmp_path / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\nwindow = [0, 200]\n'
                                       + CHANNELS)
    with pytest.raises(InputError, match=r"rec\.toml: runs\[0\]\.window: 0 samples between 0 and 200 s: the log's "
                                         r"time runs from 838\.4 to 848\.4 s \(in the log's own clock\)"):
        read_recording(tmp_path / "rec.toml", mech)


def test_the_api_takes_a_result_object_wherever_the_cli_takes_a_result_file(tmp_path):
    """bp.diagnose(params=fit) with identify's result object failed with a 67 000-character
    error; now it is the same diagnosis as with the result's JSON file."""
    import baseparams as bp
    bp.simulate("planar_2r", output=tmp_path / "d.csv", noise=0.01, seed=1, samples=400)
    fit = bp.identify("planar_2r", tmp_path / "d.csv", solver="dp")
    (tmp_path / "fit.json").write_text(json.dumps(fit.to_json()))
    by_object = bp.diagnose("planar_2r", tmp_path / "d.csv", params=fit, candidates=["viscous_friction"])
    by_file = bp.diagnose("planar_2r", tmp_path / "d.csv", params=tmp_path / "fit.json",
                          candidates=["viscous_friction"])
    a, b = by_object.to_json(), by_file.to_json()
    assert a["verdict"] == b["verdict"] and a["gap"] == b["gap"]
    with pytest.raises(InputError, match="expected a result file's path or a result object"):
        bp.diagnose("planar_2r", tmp_path / "d.csv", params=3.5)   # type: ignore[arg-type]


def test_a_bag_whose_publisher_leaves_efforts_empty_says_so(tmp_path):
    """A JointState publisher that fills positions only (effort = []): the quantity and the
    counts are named, exit 2, never a traceback."""
    pytest.importorskip("rosbags")
    t = np.arange(40) * 0.01
    messages = [(tk, {"position": np.full(3, np.sin(tk)), "velocity": np.zeros(3)}) for tk in t]
    bag = _write_bag(tmp_path / "arm.bag", {"/joint_states": messages}, ros1=True)
    (tmp_path / "rec.toml").write_text(f'[[runs]]\nfile = "{bag.name}"\n' + BAG_CHANNELS + '[torque]\n'
                                       + "".join(f'q{j + 1} = "/joint_states.effort[{n}]"\n' for j, n in enumerate(JOINTS)))
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "rec.toml", "--solver", "dp")
    assert out.exit_code == 2 and "Traceback" not in out.output, out.output
    assert "topic /joint_states, message 1: '/joint_states.effort[joint_" in out.stderr
    assert "the message's effort has 0 values for its 3 joints" in out.stderr, out.stderr


def test_blank_lines_in_a_stacked_log_separate_samples_or_stand_for_a_missing_value(tmp_path):
    """A blank line after a whole sample separates samples; one inside a sample is a missing
    value (NaN, the sample left out later), never skipped: skipped, every later value would
    move into the next column."""
    from baseparams.recordings.tables import LogFile, read_log
    log = LogFile("q.txt", ("a", "b"), True, "runs[0].files.q")
    (tmp_path / "q.txt").write_text("1\n2\n\n3\n4\n\n5\n6\n\n")
    _, table, rows = read_log(str(tmp_path / "q.txt"), log, str(tmp_path / "rec.toml"))
    assert table["a"].tolist() == [1, 3, 5] and table["b"].tolist() == [2, 4, 6] and rows == [1, 4, 7]
    (tmp_path / "q.txt").write_text("1\n2\n3\n\n5\n6\n")
    _, table, rows = read_log(str(tmp_path / "q.txt"), log, str(tmp_path / "rec.toml"))
    assert table["a"].tolist()[::2] == [1, 5] and np.isnan(table["b"][1]) and table["b"][2] == 6
    (tmp_path / "q.txt").write_text("1\n2 3\n")
    with pytest.raises(InputError, match=r"q\.txt: row 2: '2 3' holds several values"):
        read_log(str(tmp_path / "q.txt"), log, str(tmp_path / "rec.toml"))


def test_a_bags_messages_are_read_in_the_order_of_their_stamps(tmp_path):
    """Messages received out of order (two publishers, a network) are placed by their stamps:
    the truth comes back; a publisher that leaves every stamp 0 is named with the way out."""
    pytest.importorskip("rosbags")
    mech = _mechanism()
    t, q, qd, tau, truth = _simulated(mech)
    messages = [(t[k], {"position": q[k], "velocity": qd[k], "effort": tau[k]}) for k in range(len(t))]
    for k in range(10, len(messages) - 1, 37):                  # swapped on arrival
        messages[k], messages[k + 1] = messages[k + 1], messages[k]
    bag = _write_bag(tmp_path / "arm.bag", {"/joint_states": messages}, ros1=True)
    effort = "".join(f'q{j + 1} = "/joint_states.effort[{n}]"\n' for j, n in enumerate(JOINTS))
    (tmp_path / "rec.toml").write_text(f'[[runs]]\nfile = "{bag.name}"\n' + BAG_CHANNELS + '[torque]\n' + effort)
    _recovered(tmp_path / "rec.toml", mech, truth, 2e-3)
    unstamped = _write_bag(tmp_path / "zero.bag", {"/joint_states": [(-1.7e9, m) for _, m in messages[:50]]},
                           ros1=True)
    (tmp_path / "zero.toml").write_text(f'[[runs]]\nfile = "{unstamped.name}"\n' + BAG_CHANNELS + '[torque]\n' + effort)
    with pytest.raises(InputError, match=r"zero\.bag: recording\.time: every message of topic /joint_states is "
                                         r"stamped 0 s \(header\.stamp\).*time = \"log_time\""):
        read_recording(tmp_path / "zero.toml", mech)


def test_a_bag_without_rosbags_installed_says_how_to_install_it(tmp_path, monkeypatch):
    """The extra is optional: without it, exit 2 with the pip command, not an ImportError."""
    import sys
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)     # import fails as if not installed
    (tmp_path / "arm.bag").write_bytes(b"#ROSBAG V2.0\n")
    (tmp_path / "rec.toml").write_text('[[runs]]\nfile = "arm.bag"\n' + BAG_CHANNELS + '[torque]\n'
                                       + "".join(f'q{j + 1} = "/joint_states.effort[{n}]"\n' for j, n in enumerate(JOINTS)))
    out = _cli("identify", _mech_file(tmp_path), tmp_path / "rec.toml", "--solver", "dp")
    assert out.exit_code == 2 and "pip install 'baseparams[ros]'" in out.stderr and "arm.bag" in out.stderr, out.output


def test_a_joint_name_index_finds_the_names_of_the_enclosing_or_the_whole_message():
    """JointState's own name list, or a controller state's joint_names at the top of the message
    for actual.positions[joint] (a field path without ROS installed: plain objects)."""
    from types import SimpleNamespace

    from baseparams.recordings.bags import _value, parse_field
    state = SimpleNamespace(joint_names=["a", "b"], actual=SimpleNamespace(positions=np.array([1.0, 2.0])))
    field = parse_field("/state.actual.positions[b]", ["/state"])
    assert field is not None and _value(state, field, {}) == 2.0
    joint_state = SimpleNamespace(name=["b", "a"], position=np.array([3.0, 4.0]))
    assert _value(joint_state, parse_field("/js.position[a]", ["/js"]), {}) == 4.0
    assert np.isnan(_value(joint_state, parse_field("/js.position[c]", ["/js"]), {}))
    assert _value(joint_state, parse_field("/js.position[0]", ["/js"]), {}) == 3.0
    assert parse_field("/other.position[0]", ["/js"]) is None
