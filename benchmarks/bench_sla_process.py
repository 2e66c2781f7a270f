"""Benchmark: the SLA solved by each solver as a user runs it, whole process (not run by CI).

``baseparams solve sla_suspension --solver S`` in a fresh process, wall time and peak RSS,
for dp, vp at 30 digits and symbolic (issue 12's targets: vp at 30 digits <= 3 s, symbolic
<= 2 s). Yardstick, measured in the same run: the command's own start, ``baseparams solve
--help`` (imports, no work), so a time reads as start + work and stays comparable when the
shared machine is slow. Each command runs ``--repeat`` times, interleaved; the median and
the range are printed.

Run: python benchmarks/bench_sla_process.py [--repeat 5]
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "start (solve --help)": ["solve", "--help"],
    "dp": ["solve", "sla_suspension", "--solver", "dp"],
    "vp, 30 digits": ["solve", "sla_suspension", "--solver", "vp", "--digits", "30"],
    "symbolic": ["solve", "sla_suspension", "--solver", "symbolic"],
}


def run(arguments: list[str]) -> tuple[float, float]:
    """(wall seconds, peak RSS in MB) of one fresh ``baseparams`` process."""
    executable = shutil.which("baseparams")
    command = [executable] + arguments if executable else [sys.executable, "-m", "baseparams.cli"] + arguments
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    start = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(child.pid, 0)          # this child's own resource usage
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        sys.exit(f"baseparams {' '.join(arguments)} failed with exit code {child.returncode}")
    return wall, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per command, interleaved [5]")
    args = parser.parse_args()
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    memory: dict[str, list[float]] = {name: [] for name in COMMANDS}
    for _ in range(args.repeat):
        for name, arguments in COMMANDS.items():
            wall, peak = run(arguments)
            times[name].append(wall)
            memory[name].append(peak)
    start = statistics.median(times["start (solve --help)"])
    print(f"SLA suspension, whole process, {args.repeat} runs each (load average "
          f"{os.getloadavg()[0]:.2f}); yardstick: the command's start, {start:.2f} s")
    print(f"{'command':<22} {'median':>8} {'range':>15} {'x start':>8} {'work':>7} {'peak RSS':>9}")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"{name:<22} {median:7.2f}s {min(values):6.2f}-{max(values):5.2f} s {median / start:7.1f}x "
              f"{median - start:6.2f}s {max(memory[name]):6.0f} MB")


if __name__ == "__main__":
    main()
