"""Recordings with known truth outside the model's expectations: how far identify's base
parameters move and whether the stated standard deviations hold, through a recording
description (filtering and decimation as by default) on a generated 3-R chain.

Cases: white noise (2 % of each coordinate's largest force), AR(1) noise at 0.9, a 3 ms delay
of the torques, and Coulomb friction with a tanh shape (0.3 tanh(qd / 0.05)) fitted as sign(qd).
Then the calibration of the stated std over ``--seeds`` white-noise recordings, decimated and
only filtered: the SD of (estimate - truth) / std should be near 1. CPU seconds per identify
beside one least-squares fit of the same size (the yardstick, measured in the same run).

    python benchmarks/bench_recordings.py [--seeds 12]
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from baseparams import registry
from baseparams.dynamics.trajectory import Trajectory
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify
from baseparams.dynamics.forces import Motion, design
from baseparams.recordings.recording import read_recording
from baseparams.recordings.simulate import random_physical_inertia
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec
from baseparams.numeric.backends import Float64

RATE = 1000.0
CHANNELS = '[position]\nq1 = "a"\nq2 = "b"\nq3 = "c"\n[torque]\nq1 = "x"\nq2 = "y"\nq3 = "z"\n'


def fit(mech, base, t, q, tau, folder: Path, settings: str = "", effects=()):
    table = np.column_stack([t, q, tau])
    (folder / "log.csv").write_text("t,a,b,c,x,y,z\n" + "\n".join(",".join(f"{v:.17g}" for v in r) for r in table))
    (folder / "rec.toml").write_text('[recording]\ntime = "t"\n' + settings + '[[runs]]\nfile = "log.csv"\n' + CHANNELS)
    start = time.process_time()
    data, model = read_recording(folder / "rec.toml", mech)
    result = identify(model, data, base=base, effects=effects)
    return result, time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=12)
    args = parser.parse_args()
    mech = parse_mechanism(generate.serial_chain(3, bodies=3, types="R"))
    phi = random_physical_inertia(mech, np.random.default_rng(3))
    base = BaseModel.from_result(registry.solvers()["dp"].item.solve(mech), mech)
    truth = base.values(phi)
    t = np.arange(0, 10, 1 / RATE)
    z, zd, zdd = Trajectory.default(mech).independent_values(mech, Float64(), t)
    motion = Motion(t, *(np.stack([np.asarray(v, float) for v in a], axis=1) for a in (z, zd, zdd)))
    tau = design(mech, motion)[0].matrix @ phi
    rng = np.random.default_rng(0)
    sd = 0.02 * np.abs(tau).max(axis=0)
    ar = np.zeros_like(tau)
    shocks = rng.normal(0, 1, tau.shape) * sd * np.sqrt(1 - 0.9 ** 2)
    for k in range(1, len(t)):
        ar[k] = 0.9 * ar[k - 1] + shocks[k]
    cases = {"white noise": (tau + rng.normal(0, 1, tau.shape) * sd, ()),
             "AR(1) 0.9 noise": (tau + ar, ()),
             "delay 3 ms": (np.vstack([tau[:3], tau[:-3]]), ()),
             "tanh friction on q1": (tau + np.column_stack([0.3 * np.tanh(motion.qd[:, 0] / 0.05), 0 * t, 0 * t]),
                                     (EffectSpec("coulomb_friction", "q1"),))}
    x = rng.standard_normal((3 * 160, base.rank))
    start = time.process_time()
    for _ in range(200):
        np.linalg.lstsq(x, x[:, 0], rcond=None)
    yardstick = (time.process_time() - start) / 200
    print("| case | max base error / largest | max and median abs(error)/std | CPU s | x one lstsq |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for name, (logged, effects) in cases.items():
            result, cpu = fit(mech, base, t, motion.q, logged, folder, effects=effects)
            error = np.abs(result.base_estimates - truth)
            ratio = error / result.std[:base.rank]
            extra = f"; fc_q1 {result.value('fc_q1'):.3f} for a tanh of 0.3" if effects else ""
            print(f"| {name} | {error.max() / np.abs(truth).max():.2e} | {ratio.max():.1f}, "
                  f"{np.median(ratio):.2f}{extra} | {cpu:.2f} | {cpu / yardstick:.0f} |")
        print()
        print("| filter | SD of (estimate - truth) / std over seeds, median (range) |")
        print("|---|---|")
        for label, settings in (("default (decimated)", ""), ("filtered only", "[filter]\ndecimate = 1\n")):
            zs = []
            for seed in range(args.seeds):
                noisy = tau + np.random.default_rng(100 + seed).normal(0, 1, tau.shape) * sd
                result, _ = fit(mech, base, t, motion.q, noisy, folder, settings)
                zs.append((result.base_estimates - truth) / result.std[:base.rank])
            spread = np.std(zs, axis=0)
            print(f"| {label} | {np.median(spread):.2f} ({spread.min():.2f}-{spread.max():.2f}) |")


if __name__ == "__main__":
    main()
