"""Joint coordinates that no motion can move apart: tied by a fixed ratio.

A coupling (``[[couplings]]``: a gear, a belt, a cable-driven counterweight) ties a
follower to its leader, and a closed loop may tie coordinates linearly too: a
parallelogram's passive angles are +-1 times the driven one at every state. An effect on
a tied coordinate reaches the independent ones through the same row of R (times the
ratio) whatever the motion, so two effects of one kind on tied coordinates are one effect
for every motion: advice to "move through a wider range" cannot separate them (issue 49).

Found numerically, at states drawn independently of any trajectory (the excitation
check's random batch: random positions inside the reachable range, loops closed): rows
i and j of R (qd = R zd) are tied when row i is c times row j at every state, with one
constant c. A nonlinear relation (a four-bar's rocker) changes its ratio from state to
state; a coincidence at one state does not survive 2 x parameters / f random states.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from baseparams.dynamics.excitation import RandomBatch, random_batch
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import Mechanism

TOLERANCE = 1e-9     # relative: |R_i - c R_j| over the batch, against |R_i|


@dataclass(frozen=True)
class Tie:
    """``coordinate`` moves as ``ratio`` times ``leader`` (velocities; positions up to a
    constant) at every state; ``how``: "coupling" (declared) or "loop" (the closure)."""
    coordinate: str
    leader: str
    ratio: float
    how: str


@functools.lru_cache(maxsize=16)
def ties(mechanism: Mechanism, seed: int = 0) -> tuple[Tie, ...]:
    """Every tree coordinate tied to an earlier one (in the mechanism's coordinate order,
    each to the first of its group), with its ratio. Empty for a mechanism whose
    coordinates all move independently."""
    names = list(mechanism.coordinates)
    declared = tuple(Tie(c.coordinate, c.leader, float(c.ratio), "coupling") for c in mechanism.couplings)
    if not mechanism.loops or len(names) < 2:
        return declared                   # in a tree only a coupling ties two coordinates
    try:
        trajectory = Trajectory.default(mechanism, samples=64)
        rows = np.concatenate([_projection_rows(random_batch(mechanism, trajectory, seed + k), mechanism)
                               for k in range(2)], axis=1)
    except (InputError, KinematicsError):     # no trajectory, no reachable random state
        return declared
    norms = np.linalg.norm(rows, axis=1)
    scale = float(norms.max()) if norms.size else 0.0
    pairs = {(c.coordinate, c.leader) for c in mechanism.couplings}
    found: list[Tie] = []
    placed: dict[int, int] = {}
    for i in range(len(names)):
        if norms[i] <= TOLERANCE * scale:          # does not move with the independent ones
            continue
        for j in range(i):
            if j in placed or norms[j] <= TOLERANCE * scale:
                continue
            c = float(rows[i] @ rows[j]) / float(rows[j] @ rows[j])
            if np.linalg.norm(rows[i] - c * rows[j]) <= TOLERANCE * norms[i]:
                how = "coupling" if (names[i], names[j]) in pairs or (names[j], names[i]) in pairs else "loop"
                found.append(Tie(names[i], names[j], c, how))
                placed[i] = j
                break
    return tuple(found)


def _projection_rows(batch: RandomBatch, mechanism: Mechanism) -> np.ndarray:
    """R's rows (n, states x f) at every state of the batch, float64."""
    sample = batch.float64_sample(mechanism)
    count = batch.count
    return np.array([np.concatenate([np.broadcast_to(np.asarray(v, dtype=float), (count,)) for v in row])
                     for row in sample.projection])


def tied_group(mechanism: Mechanism, coordinates: list[str]) -> Tie | None:
    """When every coordinate listed is one tied group (two or more distinct coordinates,
    each tied to the same first one): a tie that names the reason, else None."""
    distinct = list(dict.fromkeys(coordinates))
    if len(distinct) < 2:
        return None
    root = {t.coordinate: t.leader for t in ties(mechanism)}
    heads = {root.get(c, c) for c in distinct}
    if len(heads) != 1:
        return None
    head = heads.pop()
    member = next(t for t in ties(mechanism) if t.coordinate in distinct and t.leader == head)
    return member
