"""Benchmark: the symbolic solver at scale, phase by phase (not run by CI; prints its figures).

(benchmarks/bench_symbolic.py times the SLA and the built-in mechanisms; this one the
generated chains and tree of issue 12.)

Cases: random serial chains of 12, 24 and 48 bodies and a random tree of 12 (the seeds of
benchmarks/bench_scaling.py), and the SLA suspension. Each (case, solver) runs in its own
subprocess (its peak RSS is its own). Printed per case: the symbolic solver's time (the
mechanism already parsed), where it goes (body conditions, sampled transfers, elimination,
the certificate's W in balls, the rank proof, the generator checks), its peak RSS, and the
yardstick measured in the same run: dp on the same case (one float64 SVD). For the SLA the
whole process (`baseparams solve sla_suspension --solver symbolic`, imports included) is
timed too, against the same command with dp.

To compare with a previous version of the solver in the same run, copy its
plugins/solvers/symbolic directory to DIR/old_symbolic and run with
``PYTHONPATH=DIR ... --previous old_symbolic.elimination`` (its ``solve`` is timed too).

Targets (issue 12): symbolic 48-body chain <= 30 s; SLA whole process <= 2 s.

Run: OPENBLAS_NUM_THREADS=1 python benchmarks/bench_symbolic_scale.py [--quick] [--previous MODULE]
"""

import argparse
import functools
import importlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from baseparams.model import generate

CHAIN_SEED, TREE_SEED = 1, 3
PHASES = (("analyse_bodies", "body conditions"), ("sampled_joint_transfers", "sampled transfers"),
          ("observation_matrix", "W (arb + f64)"), ("columns_independent", "rank proof"),
          ("analyse", "ball analysis"))


def cases(quick: bool):
    out = [(f"chain {n}", generate.serial_chain(CHAIN_SEED, bodies=n)) for n in ((12, 24) if quick else (12, 24, 48))]
    out.append(("tree 12", generate.tree(TREE_SEED, bodies=12)))
    out.append(("sla", None))
    return out


# ----- one case, in a child process ------------------------------------------------------------
def run_one(path: str, solver: str) -> None:
    """Solve and print one JSON line: seconds, phase seconds, peak RSS, rank, certified."""
    from baseparams import registry
    from baseparams.io.loader import load_mechanism, resolve

    mech = resolve(path) if path == "sla_suspension" else load_mechanism(path)
    phases = defaultdict(float)
    if solver == "dp":
        solve = functools.partial(registry.solvers()["dp"].item.solve, mech)
    else:
        module = importlib.import_module(solver)
        for name, _ in PHASES:
            if hasattr(module, name):
                setattr(module, name, _timed(getattr(module, name), name, phases))
        solve = functools.partial(module.solve, mech)
    start = time.perf_counter()
    result = solve()
    seconds = time.perf_counter() - start
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "phases": phases, "rss_mb": rss, "rank": result.rank,
                      "certified": result.certified}))


def _timed(function, name, phases):
    @functools.wraps(function)
    def run(*args, **kwargs):
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            phases[name] += time.perf_counter() - start
    return run


def measure(path: str, solver: str) -> dict:
    done = subprocess.run([sys.executable, __file__, "--one", path, solver], capture_output=True, text=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        return {"error": (done.stderr.strip().splitlines() or ["?"])[-1][:120]}
    return json.loads(lines[-1])


def whole_process(solver: str) -> float:
    start = time.perf_counter()
    subprocess.run(["baseparams", "solve", "sla_suspension", "--solver", solver], capture_output=True, check=True)
    return time.perf_counter() - start


def describe(r: dict, dp: dict) -> str:
    if "error" in r:
        return f"error: {r['error']}"
    ratio = f" ({r['seconds'] / dp['seconds']:.1f}x dp)" if "seconds" in dp else ""
    phases = r.get("phases", {})
    named = sum(phases.values())
    parts = ", ".join(f"{label} {phases[name]:.1f}" for name, label in PHASES if name in phases)
    other = f", rest {r['seconds'] - named:.1f}" if phases else ""
    return (f"{r['seconds']:.1f} s{ratio}, {r['rss_mb']:.0f} MB, rank {r['rank']}"
            f"{' certified' if r['certified'] else ''} [{parts}{other}]")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="chains of 12 and 24 bodies only")
    parser.add_argument("--previous", default=None, help="module of a previous solver version to time too")
    parser.add_argument("--one", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        run_one(*args.one)
        return
    current = "baseparams.plugins.solvers.symbolic.elimination"
    versions = [("symbolic", current)] + ([("previous", args.previous)] if args.previous else [])
    workdir = Path(tempfile.mkdtemp())
    print(f"python {sys.version.split()[0]}; OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', '-')}; "
          f"load {os.getloadavg()[0]:.1f}; yardstick: dp on the same case, same run")
    for label, text in cases(args.quick):
        if text is None:
            path = "sla_suspension"
        else:
            path = str(workdir / f"{label.replace(' ', '_')}.toml")
            Path(path).write_text(text)
        dp = measure(path, "dp")
        print(f"{label}: dp {dp.get('seconds', float('nan')):.2f} s")
        for name, module in versions:
            print(f"  {name:9s} {describe(measure(path, module), dp)}", flush=True)
    sym, dp = whole_process("symbolic"), whole_process("dp")
    print(f"sla whole process: symbolic {sym:.2f} s, dp {dp:.2f} s ({sym / dp:.2f}x dp)")


if __name__ == "__main__":
    main()
