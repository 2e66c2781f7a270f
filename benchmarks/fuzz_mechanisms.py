"""Run the fuzz corpus (tests/fuzz_corpus.py) through the command line and tabulate outcomes.

Every case is written to a temporary file and run with ``baseparams show`` and
``baseparams solve --solver dp`` in a fresh interpreter with a time limit (20 s by
default). The table counts, per mutation kind: exit codes, tracebacks, hangs (killed at
the limit), exit 0 on input that is invalid, and exit 2 on input that is valid. The
failures are then listed one a line (case, command, verdict, last line of stderr).

    python benchmarks/fuzz_mechanisms.py [--seed 0] [--per-kind 1] [--jobs 2] [--timeout 20]
                                         [--mechanism pendulum ...] [--kind wrong_type ...]

Exit status: 0 when no case fails, 1 otherwise.
"""

import argparse
import sys
import tempfile
import time
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import fuzz_corpus  # noqa: E402  (tests/ is not a package)

COLUMNS = ("runs", "exit0", "exit2", "other", "traceback", "hang", "exit0_on_invalid", "exit2_on_valid")


def tabulate(outcomes) -> str:
    rows = defaultdict(Counter)
    for o in outcomes:
        for key in (o.case.kind, "TOTAL"):
            row = rows[key]
            row["runs"] += 1
            verdict = o.verdict
            if o.returncode in (0, 2) and verdict != "traceback":
                row[f"exit{o.returncode}"] += 1
            elif verdict not in ("hang", "traceback"):
                row["other"] += 1
            if verdict in ("traceback", "hang", "exit0_on_invalid", "exit2_on_valid"):
                row[verdict] += 1
    kinds = [k for k in fuzz_corpus.KINDS if k in rows] + ["TOTAL"]
    width = max(len(k) for k in kinds)
    lines = [f"{'kind':<{width}}  " + "  ".join(f"{c:>{max(len(c), 5)}}" for c in COLUMNS)]
    for kind in kinds:
        lines.append(f"{kind:<{width}}  " + "  ".join(f"{rows[kind][c]:>{max(len(c), 5)}}" for c in COLUMNS))
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--per-kind", type=int, default=1, help="mutations of each kind per mechanism")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at the same time")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds before a run counts as a hang")
    parser.add_argument("--mechanism", action="append", help="only these built-in mechanisms")
    parser.add_argument("--kind", action="append", help="only these mutation kinds")
    args = parser.parse_args(argv)

    cases = fuzz_corpus.corpus(args.seed, args.per_kind, args.mechanism,
                               tuple(args.kind) if args.kind else fuzz_corpus.KINDS)
    jobs = [(case, command) for case in cases for command in fuzz_corpus.COMMANDS]
    print(f"{len(cases)} cases x {len(fuzz_corpus.COMMANDS)} commands = {len(jobs)} runs "
          f"(seed {args.seed}, limit {args.timeout:g} s, {args.jobs} at a time)", flush=True)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz_mechanisms_") as tmp, ThreadPoolExecutor(args.jobs) as pool:
        outcomes = list(pool.map(lambda job: fuzz_corpus.run_case(*job, Path(tmp), args.timeout), jobs))
    print(f"done in {time.perf_counter() - start:.0f} s; slowest run "
          f"{max(o.seconds for o in outcomes):.1f} s\n")
    print(tabulate(outcomes))
    failures = [o for o in outcomes if o.verdict != "ok"]
    if failures:
        print(f"\n{len(failures)} failing runs:")
        for o in failures:
            print(f"  {o.case.name:<34} {o.command:<5} {o.verdict:<16} {o.case.detail[:60]}")
            if o.message:
                print(f"  {'':<34} {o.message[:150]}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
