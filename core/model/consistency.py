"""Physical consistency of a body's ten inertial parameters, decided exactly.

A rigid body is a mass distribution: its mass is >= 0 and its inertia tensor at the centre
of mass is positive semi-definite with principal moments that satisfy the triangle
inequalities (each at most the sum of the other two). Both hold exactly when the second
moment matrix ``Sigma = tr(I)/2 * 1 - I`` at the centre of mass is positive semi-definite
(Wensing, Kim and Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification", RA-L 2018). The test is exact: every principal minor of a
symmetric matrix of Fractions is >= 0 (for semi-definiteness the leading minors are not
enough). A body without mass but with inertia is not a mass distribution either; it is
allowed with a warning when its inertia is positive semi-definite (the triangle inequalities
are not asked of it), since an idealised massless link that only carries a rotor inertia is
a common modelling shortcut (the PUMA 560's link 1: only Izz1 was measured).

Rounding: files print inertias to a few digits (iCub's head: ``ixz = 2.4e-35`` with
``ixx = izz = 0``). A violation smaller than ``ROUNDING`` times the body's scale (the trace
of its inertia about the body origin) is rounding, not physics: the test is run exactly on
the matrices shifted by that much (``Sigma + ROUNDING * scale * 1``).

Where inertia values do not enter an answer (base parameters, ``show``, ``convert``), a
reader may accept a non-physical body with a warning (URDF files as users have them); the
mechanism then lists it in ``Mechanism.nonphysical`` and :func:`require_physical` is the
one check that verbs whose answer uses the values (simulate, identification priors and
``--physical``, diagnose ``--params``) call before they start.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from fractions import Fraction
from itertools import combinations
from typing import TYPE_CHECKING

import numpy as np

from baseparams.errors import InputError

if TYPE_CHECKING:       # the mechanism module does not import this one, but the builder does
    from baseparams.model.mechanism import Mechanism

ROUNDING = Fraction(1, 10 ** 13)       # a thousand double-precision roundings


@dataclass(frozen=True)
class Verdict:
    """``error``: why the parameters are not physical (None: they are); ``warning``: a
    remark that does not stop the program (None: none)."""
    error: str | None = None
    warning: str | None = None


def check_body(params: Sequence[Fraction]) -> Verdict:
    """The verdict on (m, mx, my, mz, Ixx, Ixy, Ixz, Iyy, Iyz, Izz) about the body origin,
    with ``I..`` the tensor entries (``Ixy = -integral of x y dm``)."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (Fraction(v) for v in params)
    tensor = [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]
    slack = ROUNDING * abs(ixx + iyy + izz)
    if m < 0:
        return Verdict(f"negative mass {float(m):.6g}")
    if m == 0:
        if mx or my or mz:
            return Verdict("first moments (mx, my, mz) without mass: a centre of mass needs a mass")
        if all(v == 0 for row in tensor for v in row):
            return Verdict()
        if not _semidefinite(tensor, slack):
            return Verdict(_tensor_problem(tensor, "the inertia", slack))
        moments = ", ".join(f"{v:.6g}" for v in principal_moments(tensor))
        return Verdict(warning=f"zero mass but non-zero inertia (principal moments {moments}): not a "
                               f"mass distribution; accepted as an idealised body")
    c = (mx / m, my / m, mz / m)
    c2 = sum(x * x for x in c)
    at_com = [[tensor[i][j] - m * ((c2 if i == j else 0) - c[i] * c[j]) for j in range(3)] for i in range(3)]
    return Verdict(_tensor_problem(at_com, "the inertia at the centre of mass", slack))


def require_physical(mechanism: Mechanism, use: str, still: Collection[int] = ()) -> None:
    """Raise the ``error:`` for the first body of ``mechanism`` whose inertia is not
    physical (``Mechanism.nonphysical``), saying that ``use`` needs the values: for verbs
    whose answer depends on inertia values (simulate, identification priors and
    ``--physical``, diagnose ``--params``). Base parameters do not, so solvers never call it.
    ``still``: labels of bodies that never move (welded to the ground), whose values no force
    depends on: not checked."""
    found = [entry for entry, label in zip(mechanism.nonphysical, mechanism.nonphysical_labels or
                                           (None,) * len(mechanism.nonphysical)) if label not in still]
    if not found:
        return
    key, reason = found[0]
    more = len(found) - 1
    raise InputError(f"{reason}: {use} uses the inertia values, which must be physical"
                     + (f" ({more} more bod{'y' if more == 1 else 'ies'} too)" if more else "")
                     + "; fix the file's inertia (base parameters do not need it)",
                     file=mechanism.path, key=key)


def principal_moments(tensor: Sequence[Sequence[Fraction]]) -> list[float]:
    """The eigenvalues of a symmetric 3 x 3 tensor of Fractions, ascending (for messages):
    from its exact characteristic polynomial, so an exact zero prints as 0, not 1e-22."""
    t = [[Fraction(v) for v in row] for row in tensor]
    trace = t[0][0] + t[1][1] + t[2][2]
    minors = sum(_det([[t[i][i], t[i][j]], [t[j][i], t[j][j]]]) for i, j in ((0, 1), (0, 2), (1, 2)))
    det = _det(t)
    if det != 0:
        return [float(v) for v in np.linalg.eigvalsh(np.array(t, dtype=float))]
    # lambda * (lambda^2 - trace lambda + minors): one root is exactly 0
    disc = max(float(trace * trace - 4 * minors), 0.0) ** 0.5
    pair = [0.0, 0.0] if minors == 0 and trace == 0 else (
        [0.0, float(trace)] if minors == 0 else [(float(trace) - disc) / 2, (float(trace) + disc) / 2])
    return sorted([0.0] + pair)


def _tensor_problem(tensor: Sequence[Sequence[Fraction]], what: str, slack: Fraction = Fraction(0)) -> str | None:
    trace = tensor[0][0] + tensor[1][1] + tensor[2][2]
    sigma = [[(trace / 2 if i == j else 0) - tensor[i][j] for j in range(3)] for i in range(3)]
    if _semidefinite(sigma, slack):
        return None
    moments = ", ".join(f"{v:.6g}" for v in principal_moments(tensor))
    if not _semidefinite(tensor, slack):
        return f"{what} is not positive semi-definite (principal moments {moments})"
    return (f"{what} breaks the triangle inequality: principal moments {moments}, each must be at "
            f"most the sum of the other two")


def _semidefinite(matrix: Sequence[Sequence[Fraction]], slack: Fraction = Fraction(0)) -> bool:
    """Every principal minor of ``matrix + slack * 1`` >= 0 (exact, for a symmetric 3 x 3
    matrix of Fractions)."""
    if slack:
        matrix = [[v + (slack if i == j else 0) for j, v in enumerate(row)] for i, row in enumerate(matrix)]
    for size in (1, 2, 3):
        for rows in combinations(range(3), size):
            if _det([[matrix[i][j] for j in rows] for i in rows]) < 0:
                return False
    return True


def _det(a: Sequence[Sequence[Fraction]]) -> Fraction:
    if len(a) == 1:
        return a[0][0]
    if len(a) == 2:
        return a[0][0] * a[1][1] - a[0][1] * a[1][0]
    return (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
