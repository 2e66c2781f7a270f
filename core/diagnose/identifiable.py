"""Which of an effect's coefficients the data determine, beside the rest of a model: the
identifiable combinations of a changed body's ten parameters (Gautier's regrouping, applied
to the part of its columns the rest of the model does not span).

Why: on a mechanism of low mobility (a four-bar, a suspension) or for a body near the base,
a changed body moves the torques through a few combinations of its parameters only. The
least-squares fit then returns one solution of many (zero in the directions the data do not
see) with a standard deviation of zero there: a four-bar's payload was reported as
``m = 0 +- 0``, a certainty the data do not hold. Each coefficient outside a kept set is
reported as absorbed into the kept ones, as ``identify`` reports its absorbed coefficients."""

from dataclasses import dataclass

import numpy as np

from baseparams.diagnose.derived import ROUNDING   # a column this much smaller than the largest is zero
from baseparams.diagnose.wald import orthonormal_basis, project_out

# a direction of the scaled columns below this fraction of the largest is not seen (the
# fits' own rank tolerance, baseparams.identify.linear.RANK_TOL)
TOLERANCE = 1e-6
# a regrouping coefficient below this (in units of the kept coefficient per absorbed one,
# relative to the columns' scales) is rounding
ZERO = 1e-9


@dataclass(frozen=True)
class Regrouping:
    """``kept`` (indices into the effect's coefficients) are identified as
    beta_i = phi_i + sum_j into[i, j] phi_j over the ``absorbed`` ones j (``into``: kept x
    absorbed); ``values`` and ``covariance`` are those of beta over ``kept``."""
    kept: list[int]
    absorbed: list[int]
    into: np.ndarray
    values: np.ndarray
    covariance: np.ndarray
    # (absorbed ones determined without the other named bodies, those bodies' indices): set
    # by the caller that knows which columns are bodies
    shared: tuple[tuple[int, ...], tuple[int, ...]] | None = None


def regroup(others: np.ndarray, columns: np.ndarray, values: np.ndarray, covariance: np.ndarray
            ) -> Regrouping | None:
    """The identifiable combinations of the coefficients of ``columns`` (rows, c) beside
    ``others`` (rows, q) (both weighted as fitted), from the fit's ``values`` (c,) and their
    ``covariance`` (c, c) (any solution: the combinations do not depend on which); None when
    every coefficient is identified on its own."""
    c = columns.shape[1]
    beyond = project_out(columns, orthonormal_basis(others, TOLERANCE))
    scale = np.linalg.norm(columns, axis=0)
    rounding = scale <= ROUNDING * max(scale.max(initial=0.0), 1e-300)     # a column of rounding: zero
    beyond = np.where(rounding[None, :], 0.0, beyond)
    scale = np.where(rounding, 1.0, scale)
    kept = _kept_in_order(beyond / scale)
    rank = len(kept)
    if rank == c:
        return None
    absorbed = [j for j in range(c) if j not in kept]
    # beyond[:, absorbed] = beyond[:, kept] K in the scaled units, by least squares on the kept
    scaled = beyond / scale
    into_scaled = np.linalg.lstsq(scaled[:, kept], scaled[:, absorbed], rcond=None)[0]
    into_scaled[np.abs(into_scaled) < ZERO] = 0.0
    into = into_scaled * scale[absorbed][None, :] / scale[kept][:, None]
    transform = np.zeros((rank, c))
    transform[np.arange(rank), kept] = 1.0
    transform[:, absorbed] = into
    return Regrouping(kept, absorbed, into, transform @ values, transform @ covariance @ transform.T)


def _kept_in_order(scaled: np.ndarray) -> list[int]:
    """The coefficients kept, in the effect's own order (a body's mass first, then its first
    moments, then its inertia): each kept when its column adds a direction the ones kept
    before it do not span. Why in order, not by pivoting on the largest column: the first a
    reader asks of a load is its mass; pivoting kept a parallelogram end link's inertia and
    left its mass "not identifiable" (issue 49), where the data determine the mass beside a
    combination of inertias."""
    norms = np.linalg.norm(scaled, axis=0)
    largest = max(float(norms.max(initial=0.0)), 1e-300)
    kept: list[int] = []
    basis = np.zeros((scaled.shape[0], 0))
    for j in range(scaled.shape[1]):
        left = scaled[:, j] - basis @ (basis.T @ scaled[:, j])
        size = float(np.linalg.norm(left))
        if size > TOLERANCE * largest:
            kept.append(j)
            left = left - basis @ (basis.T @ left)        # twice is enough (Kahan)
            basis = np.concatenate([basis, (left / np.linalg.norm(left))[:, None]], axis=1)
    return kept
