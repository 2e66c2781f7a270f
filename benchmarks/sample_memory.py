"""Peak memory and time of ``solve --solver dp`` at large sample counts, against the estimate
that refuses too large a run before allocating (baseparams.dynamics.trajectory.float64_bytes).

Each run is a fresh interpreter that reports its own peak resident memory. The yardstick is
the same mechanism at 200 samples, run alongside: the table prints the peak above it (what
the samples cost), the estimate of the same difference and their ratio (the estimate must
stay above the measurement: ratio < 1), and the time with its ratio to the yardstick's.
The last line is the issue-13 acceptance run: `solve pendulum --solver dp --samples 100000`
must finish or refuse within 30 s and 2 GB.

    python benchmarks/sample_memory.py [--quick]
"""

import argparse
import subprocess
import sys
import time

from baseparams.dynamics.trajectory import float64_bytes, memory_limit
from baseparams.io.loader import resolve

CASES = [("pendulum", 100_000), ("four_bar", 50_000), ("puma560", 20_000), ("sla_suspension", 20_000),
         ("stewart_platform", 5_000)]
QUICK = [("pendulum", 20_000), ("puma560", 5_000)]
YARDSTICK = 200

CHILD = """
import resource, sys
from baseparams.cli.commands import main
try:
    main(sys.argv[1:], standalone_mode=True)
except SystemExit as exc:
    code = exc.code
print("PEAK_KB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, code, file=sys.stderr)
"""


def run(mech: str, samples: int) -> tuple[float, float, int]:
    """(peak MiB, seconds, exit code) of one solve in a fresh interpreter."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CHILD, "solve", mech, "--solver", "dp",
                           "--samples", str(samples)], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    line = [x for x in proc.stderr.splitlines() if x.startswith("PEAK_KB")][-1].split()
    return int(line[1]) / 1024, seconds, int(line[2]) if line[2] != "None" else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two small cases only")
    args = parser.parse_args(argv)
    print(f"memory limit {memory_limit() / 2 ** 30:.1f} GiB; yardstick: the same mechanism at {YARDSTICK} samples")
    print(f"{'mechanism':<17} {'samples':>8} {'peak MiB':>9} {'above yard':>10} {'estimate':>9} "
          f"{'ratio':>6} {'seconds':>8} {'x yard':>7}")
    worst = 0.0
    for mech, samples in (QUICK if args.quick else CASES):
        m = resolve(mech)
        base_mib, base_s, _ = run(mech, YARDSTICK)
        peak, seconds, code = run(mech, samples)
        estimate = (float64_bytes(m, samples) - float64_bytes(m, YARDSTICK)) / 2 ** 20
        ratio = (peak - base_mib) / estimate
        worst = max(worst, ratio)
        print(f"{mech:<17} {samples:>8} {peak:>9.0f} {peak - base_mib:>10.0f} {estimate:>9.0f} "
              f"{ratio:>6.2f} {seconds:>8.1f} {seconds / base_s:>7.1f}" + ("" if code == 0 else f"  exit {code}"))
    peak, seconds, code = run("pendulum", 100_000)
    print(f"\nacceptance: solve pendulum --solver dp --samples 100000: exit {code}, {seconds:.1f} s, "
          f"{peak:.0f} MiB peak (targets: 30 s, 2048 MiB)")
    print(f"worst measured / estimated: {worst:.2f} (must stay below 1)")
    return 0 if worst < 1 and seconds < 30 and peak < 2048 else 1


if __name__ == "__main__":
    sys.exit(main())
