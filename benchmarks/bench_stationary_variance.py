"""The Wald test of a direction acting on few samples, on coloured noise (issue 21): its
rejection rate at 5 % as ``wald.wald`` makes it on whitened data (the stationary
variance, truncated kernel floored by Bartlett's, scaled by the noise's local power where
the direction acts), against the Bartlett-tapered stationary variance alone and the
classical sigma^2 I; on AR(1) noise of one level, and with the noise ``--louder`` times
larger on 60 samples around the direction (as at a velocity reversal); and the CPU time of
one such test against one dense HAC Wald test of the same size (the yardstick, measured in
the same run).

    python benchmarks/bench_stationary_variance.py [--draws 2000] [--rho 0.6] [--louder 3]
"""

import argparse
import time

import numpy as np
from scipy.signal import lfilter
from scipy.stats import chi2

from baseparams.identify import longrun
from baseparams.diagnose import wald as W


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--draws", type=int, default=2000)
    parser.add_argument("--rho", type=float, default=0.6)
    parser.add_argument("--samples", type=int, default=400)
    parser.add_argument("--louder", type=float, default=3.0, help="the noise's level around the direction [3]")
    args = parser.parse_args()
    n = args.samples
    t = np.linspace(0.0, 10.0, n)
    Q = W.orthonormal_basis(np.stack([np.ones(n), np.sin(t), np.cos(0.7 * t)], axis=1), 1e-12)
    z = np.zeros(n)
    z[n // 2:n // 2 + 6] = 1.0                               # a direction on 6 samples
    U = W.orthonormal_basis(W.project_out(z[:, None], Q), W.ABSORB_TOL, reference=z[:, None])
    dense = W.orthonormal_basis(W.project_out(np.sin(3.1 * t)[:, None], Q), W.ABSORB_TOL)
    around = np.ones(n)
    around[n // 2 - 30:n // 2 + 30] = args.louder
    rng = np.random.default_rng(11)
    for label, level in (("one level", np.ones(n)), (f"{args.louder:g} x on 60 samples around it", around)):
        wald, bartlett, classical, sparse_cpu, dense_cpu = [], [], [], 0.0, 0.0
        for _ in range(args.draws):
            y = lfilter([np.sqrt(1 - args.rho ** 2)], [1.0, -args.rho], rng.standard_normal(n)) * level
            e = y - Q @ (Q.T @ y)
            started = time.process_time()
            test = W.wald(e, U, (n, 1), 3, sparse_if_white=True, sparse_if_coloured=True)
            sparse_cpu += time.process_time() - started
            started = time.process_time()
            W.wald(e, dense, (n, 1), 3)
            dense_cpu += time.process_time() - started
            wald.append(test.pvalue <= 0.05)
            g = float(U[:, 0] @ e)
            rest = e - U[:, 0] * g
            V = longrun.stationary_variance(rest[:, None], U[:, None, :], test.lags, n - 4.0)[0, 0]
            bartlett.append(chi2.sf(g * g / V, 1) <= 0.05)
            classical.append(chi2.sf(g * g / (float(e @ e) / (n - 4)), 1) <= 0.05)
        print(f"a 6-sample direction, AR(1) {args.rho} noise ({label}), {n} samples, {args.draws} draws: "
              f"rejections at 5 %: wald {np.mean(wald):.1%}, stationary variance (Bartlett, one level) "
              f"{np.mean(bartlett):.1%}, classical {np.mean(classical):.1%}")
        print(f"  CPU per test: sparse (wald) {1e3 * sparse_cpu / args.draws:.2f} ms, dense HAC "
              f"{1e3 * dense_cpu / args.draws:.2f} ms (ratio {sparse_cpu / max(dense_cpu, 1e-12):.2f})")


if __name__ == "__main__":
    main()
