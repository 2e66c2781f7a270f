"""Benchmark: building the observation matrix W (not run by CI; prints its figures).

- SLA suspension, N = 200 samples: float64, and arb at 30, 100 and 500 digits
  (goal: 30 digits <= 2 s on the 2-core reference machine).
- PUMA 560 float64, per-sample cost in one vectorised batch (goal: <= 10 us per sample;
  Pinocchio's C++ regressor takes about 5 us per call).

Run: python benchmarks/bench_regressor.py [--repeat R]
"""

import argparse
import platform
import time
import tracemalloc

import numpy as np

from baseparams.numeric.backends import Arb, Float64
from baseparams.io.loader import resolve
from baseparams.dynamics.trajectory import Trajectory, observation_matrix


def best_of(repeat, fn):
    times = []
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def peak_memory_mb(fn):
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2 ** 20


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    sla = resolve("sla_suspension")
    print("\nSLA suspension, W = 400 x 70 (200 samples, 2 dof)")
    print(f"{'arithmetic':>12} {'time (s)':>10} {'peak MB':>8}  closure residual")
    t, _ = best_of(args.repeat, lambda: observation_matrix(sla, Float64()))
    print(f"{'float64':>12} {t:10.3f} {peak_memory_mb(lambda: observation_matrix(sla, Float64())):8.1f}")
    for digits in (30, 100, 500):
        t, (_, info) = best_of(args.repeat if digits < 500 else 1, lambda: observation_matrix(sla, Arb(digits)))
        mem = peak_memory_mb(lambda: observation_matrix(sla, Arb(digits)))
        print(f"{f'arb {digits}':>12} {t:10.3f} {mem:8.1f}  {info['closure_residual']}")

    puma = resolve("puma560")
    print("\nPUMA 560 float64, one vectorised batch (regressor rows = 6 per sample)")
    print(f"{'samples':>8} {'time (s)':>10} {'us/sample':>10}")
    for n in (1000, 10000, 50000):
        trajectory = Trajectory.default(puma, samples=n)
        t, (w, _) = best_of(args.repeat, lambda: observation_matrix(puma, Float64(), trajectory))
        assert w.shape == (6 * n, 60) and np.isfinite(w).all()
        print(f"{n:8d} {t:10.3f} {t / n * 1e6:10.2f}")


if __name__ == "__main__":
    main()
