"""Benchmark: `baseparams validate --all` in-process against 2 local worker processes and a
2-worker Dask LocalCluster (not run by CI; prints its figures).

Each configuration validates every registered mechanism with every registered solver plus
the model checks, measured in one run of this script so that the ratios compare like with
like on a shared machine. The in-process run is the yardstick: the ratios are its wall time
divided by the others'.

Run: python benchmarks/bench_validate.py [--mechanisms a,b,...] [--no-dask]
"""

import argparse
import os
import platform
import time

from baseparams import registry
from baseparams.orchestrate.runners import DaskCluster, InProcess, Processes
from baseparams.orchestrate.validate import mechanism_texts, validate


def timed(label, runner, texts):
    start = time.perf_counter()
    report = validate(texts, runner=runner)
    wall = time.perf_counter() - start
    jobs = sum(row["seconds"] for m in report.mechanisms for row in m.solvers.values())
    print(f"{label:<28} {wall:7.1f} s wall   (solver jobs add up to {jobs:6.1f} s)   "
          f"{'all agree' if report.ok else 'DISAGREEMENT'}")
    return wall, report


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mechanisms", default=None, help="comma separated (default: all registered)")
    parser.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster run")
    args = parser.parse_args()
    names = args.mechanisms.split(",") if args.mechanisms else list(registry.mechanisms())
    texts = mechanism_texts(names)
    print(f"python {platform.python_version()} on {platform.machine()}, {os.cpu_count()} cores; "
          f"{len(texts)} mechanisms x {len(registry.solvers())} solvers + model checks")
    base, _ = timed("in-process (yardstick)", InProcess(), texts)
    two, _ = timed("2 worker processes", Processes(2), texts)
    print(f"{'':<28} ratio in-process / 2 workers = {base / two:.2f}")
    if not args.no_dask:
        try:
            cluster = DaskCluster("local", 2)
        except Exception as exc:         # the optional extra is missing: say so, go on
            print(f"Dask LocalCluster: not run ({exc})")
        else:
            dask, _ = timed("Dask LocalCluster, 2 workers", cluster, texts)
            print(f"{'':<28} ratio in-process / Dask = {base / dask:.2f}")


if __name__ == "__main__":
    main()
