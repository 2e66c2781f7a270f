"""Benchmark: the symbolic solver (not run by CI; prints its figures).

- SLA suspension: the whole solver (body conditions by sampling, rule generators, exact
  elimination, base expressions, and the ball-arithmetic rank check at 40 digits, at the
  random states whose rows carry it). Goal: <= 5 s on the 2-core reference machine.
- The same without the rank check, split into its stages.
- Every built-in mechanism once, with the check: rank, certified, seconds.

Run: python benchmarks/bench_symbolic.py [--repeat R]
"""

import argparse
import platform
import time

from baseparams import registry
from baseparams.plugins.solvers.symbolic.body_conditions import analyse_bodies, random_states
from baseparams.io.loader import resolve
from baseparams.cli.report import render
from baseparams.plugins.solvers.symbolic.elimination import solve


def best_of(repeat, fn):
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return min(times), out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"python {platform.python_version()} on {platform.machine()}, best of {args.repeat}")

    sla = resolve("sla_suspension")
    t, r = best_of(args.repeat, lambda: solve(sla))
    goal = "ok" if t <= 5 else "SLOWER THAN THE 5 s GOAL"
    print(f"SLA symbolic, certified at 40 digits: {t:.2f} s  (rank {r.rank}, certified {r.certified}) [{goal}]")

    t_states, (states, _) = best_of(args.repeat, lambda: random_states(sla))
    t_bodies, _ = best_of(args.repeat, lambda: analyse_bodies(sla, states=states))
    t_nocert, r = best_of(args.repeat, lambda: solve(sla, certify_rank=False))
    t_report, _ = best_of(args.repeat, lambda: render(r, "latex"))
    print(f"  without the rank check: {t_nocert:.2f} s  (random states {t_states:.2f} s, "
          f"body conditions {t_bodies:.2f} s, LaTeX report {t_report:.2f} s)")

    print("built-in mechanisms (certified run):")
    for name in registry.mechanisms():
        mech = resolve(name)
        t, r = best_of(1, lambda: solve(mech))
        print(f"  {name:16s} {len(mech.parameters):4d} parameters  rank {r.rank:3d}  "
              f"certified {str(r.certified):5s}  {t:6.2f} s")


if __name__ == "__main__":
    main()
