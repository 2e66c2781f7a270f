"""Rigorous enclosure of the loop-closure solution (Krawczyk's test), in ball arithmetic.

Newton's method at D digits gives dependent coordinates d~ close to the exact solution
d* of Phi(z, d) = 0, but nothing proves how close. Krawczyk's operator

    K(X) = d~ - Y Phi(z, d~) + (I - Y Phi_d(z, X)) (X - d~),   Y ~ Phi_d(z, d~)^-1,

evaluated in ball arithmetic over a box X around d~ (and over the ball z of the
independent coordinates), proves that X holds exactly one solution for every z in its
ball when K(X) lies inside X. The kinematics then runs on balls that contain the exact
positions, so every entry of W encloses its exact value: this is what makes the rank
proofs of the `vp` solver cover the mechanism, not just its rounded Newton iterate.
"""

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from flint import arb, arb_mat

from baseparams.errors import KinematicsError
from baseparams.numeric.backends import Arb

if TYPE_CHECKING:
    from baseparams.dynamics.evaluator import Evaluator


def enclose(evaluator: "Evaluator", q: Sequence[Any], where: str = "",
            at: tuple[list[Any], list[list[Any]]] | None = None) -> list[Any]:
    """Tree coordinates with the dependent ones replaced by proven enclosures (arb balls).
    ``at``: the closure values and Jacobian rows at ``q`` when already computed (Newton's last)."""
    st = evaluator.structure
    dep = st.dependent
    values, rows = at if at is not None else evaluator.closure(q)
    residual = [arb(values[i]) for i in st.rows]
    m = len(dep)
    jac_mid = arb_mat(m, m, [arb(rows[i][j]).mid() for i in st.rows for j in dep])
    try:
        inverse = jac_mid.inv()
    except ZeroDivisionError:
        raise KinematicsError(f"{where}singular closure Jacobian: no enclosure") from None
    y = arb_mat(m, m, [inverse[i, j].mid() for i in range(m) for j in range(m)])
    step = y * arb_mat(m, 1, residual)
    size = max(abs(step[i, 0]).upper() for i in range(m))
    backend = evaluator.backend
    assert isinstance(backend, Arb)              # balls: the evaluator certifies in arb only
    floor = arb(10) ** (-(backend.digits - 2))
    radius = 4 * size + floor
    for _ in range(4):
        centre = [arb(q[j]).mid() for j in dep]
        box = list(q)
        for j, c in zip(dep, centre):
            box[j] = arb(c, radius)
        _, box_rows = evaluator.closure(box)
        jac_box = arb_mat(m, m, [arb(box_rows[i][j]) for i in st.rows for j in dep])
        spread = arb_mat(m, 1, [arb(0, radius)] * m)
        k = arb_mat(m, 1, centre) - step + (_identity(m) - y * jac_box) * spread
        if all(box[j].contains_interior(k[a, 0]) for a, j in enumerate(dep)):
            out = list(q)
            for a, j in enumerate(dep):
                out[j] = k[a, 0]
            return out
        radius = radius * 16
    raise KinematicsError(f"{where}could not prove an enclosure of the loop-closure solution "
                          f"(Krawczyk test failed); the configuration may be near singular")


def _identity(m: int) -> Any:
    return arb_mat(m, m, [1 if i == j else 0 for i in range(m) for j in range(m)])
