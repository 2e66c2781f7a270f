"""Benchmark: the costs that explain design choices in the code (not run by CI).

Docstrings and comments say *why* (an import deferred, a cache, a hand-written loop) without
a number that would go stale; the numbers are here, measured on the machine at hand, and in
docs/performance.md ("Costs behind design choices") with the code they justify. Each line
prints the figure, where it is used, and a yardstick measured in the same run where one fits.

Run: python benchmarks/bench_design_notes.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_regressor import best_of  # noqa: E402


def best(fn: Callable[[], object], repeat: int) -> float:
    """The smallest of ``repeat`` wall times of ``fn()`` (seconds)."""
    return best_of(repeat, fn)[0]


def import_seconds(modules: str, before: str = "numpy", repeat: int = 3) -> float:
    """Median seconds to import ``modules`` in a fresh process that already imported ``before``."""
    code = (f"import time, {before}; t = time.perf_counter(); import {modules}; "
            "print(time.perf_counter() - t)")
    runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True).stdout) for _ in range(repeat)]
    return statistics.median(runs)


def row(figure: str, where: str) -> None:
    print(f"{figure:<58} {where}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="repetitions per figure (the best is kept) [5]")
    args = parser.parse_args()

    import numpy as np
    import sympy

    from baseparams.dynamics.trajectory import T
    from baseparams.io.loader import resolve
    from baseparams.kinematics.tree import TreeKinematics
    from baseparams.model import generate
    from baseparams.io.loader import parse_mechanism
    from baseparams.numeric.backends import Float64, Symbolic

    print(f"{'figure':<58} where it explains a choice")
    # numpy's per-call dispatch against its arithmetic at a thousand samples
    a, b, out = np.ones(1000), np.ones(1000), np.empty(1000)
    one, one_out = np.ones(1), np.empty(1)
    n = 20000
    small = best(lambda: [np.multiply(one, one, out=one_out) for _ in range(n)], args.repeat) / n
    large = best(lambda: [np.multiply(a, b, out=out) for _ in range(n)], args.repeat) / n
    row(f"numpy multiply: {small * 1e6:.2f} us dispatch, {(large - small) * 1e6:.2f} us arithmetic (1000)",
        "core/dynamics/codegen.py _numpy_kernel")

    # imports deferred to where they are needed
    row(f"import scipy.linalg after numpy: {import_seconds('scipy.linalg'):.2f} s",
        "core/numeric/linalg.py, certify.py, plugins/solvers/symbolic/rank_bound.py")
    stats = import_seconds("scipy.signal, scipy.stats, statsmodels.api", before="numpy, sympy")
    row(f"import scipy.signal, scipy.stats, statsmodels.api: {stats:.2f} s", "core/cli/diagnose.py, identify.py")

    # sympy costs that caches and forward-mode derivatives avoid
    sla = resolve("sla_suspension")
    chain = parse_mechanism(generate.serial_chain(1, bodies=12))
    expressions = list(chain.trajectory.expressions.values())
    diff = best(lambda: [sympy.diff(sympy.diff(e, T), T) for e in expressions], 1) / len(expressions)
    row(f"sympy: two derivatives of a trajectory expression: {diff:.3f} s", "core/dynamics/trajectory.py")
    frames = [frame for joint in sla.joints for frame in (joint.parent_frame, joint.child_frame)]
    subs = best(lambda: [sla.numeric_frame(f, Symbolic(), symbolic=True) for f in frames], 1) / len(frames)
    row(f"sympy: one symbolic frame of the SLA: {subs * 1e3:.1f} ms", "core/dynamics/transfers.py symbolic_frame")
    frames_time = best(lambda: TreeKinematics(resolve("sla_suspension"), Float64()), args.repeat)
    row(f"TreeKinematics of a freshly loaded SLA (float64): {frames_time:.2f} s", "core/kinematics/tree.py")
    gc.collect()
    collect = best(gc.collect, args.repeat)
    row(f"gc.collect() in this process (sympy and the SLA loaded): {collect * 1e3:.0f} ms",
        "core/diagnose/wald.py holm")


if __name__ == "__main__":
    main()
