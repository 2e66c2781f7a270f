"""Benchmark: the JSON form of base-parameter coefficients (issue 45, "floats as floats":
``baseparams.solvers.result.base_json``) against the dp solve that made them (not run by CI;
prints its figures).

The yardstick is the dp solve of the same generated chain, measured in the same run, so the
ratio says what writing the JSON adds to solving, however loaded the machine is.

Run: OPENBLAS_NUM_THREADS=1 python benchmarks/bench_coefficient_json.py [--bodies 30] [--repeat 10]
"""

import argparse
import time

from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.solvers.result import base_json
from baseparams.solvers.run import run_solver


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=30)
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    mechanism = parse_mechanism(generate.serial_chain(3, bodies=args.bodies), f"chain{args.bodies}.toml")
    start = time.process_time()
    result = run_solver("dp", mechanism, {})
    solve = time.process_time() - start
    count = sum(len(b["expression"]) for b in result.base)
    start = time.process_time()
    for _ in range(args.repeat):
        base_json(result.base, result.coefficients or [])
    write = (time.process_time() - start) / args.repeat
    print(f"chain of {args.bodies} bodies: rank {result.rank}, {count} coefficients")
    print(f"dp solve (yardstick)  {solve:8.3f} CPU s")
    print(f"base_json             {write:8.4f} CPU s   ({write / count * 1e6:.1f} us a coefficient; "
          f"ratio to the solve {write / solve:.3f})")


if __name__ == "__main__":
    main()
