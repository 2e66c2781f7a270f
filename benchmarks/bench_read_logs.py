"""Reading long and wide logs through a recording description: CPU seconds and peak memory
of ``read_recording`` (reading, derivatives, filter and decimation), each in its own process,
beside numpy's ``loadtxt`` of the same file's used columns (the yardstick, same run).

Two logs of a generated 3-R chain, written here: a *wide* one as a UR's RTDE logger writes it
(500 Hz, 4 minutes, the 6 used columns among 100 numeric ones and a text column) and a *long*
narrow one (1 kHz, 10 minutes, 7 columns). Before the reader parsed only the used columns,
batch by batch, the wide log was refused for its text column, and a log over 70 MB was
refused for memory (every field was kept as a string: 30 bytes a byte of text).

    python benchmarks/bench_read_logs.py [--minutes-wide 4] [--minutes-long 10] [--minutes-headerless 4]
                                         [--minutes-stacked 10] [--minutes-bag 2]

Issue 44's layouts too: the wide log without its header row (``names = [...]``), the long one
as one value a line in three files (time, positions, torques: ``stacked = true``), and a ROS 1
bag of ``sensor_msgs/JointState`` at 500 Hz (needs rosbags: ``pip install 'baseparams[ros]'``;
its yardstick is rosbags' own reading and deserialising of the messages).

Linux counts a child's peak from the image it was forked from (this process's size, about
160 MB here): read the memory as "beyond the import", which the import alone measures.
"""

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHANNELS = '[position]\nq1 = "a"\nq2 = "b"\nq3 = "c"\n[torque]\nq1 = "x"\nq2 = "y"\nq3 = "z"\n'
CHAIN = "from baseparams.model import generate; MECH = generate.serial_chain(3, bodies=3, types='R')"

READ = CHAIN + """
import sys
from baseparams.io.loader import parse_mechanism
from baseparams.recordings.recording import read_recording
data, _ = read_recording(sys.argv[1], parse_mechanism(MECH))
print(data.motion.count, data.count)
"""
YARDSTICK = """
import sys
import numpy as np
columns = [int(c) for c in sys.argv[2].split(",")]
values = np.loadtxt(sys.argv[1], delimiter=",", skiprows=1, usecols=columns)
print(values.shape[0])
"""


BAG_YARDSTICK = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
with AnyReader([Path(sys.argv[1])]) as reader:
    count = sum(1 for c, _, raw in reader.messages() if reader.deserialize(raw, c.msgtype) is not None)
print(count)
"""
JOINTS = ("ja", "jb", "jc")
BAG_CHANNELS = "".join(f'[{quantity}]\n' + "".join(f'q{j + 1} = "/joint_states.{field}[{n}]"\n'
                                                   for j, n in enumerate(JOINTS))
                       for quantity, field in (("position", "position"), ("torque", "effort")))


def motion(rate: float, minutes: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, tau): a smooth motion of three joints and its torques (any numbers: reading is measured)."""
    t = np.arange(0, 60 * minutes, 1 / rate)
    rng = np.random.default_rng(0)
    q = np.stack([0.8 * np.sin(2 * np.pi * 0.1 * (k + 1) * t + k) for k in range(3)], axis=1)
    tau = np.stack([np.cos(2 * np.pi * 0.1 * (k + 1) * t) + 0.01 * rng.standard_normal(len(t)) for k in range(3)], axis=1)
    return t, q, tau


def write_stacked(folder: Path, rate: float, minutes: float) -> None:
    """The long log as one value a line: t.txt, q.txt (3 lines a sample), tau.txt."""
    t, q, tau = motion(rate, minutes)
    for name, values in (("t.txt", t), ("q.txt", q.reshape(-1)), ("tau.txt", tau.reshape(-1))):
        with (folder / name).open("w") as fh:
            for first in range(0, len(values), 60_000):
                fh.write("\n".join(f"{v:.10g}" for v in values[first:first + 60_000]) + "\n")


def write_bag(path: Path, rate: float, minutes: float) -> None:
    """A ROS 1 bag of JointState messages (positions and efforts), stamped at ``rate``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS1_NOETIC)
    State, Header, Time = (store.types[n] for n in ("sensor_msgs/msg/JointState", "std_msgs/msg/Header",
                                                    "builtin_interfaces/msg/Time"))
    t, q, tau = motion(rate, minutes)
    with Writer(path) as writer:
        connection = writer.add_connection("/joint_states", State.__msgtype__, typestore=store)
        for k in range(len(t)):
            ns = 1_700_000_000 * 10 ** 9 + int(round(t[k] * 1e9))
            message = State(header=Header(seq=k, stamp=Time(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), frame_id=""),
                            name=list(JOINTS), position=q[k], velocity=np.zeros(0), effort=tau[k])
            writer.write(connection, ns, store.serialize_ros1(message, State.__msgtype__))


def write_log(path: Path, rate: float, minutes: float, extra: int, text: bool, header: bool = True) -> list[int]:
    """A smooth motion of three joints and its torques (any numbers: reading is measured), with
    ``extra`` columns of noise and a text column; returns the used columns' indices."""
    t, q, tau = motion(rate, minutes)
    rng = np.random.default_rng(1)
    names = ["t", "a", "b", "c", "x", "y", "z"] + [f"extra_{k}" for k in range(extra)] + (["mode"] if text else [])
    with path.open("w") as fh:
        if header:
            fh.write(",".join(names) + "\n")
        for first in range(0, len(t), 20_000):
            rows = slice(first, first + 20_000)
            block = np.column_stack([t[rows], q[rows], tau[rows], rng.standard_normal((len(t[rows]), extra))])
            tail = ",RUNNING" if text else ""
            fh.write("\n".join(",".join(f"{v:.10g}" for v in row) + tail for row in block) + "\n")
    return list(range(7))


