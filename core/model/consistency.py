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
"""

from dataclasses import dataclass
from fractions import Fraction
from itertools import combinations

import numpy as np


@dataclass(frozen=True)
class Verdict:
    """``error``: why the parameters are not physical (None: they are); ``warning``: a
    remark that does not stop the program (None: none)."""
    error: str | None = None
    warning: str | None = None


def check_body(params) -> Verdict:
    """The verdict on (m, mx, my, mz, Ixx, Ixy, Ixz, Iyy, Iyz, Izz) about the body origin,
    with ``I..`` the tensor entries (``Ixy = -integral of x y dm``)."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (Fraction(v) for v in params)
    tensor = [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]
    if m < 0:
        return Verdict(f"negative mass {float(m):.6g}")
    if m == 0:
        if (mx, my, mz) != (0, 0, 0):
            return Verdict("first moments (mx, my, mz) without mass: a centre of mass needs a mass")
        if all(v == 0 for row in tensor for v in row):
            return Verdict()
        if not _semidefinite(tensor):
            return Verdict(_tensor_problem(tensor, "the inertia"))
        moments = ", ".join(f"{v:.6g}" for v in principal_moments(tensor))
        return Verdict(warning=f"zero mass but non-zero inertia (principal moments {moments}): not a "
                               f"mass distribution; accepted as an idealised body")
    c = (mx / m, my / m, mz / m)
    c2 = sum(x * x for x in c)
    at_com = [[tensor[i][j] - m * ((c2 if i == j else 0) - c[i] * c[j]) for j in range(3)] for i in range(3)]
    return Verdict(_tensor_problem(at_com, "the inertia at the centre of mass"))


def principal_moments(tensor) -> list[float]:
    """The eigenvalues of a symmetric 3 x 3 tensor, ascending (for messages)."""
    return [float(v) for v in np.linalg.eigvalsh(np.array(tensor, dtype=float))]


def _tensor_problem(tensor, what: str) -> str | None:
    trace = tensor[0][0] + tensor[1][1] + tensor[2][2]
    sigma = [[(trace / 2 if i == j else 0) - tensor[i][j] for j in range(3)] for i in range(3)]
    if _semidefinite(sigma):
        return None
    moments = ", ".join(f"{v:.6g}" for v in principal_moments(tensor))
    if not _semidefinite(tensor):
        return f"{what} is not positive semi-definite (principal moments {moments})"
    return (f"{what} breaks the triangle inequality: principal moments {moments}, each must be at "
            f"most the sum of the other two")


def _semidefinite(matrix) -> bool:
    """Every principal minor >= 0 (exact, for a symmetric 3 x 3 matrix of Fractions)."""
    for size in (1, 2, 3):
        for rows in combinations(range(3), size):
            if _det([[matrix[i][j] for j in rows] for i in rows]) < 0:
                return False
    return True


def _det(a) -> Fraction:
    if len(a) == 1:
        return a[0][0]
    if len(a) == 2:
        return a[0][0] * a[1][1] - a[0][1] * a[1][0]
    return (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
