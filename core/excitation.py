"""Independent random batches that check whether a trajectory excites a mechanism.

A trajectory that does not excite every base parameter (too few samples, a coordinate
that never accelerates ...) gives W a clean ridge at too low a rank: every missing
direction is an exact zero of W, so no precision shows it. Rows of W at states chosen
independently of the trajectory do. The numeric solvers analyse W together with such a
batch before they trust (or certify) a rank.
"""

import math
import random
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from flint import arb, arb_mat, fmpq

from .backends import Float64
from .dynamics import Evaluator
from .trajectory import Trajectory, samples_float64


@dataclass(frozen=True)
class RandomBatch:
    """States independent of the trajectory's samples, for the excitation check.

    Positions are the trajectory's own at random rational times (along the trajectory
    the loops close and Newton has a start); velocities and accelerations are random
    rationals of the trajectory's scale, independent of it. A trajectory that does not
    excite the mechanism (too few samples, a coordinate that never accelerates...) gives
    W a clean ridge at too low a rank: every missing direction is an exact zero of W, so
    no precision shows it; rows at states like these do.
    """
    seed: int
    times: tuple               # Fractions, increasing
    zd: tuple                  # per state: one Fraction per independent coordinate
    zdd: tuple

    @property
    def states(self):
        return len(self.times)


def random_batch(mechanism, trajectory, seed):
    """At least as many rows as parameters (ceil(n / f) states)."""
    f = max(1, len(mechanism.independent))
    count = max(2, math.ceil(len(mechanism.parameters) / f))
    t0, t1 = min(trajectory.times), max(trajectory.times)
    grid = np.linspace(float(t0), float(t1), 101)
    _, zd, zdd = trajectory.independent_values(mechanism, Float64(), grid)
    rng = random.Random(seed)
    times = tuple(sorted(t0 + (t1 - t0) * Fraction(rng.randint(1, 9999), 10000) for _ in range(count)))

    def draw(scales):
        return tuple(s * Fraction(rng.randint(-1000, 1000), 1000) for s in scales)

    vel, acc = _scales(zd), _scales(zdd)
    return RandomBatch(seed, times, tuple(draw(vel) for _ in times), tuple(draw(acc) for _ in times))


def _scales(values):
    """Per coordinate: the largest |value| on the grid to 2 digits (else the largest of the
    others, else 1), as an exact rational."""
    peaks = [float(np.max(np.abs(np.asarray(v, dtype=float)))) for v in values]
    fallback = max(peaks, default=0.0) or 1.0
    return [Fraction(f"{p or fallback:.2g}") for p in peaks]


def batch_matrix(mechanism, backend, trajectory, batch):
    """The batch's rows of W: a numpy array for Float64; for Arb an ``arb_mat`` whose balls
    enclose the exact values (Krawczyk-enclosed positions, as for the trajectory's W)."""

    along = Trajectory(trajectory.expressions, batch.times)
    f = len(mechanism.independent)
    t = np.array([float(x) for x in batch.times])
    start = _positions(mechanism, trajectory, batch) if mechanism.loops else None
    if isinstance(backend, Float64):
        z, _, _ = along.independent_values(mechanism, backend, t)
        z = [np.broadcast_to(np.asarray(v, float), t.shape).copy() for v in z]
        zd = [np.array([float(s[k]) for s in batch.zd]) for k in range(f)]
        zdd = [np.array([float(s[k]) for s in batch.zdd]) for k in range(f)]
        sample = Evaluator(mechanism, backend).sample(z, zd, zdd, start, where="check batch: ")
        return sample.regressor_array().reshape(len(t) * f, len(mechanism.parameters))
    ev = Evaluator(mechanism, backend, certify=True)
    rows = []
    with backend.activate():
        for index, tk in enumerate(batch.times):
            z, _, _ = along.independent_values(mechanism, backend, arb(fmpq(tk.numerator, tk.denominator)))
            guess = None
            if start is not None:
                guess = [backend.rational(Fraction(float(v[index]))) for v in start]
            sample = ev.sample(z, [backend.rational(v) for v in batch.zd[index]],
                               [backend.rational(v) for v in batch.zdd[index]], guess,
                               where=f"check state at t = {float(tk):.6g} s: ")
            rows.extend(sample.regressor())
        return arb_mat(len(rows), len(rows[0]), [arb(v) for row in rows for v in row])


def _positions(mechanism, trajectory, batch, grid=200):
    """float64 tree coordinates at the batch's times (a closed loop's start for Newton):
    followed along the trajectory on a uniform grid of its time span that includes them,
    since a closure solved from far away may not converge or find another branch."""
    t0, t1 = min(trajectory.times), max(trajectory.times)
    times = sorted({t0 + (t1 - t0) * Fraction(k, grid - 1) for k in range(grid)} | set(batch.times))
    sample, t = samples_float64(mechanism, Trajectory(trajectory.expressions, tuple(times)))
    where = [times.index(tk) for tk in batch.times]
    return [np.broadcast_to(np.asarray(q, float), t.shape)[where].copy() for q in sample.q]
