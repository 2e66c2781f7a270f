"""Benchmark: how every solver scales with the mechanism (not run by CI; prints its figures).

Cases: random serial chains of 6, 12, 24 and 48 bodies (core/model/generate.py, R and P
joints), a random tree of 12 bodies, ladders of 1, 2 and 4 random four-bars in series (each
mounted on the previous one's rocker: closed loops that grow) and the Stewart platform.
Each (case, solver) runs in its own subprocess, so its peak RSS is its own, with a time
limit; the time is the solver's (mechanism already parsed), the whole process's is given
too. The growth exponent k of time ~ parameters^k is fitted over the chains per solver. A
log-log plot of time against parameters is written to docs/scaling.png.

The yardstick measured in the same run is dp, whose cost is one float64 SVD: the table
gives each solver's time as a ratio to dp's on the same case.

Targets (issue 12): vp 24-body chain <= 20 s and <= 400 MB, 48-body <= 120 s; symbolic
48-body <= 30 s. They are printed against the measured figures at the end (never asserted).
Each child also reports its CPU time (``cpu_s``): on the shared 2-core machine wall time
varies 2x with load, CPU time much less.

Run: python benchmarks/bench_scaling.py [--limit S] [--solvers dp,vp,exact,symbolic] [--quick]
                                        [--cases "chain 24,chain 48"]
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from baseparams.model import generate

ROOT = Path(__file__).resolve().parents[1]
CHAIN_SEED, TREE_SEED = 1, 3
SOLVERS = ("dp", "vp", "exact", "symbolic")
CERTIFYING = ("vp", "exact")
TARGETS = (("chain 24", "vp", 20, 400), ("chain 48", "vp", 120, None), ("chain 48", "symbolic", 30, None))


def cases(quick: bool):
    sizes = (6, 12, 24) if quick else (6, 12, 24, 48)
    out = [(f"chain {n}", "chain", generate.serial_chain(CHAIN_SEED, bodies=n)) for n in sizes]
    out.append(("tree 12", "tree", generate.tree(TREE_SEED, bodies=12)))
    out += [(f"ladder {n}", "ladder", generate.ladder(n)) for n in ((1, 2) if quick else (1, 2, 4))]
    out.append(("stewart", "stewart", (ROOT / "mechanisms" / "stewart_platform.toml").read_text()))
    return out


# ----- one case, in a child process ------------------------------------------------------------
def run_one(path: str, solver_name: str) -> None:
    """Solve the mechanism file at ``path`` and print one JSON line: time, peak RSS, rank."""
    import resource
    from baseparams import registry
    from baseparams.io.loader import load_mechanism

    mech = load_mechanism(path)
    solver = registry.solvers()[solver_name].item
    reason = solver.applicable(mech)
    if reason:
        print(json.dumps({"skipped": reason}))
        return
    start, cpu = time.perf_counter(), time.process_time()
    result = solver.solve(mech)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "cpu_s": cpu, "rss_mb": rss, "rank": result.rank,
                      "certified": result.certified, "parameters": len(mech.parameters)}))


def measure(path: Path, solver: str, limit: float) -> dict:
    start = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, __file__, "--one", str(path), solver], capture_output=True,
                              text=True, timeout=limit)
    except subprocess.TimeoutExpired:
        return {"timeout": limit}
    out = {"process_s": time.perf_counter() - start}
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        tail = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {**out, "error": tail[:120]}
    return {**out, **json.loads(lines[-1])}


def cell(r: dict, dp: dict | None, solver: str) -> str:
    if "timeout" in r:
        return f"> {r['timeout']:.0f} s"
    if "skipped" in r:
        return "n/a"
    if "error" in r:
        return "error"
    ratio = f" ({r['seconds'] / dp['seconds']:.2g}x dp)" if dp and "seconds" in dp and dp["seconds"] > 0 else ""
    mark = " (not certified)" if solver in CERTIFYING and not r.get("certified", True) else ""
    return f"{r['seconds']:.1f} s, {r['rss_mb']:.0f} MB{ratio}{mark}"


def exponent(points):
    """k of time ~ parameters^k, least squares in log-log (None with fewer than 2 points)."""
    if len(points) < 2:
        return None
    x, y = np.log([p for p, _ in points]), np.log([t for _, t in points])
    return float(np.polyfit(x, y, 1)[0])


def plot(results, solvers, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    markers = {"chain": "o-", "tree": "s", "ladder": "^--", "stewart": "D"}
    for s, color in zip(solvers, ("C0", "C1", "C2", "C3")):
        for kind, style in markers.items():
            pts = sorted((r["parameters"], r["seconds"]) for (c, k), by in results.items() if k == kind
                         for name, r in by.items() if name == s and "seconds" in r)
            if pts:
                ax.loglog(*zip(*pts), style, color=color, label=f"{s} ({kind})" if kind in ("chain", "ladder") else None)
    ax.set_xlabel("inertial parameters (10 per body)")
    ax.set_ylabel("solver time (s)")
    ax.set_title("baseparams: time against size (chains: lines; ladders of four-bars: dashed)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit", type=float, default=300.0, help="seconds per (case, solver) [300]")
    parser.add_argument("--solvers", default=",".join(SOLVERS))
    parser.add_argument("--quick", action="store_true", help="chains up to 24 bodies, ladders up to 2")
    parser.add_argument("--cases", default=None,
                        help='only these cases, by label or kind: "chain 24,chain 48", "chain,stewart"')
    parser.add_argument("--plot", default=None,
                        help="write the log-log plot here [docs/scaling.png; none with --cases]")
    parser.add_argument("--json", default=None, help="also write the raw figures here")
    parser.add_argument("--from-json", default=None, help="report a run written by --json, no solving")
    parser.add_argument("--one", nargs=2, metavar=("FILE", "SOLVER"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        run_one(*args.one)
        return
    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    plot_path = args.plot or (None if args.cases else str(ROOT / "docs" / "scaling.png"))
    if args.from_json:                   # the table, exponents and plot of an earlier run
        data = json.loads(Path(args.from_json).read_text())
        report({(label, label.split()[0]): by for label, by in data.items()}, solvers, plot_path)
        return
    workdir = Path(subprocess.check_output([sys.executable, "-c", "import tempfile; print(tempfile.mkdtemp())"],
                                           text=True).strip())
    results = {}
    print(f"python {sys.version.split()[0]}; limit {args.limit:.0f} s per case; yardstick: dp on the same case")
    header = "| case | parameters | " + " | ".join(solvers) + " |"
    rows = [header, "|" + "---|" * (len(solvers) + 2)]
    wanted = {c.strip() for c in args.cases.split(",")} if args.cases else None
    for label, kind, text in cases(args.quick):
        if wanted is not None and label not in wanted and kind not in wanted:
            continue
        path = workdir / f"{label.replace(' ', '_')}.toml"
        path.write_text(text)
        by = {s: measure(path, s, args.limit) for s in solvers}
        results[(label, kind)] = by
        params = next((r["parameters"] for r in by.values() if "parameters" in r), "?")
        for r in by.values():
            r.setdefault("parameters", params)
        rows.append(f"| {label} | {params} | " + " | ".join(cell(by[s], by.get("dp"), s) for s in solvers) + " |")
        print(rows[-1], flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({f"{c}": by for (c, _), by in results.items()}, indent=1))
    report(results, solvers, plot_path)


def report(results, solvers, plot_path):
    """The markdown table, the fitted exponents and the plot."""
    rows = ["| case | parameters | " + " | ".join(solvers) + " |", "|" + "---|" * (len(solvers) + 2)]
    for (label, _), by in results.items():
        params = next((r["parameters"] for r in by.values() if "parameters" in r), "?")
        rows.append(f"| {label} | {params} | " + " | ".join(cell(by.get(s, {"skipped": 1}), by.get("dp"), s)
                                                           for s in solvers) + " |")
    print("\n" + "\n".join(rows))
    print("\ngrowth exponent k (time ~ parameters^k, serial chains):")
    for s in solvers:
        pts = [(r["parameters"], r["seconds"]) for (label, kind), by in results.items() if kind == "chain"
               for name, r in by.items() if name == s and "seconds" in r]
        k = exponent(pts)
        print(f"  {s:9s} " + ("-" if k is None else f"{k:.2f}") + f"  ({len(pts)} chains)")
    print("\ntargets (issue 12), measured in this run:")
    for label, solver, seconds, mb in TARGETS:
        r = next((by.get(solver) for (c, _), by in results.items() if c == label), None)
        if not r or "seconds" not in r:
            continue
        dp = next((by.get("dp") for (c, _), by in results.items() if c == label), None)
        ratio = f", {r['seconds'] / dp['seconds']:.2g}x dp" if dp and dp.get("seconds") else ""
        memory = f" and <= {mb} MB: {r['rss_mb']:.0f} MB" if mb else ""
        ok = r["seconds"] <= seconds and (not mb or r["rss_mb"] <= mb)
        print(f"  {solver} {label}: <= {seconds} s{memory}; {r['seconds']:.1f} s"
              + (f" ({r['cpu_s']:.1f} s CPU)" if "cpu_s" in r else "") + f"{ratio}: {'met' if ok else 'NOT met'}")
    if plot_path:
        plot(results, solvers, Path(plot_path))
        print(f"\nplot: {plot_path}")


if __name__ == "__main__":
    main()