def measure(args: list[str]) -> tuple[float, float, str]:
    """CPU seconds, peak resident MB (this child alone: os.wait4) and the output of a Python child."""
    with tempfile.TemporaryFile("w+") as out:
        process = subprocess.Popen([sys.executable, "-c", *args], stdout=out, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, out.read().strip().splitlines()[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes-wide", type=float, default=4.0)
    parser.add_argument("--minutes-long", type=float, default=10.0)
    parser.add_argument("--minutes-headerless", type=float, default=4.0)
    parser.add_argument("--minutes-stacked", type=float, default=10.0)
    parser.add_argument("--minutes-bag", type=float, default=2.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        layouts(folder, args)
        cases = [("wide: 500 Hz, 107 columns (one text)", 500.0, args.minutes_wide, 100, True),
                 ("long: 1 kHz, 7 columns", 1000.0, args.minutes_long, 0, False)]
        for label, rate, minutes, extra, text in cases:
            log = folder / "log.csv"
            used = write_log(log, rate, minutes, extra, text)
            (folder / "rec.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n' + CHANNELS)
            size = log.stat().st_size / 1e6
            cpu, peak, out = measure([READ, str(folder / "rec.toml")])
            base_cpu, base_peak, _ = measure([YARDSTICK, str(log), ",".join(map(str, used))])
            start_cpu, start_peak, _ = measure([CHAIN + "\nimport baseparams.recordings.recording\nprint(0)"])
            print(f"{label}, {minutes:g} min, {size:.0f} MB: read_recording {cpu:.1f} CPU s, peak {peak:.0f} MB "
                  f"(rows, fit rows: {out}); numpy.loadtxt of the used columns {base_cpu:.1f} CPU s, peak "
                  f"{base_peak:.0f} MB; importing alone {start_cpu:.1f} s, {start_peak:.0f} MB; beyond the import "
                  f"{(cpu - start_cpu) / base_cpu:.1f} times loadtxt's time and "
                  f"{(peak - start_peak) / size:.1f} bytes of memory a byte of text", flush=True)


def layouts(folder: Path, args: argparse.Namespace) -> None:
    """Issue 44's layouts: headerless, stacked, a ROS bag."""
    names = ["t", "a", "b", "c", "x", "y", "z"] + [f"extra_{k}" for k in range(100)] + ["mode"]
    log = folder / "bare.csv"
    used = write_log(log, 500.0, args.minutes_headerless, 100, True, header=False)
    (folder / "bare.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = { path = "bare.csv", names = '
                                      + "[" + ", ".join(f'"{n}"' for n in names) + "] }\n" + CHANNELS)
    cpu, peak, out = measure([READ, str(folder / "bare.toml")])
    base_cpu, _, _ = measure([YARDSTICK.replace("skiprows=1", "skiprows=0"), str(log), ",".join(map(str, used))])
    print(f"headerless (names = [...]): 500 Hz, 108 columns, {args.minutes_headerless:g} min, "
          f"{log.stat().st_size / 1e6:.0f} MB: read_recording {cpu:.1f} CPU s, peak {peak:.0f} MB (rows, fit rows: "
          f"{out}); numpy.loadtxt of the used columns {base_cpu:.1f} CPU s", flush=True)
    log.unlink()
    write_stacked(folder, 1000.0, args.minutes_stacked)
    (folder / "stacked.toml").write_text(
        '[recording]\ntime = "t"\n[[runs]]\nfiles = { t = { path = "t.txt", names = ["t"] }, q = { path = "q.txt", '
        'names = ["a", "b", "c"], stacked = true }, tau = { path = "tau.txt", names = ["x", "y", "z"], stacked = true } }\n'
        + CHANNELS)
    size = sum((folder / n).stat().st_size for n in ("t.txt", "q.txt", "tau.txt")) / 1e6
    cpu, peak, out = measure([READ, str(folder / "stacked.toml")])
    print(f"stacked (one value a line, 3 files): 1 kHz, {args.minutes_stacked:g} min, {size:.0f} MB: read_recording "
          f"{cpu:.1f} CPU s, peak {peak:.0f} MB (rows, fit rows: {out})", flush=True)
    try:
        import rosbags  # noqa: F401
    except ImportError:
        print("ROS bag: skipped (pip install 'baseparams[ros]')")
        return
    write_bag(folder / "arm.bag", 500.0, args.minutes_bag)
    (folder / "bag.toml").write_text('[[runs]]\nfile = "arm.bag"\n' + BAG_CHANNELS)
    cpu, peak, out = measure([READ, str(folder / "bag.toml")])
    base_cpu, _, count = measure([BAG_YARDSTICK, str(folder / "arm.bag")])
    print(f"ROS 1 bag of JointState: 500 Hz, {args.minutes_bag:g} min ({count} messages, "
          f"{(folder / 'arm.bag').stat().st_size / 1e6:.0f} MB): read_recording {cpu:.1f} CPU s, peak {peak:.0f} MB "
          f"(rows, fit rows: {out}); rosbags reading and deserialising every message {base_cpu:.1f} CPU s", flush=True)


if __name__ == "__main__":
    main()
