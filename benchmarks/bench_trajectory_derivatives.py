"""Trajectory derivatives differentiated once per process (dynamics.trajectory._derivatives)
against differentiating them at every call, measured in one run.

    python benchmarks/bench_trajectory_derivatives.py [--bodies 12] [--solver dp]

Prints the solve time with the cache and without it (sympy.diff at every call), and the ratio.
"""

import argparse
import time

import sympy

from baseparams import registry
from baseparams.dynamics import trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate


def _uncached(expression):
    d1 = sympy.diff(expression, trajectory.T)
    return expression, d1, sympy.diff(d1, trajectory.T)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=12)
    parser.add_argument("--solver", default="dp")
    args = parser.parse_args()
    mechanism = parse_mechanism(generate.serial_chain(1, bodies=args.bodies))
    solver = registry.solvers()[args.solver].item
    solver.solve(mechanism)                                   # warm-up: imports, generated code
    cached = trajectory._derivatives
    times = {}
    for label, function in (("differentiated at every call", _uncached), ("cached", cached)):
        trajectory._derivatives = function
        cached.cache_clear()
        start = time.perf_counter()
        solver.solve(mechanism)
        times[label] = time.perf_counter() - start
    trajectory._derivatives = cached
    for label, seconds in times.items():
        print(f"{args.solver}, {args.bodies}-body generated chain, {label}: {seconds:.2f} s")
    print(f"ratio cached / uncached: {times['cached'] / times['differentiated at every call']:.2f}")


if __name__ == "__main__":
    main()
