"""The observation matrix over the rationals, and base parameters from its exact rref.

For an open chain with rational geometry, the kinematics is rational at rational points
of the unit circle: an angle given by ``t = tan(theta/2)`` has ``cos = (1 - t^2)/(1 + t^2)``
and ``sin = 2t/(1 + t^2)`` (:class:`baseparams.numeric.backends.TanHalf`). With random rational
angles, lengths, velocities and accelerations, every regressor entry is an exact
rational (python-flint ``fmpq``), W is exact, and so are its rank and its reduced row
echelon form, from which the base parameters follow with no tolerance at all.

What "exact" means here: the rank of W at the sampled states, a lower bound of the number
of base parameters. It equals that number unless every sample falls on the zero set of
some nonzero polynomial (a minor of W): random samples make that a probability-zero
event (Schwartz-Zippel); a second independent batch is added and must not raise the rank.

Closed loops are refused: loop closure makes the dependent coordinates algebraic, not
rational, functions of the independent ones.
"""

import random
from collections.abc import Sequence
from fractions import Fraction
from typing import Any, cast

from flint import fmpq, fmpq_mat

from baseparams.dynamics.observation import RationalStates, observation_matrix
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Exact, TanHalf


def coordinate_kinds(mechanism: Mechanism) -> tuple[list[str], list[str]]:
    """'angle' or 'length' for each independent coordinate."""
    names = mechanism.independent or mechanism.coordinates
    return list(names), [mechanism.coordinate_kind(name) for name in names]


def check_exact_possible(mechanism: Mechanism) -> None:
    """InputError unless the mechanism is an open chain (exact kinematics exists)."""
    if mechanism.loops:
        raise InputError(
            f"the exact solver needs an open kinematic chain, and {mechanism.name} has "
            f"{len(mechanism.loops)} closed loop(s): loop closure makes the dependent coordinates "
            f"irrational; use --solver vp (certified ball arithmetic) instead",
            file=mechanism.path)
    for coupling in mechanism.couplings:
        joint = mechanism.joint_of_coordinate(coupling.coordinate)
        same_kind = mechanism.coordinate_kind(coupling.coordinate) == mechanism.coordinate_kind(coupling.leader)
        if same_kind and coupling.offset == 0 and abs(coupling.ratio) == 1:
            continue            # tan(-theta/2) = -tan(theta/2): an exact angle stays exact
        if "angle" in joint.type.coordinate_kinds:
            raise InputError(
                f"the exact solver evaluates angles as rational points of the circle, and "
                f"{coupling.coordinate} = {coupling.ratio} {coupling.leader} + {coupling.offset} is not one "
                f"of them in general; use --solver vp (certified ball arithmetic) instead",
                file=mechanism.path)


def _random_state(rng: random.Random, mechanism: Mechanism, names: Sequence[str],
                  kinds: Sequence[str]) -> tuple[list[Any], list[fmpq], list[fmpq]]:
    z: list[Any] = []
    zd: list[fmpq] = []
    zdd: list[fmpq] = []
    for name, kind in zip(names, kinds):
        if kind == "angle":
            z.append(TanHalf(Fraction(rng.randint(-97, 97), rng.randint(37, 101))))
        else:
            lo, hi = mechanism.joint_of_coordinate(name).limits.get(name, (Fraction(-1), Fraction(1)))
            z.append(fmpq(1) * _fmpq(lo + (hi - lo) * Fraction(rng.randint(1, 99), 100)))
        zd.append(fmpq(rng.randint(-50, 50), rng.randint(7, 31)))
        zdd.append(fmpq(rng.randint(-50, 50), rng.randint(7, 31)))
    return z, zd, zdd


def _fmpq(value: Fraction | int | float) -> fmpq:
    value = Fraction(value)
    return fmpq(value.numerator, value.denominator)


def random_rational_states(mechanism: Mechanism, count: int, seed: int = 0) -> RationalStates:
    """``count`` random states with every value rational: angles as rational points of the
    unit circle (:class:`TanHalf`), lengths inside their limits, rational velocities and
    accelerations. They can be evaluated in any backend."""
    names, kinds = coordinate_kinds(mechanism)
    rng = random.Random(seed)
    states = [_random_state(rng, mechanism, names, kinds) for _ in range(count)]
    z, zd, zdd = (tuple(tuple(state[k]) for state in states) for k in range(3))
    return RationalStates(z, zd, zdd, name="random rational state")


def exact_observation_matrix(mechanism: Mechanism, samples: int, seed: int = 0) -> fmpq_mat:
    """W over the rationals at ``samples`` random states: an ``fmpq_mat``.

    Raises InputError for closed loops or geometry that is not rational here (an axis of
    irrational length, say).
    """
    check_exact_possible(mechanism)
    try:
        states: Any = random_rational_states(mechanism, samples, seed)
        W = cast(fmpq_mat, observation_matrix(mechanism, Exact(), states)[0])
    except KinematicsError as exc:
        raise InputError(f"the exact solver cannot evaluate {mechanism.name} in rational arithmetic "
                         f"({exc}); use --solver vp", file=mechanism.path) from None
    return W


def rref_base(W: fmpq_mat) -> tuple[int, list[int], list[int], list[list[Fraction]]]:
    """(rank, kept columns, eliminated columns, beta as Fractions) from the exact rref of W.

    The pivot columns of the rref are kept (the leftmost basis); a non-pivot column j is
    the combination ``W_j = sum_i R[i, j] W_{p_i}`` of them, so
    ``phi_b,i = phi_{p_i} + sum_j R[i, j] phi_j``: beta is R's non-pivot columns.
    """
    R, rank = W.rref()
    n = W.ncols()
    kept = rref_pivots(R, rank)
    eliminated = [j for j in range(n) if j not in set(kept)]
    beta = [[Fraction(int(R[i, j].p), int(R[i, j].q)) for j in eliminated] for i in range(rank)]
    return rank, kept, eliminated, beta


def rref_pivots(R: fmpq_mat, rank: int) -> list[int]:
    """Pivot columns of a reduced row echelon form ``R`` of rank ``rank``: the leading
    nonzero of each of its first ``rank`` rows."""
    pivots, row = [], 0
    for j in range(R.ncols()):
        if row < rank and R[row, j] != 0:
            pivots.append(j)
            row += 1
    return pivots
