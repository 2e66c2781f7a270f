"""Which closure equations are independent and which coordinates are dependent: the
structure of a mechanism's loops (and couplings), from the closure Jacobian at q = 0.

Its own module so that the generated code (``codegen``) and the evaluator both use it
without importing each other.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from baseparams.errors import InputError
from baseparams.kinematics.tree import TreeKinematics
from baseparams.numeric.backends import Float64

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism

Array = np.ndarray


@dataclass(frozen=True)
class ClosureStructure:
    rows: tuple[int, ...]         # indices of the independent closure equations
    independent: tuple[int, ...]  # coordinate indices of z
    dependent: tuple[int, ...]    # coordinate indices of d
    rank: int            # rank of the closure Jacobian
    redundant: int       # closure equations implied by the others

    @property
    def dof(self) -> int:
        return len(self.independent)


@functools.lru_cache(maxsize=64)
def closure_structure(mechanism: Mechanism) -> ClosureStructure:
    """Independent closure equations and dependent coordinates, from the Jacobian at q = 0."""
    n = len(mechanism.coordinates)
    names = list(mechanism.coordinates)
    if not mechanism.loops:
        followers = [names.index(c.coordinate) for c in mechanism.couplings]
        free = [c for i, c in enumerate(names) if i not in followers]
        if mechanism.independent and sorted(mechanism.independent) != sorted(free):
            which = "that follows no other " if followers else ""
            raise InputError(f"a mechanism without loops has {len(free)} degrees of freedom: every tree "
                             f"coordinate {which}is independent ({', '.join(free)}); omit "
                             f"coordinates.independent or list them all", file=mechanism.path,
                             key="coordinates.independent")
        given = mechanism.independent if mechanism.independent else free
        return ClosureStructure((), tuple(names.index(c) for c in given), tuple(followers), 0, 0)
    kin = TreeKinematics(mechanism, Float64())
    _, rows, _ = kin.closure(kin.forward([0.0] * n), q=[0.0] * n)
    jac = np.array([[float(v) for v in row] for row in rows])
    tol = 1e-9 * max(1.0, np.abs(jac).max())
    chosen = independent_rows(jac, tol)
    rank = len(chosen)
    if mechanism.independent:
        indep = [names.index(c) for c in mechanism.independent]
        dep = [i for i in range(n) if i not in indep]
        sub = jac[np.ix_(chosen, dep)]
        if len(dep) != rank or np.linalg.matrix_rank(sub, tol) < rank:
            raise InputError(
                f"the independent coordinates {list(mechanism.independent)} do not parameterize the "
                f"mechanism: {n} tree coordinates, {rank} independent closure equations"
                + (f" ({len(mechanism.couplings)} coupling(s) included)" if mechanism.couplings else "")
                + f", so "
                f"{n - rank} independent coordinates are needed and the others must be solvable",
                file=mechanism.path, key="coordinates.independent")
    else:
        # followers first: a coupling makes its follower dependent, not its leader
        followers = [names.index(c.coordinate) for c in mechanism.couplings]
        order = followers + [i for i in range(n) if i not in followers]
        dep = sorted(order[k] for k in independent_rows(jac[chosen][:, order].T, tol))
        indep = [i for i in range(n) if i not in dep]
    return ClosureStructure(tuple(chosen), tuple(indep), tuple(dep), rank, len(rows) - rank)


def independent_rows(matrix: Array, tol: float) -> list[int]:
    """Greedy Gram-Schmidt: indices of rows independent of the earlier ones."""
    chosen: list[int] = []
    basis: list[Array] = []
    for i, row in enumerate(matrix):
        r = row.astype(float).copy()
        for b in basis:
            r -= (r @ b) * b
        norm = np.linalg.norm(r)
        if norm > tol:
            chosen.append(i)
            basis.append(r / norm)
    return chosen
