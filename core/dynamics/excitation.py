"""Independent random batches that check whether a trajectory excites a mechanism.

A trajectory that does not excite every base parameter (too few samples, a coordinate
that never moves or never accelerates ...) gives W a clean ridge at too low a rank:
every missing direction is an exact zero of W, so no precision shows it. Rows of W at
states drawn independently of the trajectory do. The numeric solvers analyse W together
with such a batch before they trust (or certify) a rank.

Positions, velocities and accelerations of the batch are all random: each independent
coordinate is drawn in a box around the trajectory's range (widened, so a coordinate the
trajectory holds still moves here too, and kept inside the joint's limits). Closed
loops are assembled by continuation from the reference configuration, on the same
branch as the trajectory; a draw that cannot be assembled is redrawn closer to the
trajectory's range.
"""

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.observation import RationalStates
from baseparams.numeric.backends import Float64
from baseparams.errors import KinematicsError
from baseparams.dynamics.trajectory import Trajectory
from baseparams.model.mechanism import Mechanism

Box = tuple[float, float, float, float]     # (low, high, trajectory low, trajectory high)

WIDEN_ANGLE = 0.3          # rad added on each side of an angle's range on the trajectory
WIDEN_LENGTH = 0.02        # m added on each side of a length's range
REDRAWS = 8                # attempts per state before it is drawn inside the trajectory's range


@dataclass(frozen=True)
class RandomBatch(RationalStates):
    """States independent of the trajectory: one tuple of Fractions per state for each of
    the independent positions, velocities and accelerations, and the float64 tree
    coordinates of each state (a closed loop's start for Newton at higher precision).
    W at the batch: :func:`baseparams.dynamics.observation.observation_matrix`."""
    seed: int = 0
    name: str = "check state"

    @property
    def states(self) -> int:
        """The number of states (as ``count``)."""
        return self.count


def random_batch(mechanism: Mechanism, trajectory: Trajectory, seed: int) -> RandomBatch:
    """At least as many rows as parameters (ceil(n / f) states)."""
    f = max(1, len(mechanism.independent))
    count = max(2, math.ceil(len(mechanism.parameters) / f))
    t0, t1 = min(trajectory.times), max(trajectory.times)
    grid = np.linspace(float(t0), float(t1), 201)
    z, zd, zdd = trajectory.independent_values(mechanism, Float64(), grid)
    boxes = _boxes(mechanism, z)
    vel, acc = _scales(zd), _scales(zdd)
    rng = random.Random(seed)
    ev = Evaluator(mechanism, Float64())
    states: list[tuple[tuple[Fraction, ...], tuple[Fraction, ...], tuple[Fraction, ...], list[float]]] = []
    for _ in range(count):
        position, start = _assembled_draw(ev, boxes, rng)
        states.append((position, tuple(_draw(rng, vel)), tuple(_draw(rng, acc)), start))
    z_, zd_, zdd_, starts = (tuple(column) for column in zip(*states))
    return RandomBatch(z=z_, zd=zd_, zdd=zdd_, start=starts, seed=seed)


def _boxes(mechanism: Mechanism, values: Sequence[Any]) -> list[Box]:
    """Per independent coordinate: (low, high, trajectory low, trajectory high) as floats."""
    boxes: list[Box] = []
    for name, raw in zip(mechanism.independent, values):
        v = np.asarray(raw, dtype=float)
        lo, hi = float(v.min()), float(v.max())
        joint = mechanism.joint_of_coordinate(name)
        widen = WIDEN_ANGLE if mechanism.coordinate_kind(name) == "angle" else WIDEN_LENGTH
        low, high = lo - widen, hi + widen
        if name in joint.limits:
            limit_lo, limit_hi = joint.limits[name]
            low, high = max(low, limit_lo), min(high, limit_hi)
        boxes.append((low, high, lo, hi))
    return boxes


def _assembled_draw(ev: Evaluator, boxes: Sequence[Box], rng: random.Random) -> tuple[tuple[Fraction, ...], list[float]]:
    """A random position (Fractions) the mechanism can take, with its float tree coordinates."""
    for attempt in range(REDRAWS + 1):
        shrink = Fraction(attempt, REDRAWS)        # 0: the widened box ... 1: the trajectory's range
        position: list[Fraction] = []
        for low, high, lo, hi in boxes:
            a = Fraction(low) + (Fraction(lo) - Fraction(low)) * shrink
            b = Fraction(high) + (Fraction(hi) - Fraction(high)) * shrink
            position.append(a + (b - a) * Fraction(rng.randint(0, 10000), 10000))
        try:
            q = ev.assemble([float(v) for v in position])
        except KinematicsError:
            continue
        return tuple(position), [float(np.asarray(v)) for v in q]
    raise KinematicsError("no random state of the excitation check could be assembled, even "
                          "inside the trajectory's range of independent coordinates")


def _draw(rng: random.Random, scales: Sequence[Fraction]) -> list[Fraction]:
    return [s * Fraction(rng.randint(-1000, 1000), 1000) for s in scales]


def _scales(values: Sequence[Any]) -> list[Fraction]:
    """Per coordinate: the largest |value| on the grid to 2 digits (else the largest of the
    others, else 1), as an exact rational."""
    peaks = [float(np.max(np.abs(np.asarray(v, dtype=float)))) for v in values]
    fallback = max(peaks, default=0.0) or 1.0
    return [Fraction(f"{p or fallback:.2g}") for p in peaks]
