"""Reading long and wide logs through a recording description: CPU seconds and peak memory
of ``read_recording`` (reading, derivatives, filter and decimation), each in its own process,
beside numpy's ``loadtxt`` of the same file's used columns (the yardstick, same run).

Two logs of a generated 3-R chain, written here: a *wide* one as a UR's RTDE logger writes it
(500 Hz, 4 minutes, the 6 used columns among 100 numeric ones and a text column) and a *long*
narrow one (1 kHz, 10 minutes, 7 columns). Before the reader parsed only the used columns,
batch by batch, the wide log was refused for its text column, and a log over 70 MB was
refused for memory (every field was kept as a string: 30 bytes a byte of text).

    python benchmarks/bench_read_logs.py [--minutes-wide 4] [--minutes-long 10]

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


def write_log(path: Path, rate: float, minutes: float, extra: int, text: bool) -> list[int]:
    """A smooth motion of three joints and its torques (any numbers: reading is measured), with
    ``extra`` columns of noise and a text column; returns the used columns' indices."""
    t = np.arange(0, 60 * minutes, 1 / rate)
    rng = np.random.default_rng(0)
    q = np.stack([0.8 * np.sin(2 * np.pi * 0.1 * (k + 1) * t + k) for k in range(3)], axis=1)
    tau = np.stack([np.cos(2 * np.pi * 0.1 * (k + 1) * t) + 0.01 * rng.standard_normal(len(t)) for k in range(3)], axis=1)
    names = ["t", "a", "b", "c", "x", "y", "z"] + [f"extra_{k}" for k in range(extra)] + (["mode"] if text else [])
    with path.open("w") as fh:
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
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
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


if __name__ == "__main__":
    main()
