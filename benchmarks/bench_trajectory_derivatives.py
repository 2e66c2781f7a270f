"""Trajectory derivatives by forward-mode jets (dynamics.trajectory.values_at) against the
previous method, sympy derivatives differentiated once per process and then evaluated,
measured in one run.

    python benchmarks/bench_trajectory_derivatives.py [--bodies 12] [--solver dp]

Each method solves its own freshly parsed copy of the same generated chain (so each pays
the per-mechanism work once, as a new process would); a warm-up on another chain loads
the modules first. Prints both solve times and the ratio.
"""

import argparse
import time

from baseparams import registry
from baseparams.dynamics import trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate


def _sympy_values_at(expression, backend, t):
    """The previous method: (q, qd, qdd) from sympy's derivatives (cached per process)."""
    return tuple(backend.evaluate(e, {"t": t}) for e in trajectory._derivatives(expression))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=12)
    parser.add_argument("--solver", default="dp")
    args = parser.parse_args()
    solver = registry.solvers()[args.solver].item
    solver.solve(parse_mechanism(generate.serial_chain(2, bodies=args.bodies)))    # warm-up
    text = generate.serial_chain(1, bodies=args.bodies)
    jets = trajectory.values_at
    times = {}
    for label, function in (("sympy derivatives (previous)", _sympy_values_at), ("jets", jets)):
        mechanism = parse_mechanism(text)
        trajectory.values_at = function
        start = time.perf_counter()
        solver.solve(mechanism)
        times[label] = time.perf_counter() - start
    trajectory.values_at = jets
    for label, seconds in times.items():
        print(f"{args.solver}, {args.bodies}-body generated chain, {label}: {seconds:.2f} s")
    print(f"ratio jets / sympy derivatives: {times['jets'] / times['sympy derivatives (previous)']:.3f}")


if __name__ == "__main__":
    main()
