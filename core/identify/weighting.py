"""Gautier's per-coordinate noise weighting, iterated to its fixed point: the one home for
the noise levels that ``identify`` (the base-parameter fit) and ``diagnose`` (the selection
tests) divide each coordinate's rows by, so that a coordinate with large forces does not
drown the others.

One pass (an ordinary fit, each coordinate's SD from its residual, a weighted refit) leaves
a quiet coordinate's SD many times too large when the coordinates' noise levels differ by
orders of magnitude: its ordinary residual carries some of the loud ones' misfit through the
shared parameters (16 times too large on a quiet PUMA 560 coordinate, docs/diagnosis.md), which
a whiteness test then reads as structure. Refitting with the new weights until no SD moves
settles it in a few passes.

Each coordinate's SD divides its residual sum of squares by its own degrees of freedom:
samples minus the leverage the fit spends on that coordinate's rows (the diagonal of the hat
matrix summed over them), not an even share of the parameters.
"""

from collections.abc import Callable

import numpy as np

# at most this many weighted fits, until no SD changes by more than TOLERANCE (relative)
PASSES = 12
TOLERANCE = 1e-3

# A weighted fit: given each coordinate's weight (f,), the unweighted residual (n, f) and the
# orthonormal basis (n f, rank) of the weighted model's range (rows sample-major).
WeightedFit = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def noise_levels(residual: np.ndarray, basis: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Per-coordinate noise SD of a fit's residual (n, f), each with its own degrees of
    freedom n - (leverage of that coordinate's rows); at least ``floor`` (a coordinate fitted
    exactly must not get an infinite weight)."""
    n, f = residual.shape
    leverage = np.sum(basis ** 2, axis=1).reshape(n, f).sum(axis=0) if basis.size else np.zeros(f)
    dof = np.maximum(n - leverage, 1.0)
    level = np.sqrt(np.sum(residual ** 2, axis=0) / dof)
    positive = level[level > 0]
    tiny = (positive.min() if positive.size else 1.0) * 1e-12 or 1e-300
    return np.maximum(level, max(floor, tiny))


def fixed_point(weighted_fit: WeightedFit, coordinates: int, floor: float = 0.0,
                start: np.ndarray | None = None, tolerance: float = TOLERANCE) -> np.ndarray:
    """The noise SDs (f,) at which refitting with weights 1/SD no longer changes them,
    starting from ``start`` (default: equal weights, the ordinary fit; a previous model's
    SDs save passes when a model grows by one effect at a time); ``tolerance``: the largest
    relative change of an SD that ends the passes."""
    sigma = np.ones(coordinates) if start is None else np.asarray(start, dtype=float)
    for _ in range(PASSES):
        residual, basis = weighted_fit(1.0 / sigma)
        previous, sigma = sigma, noise_levels(residual, basis, floor)
        if np.max(np.abs(sigma / previous - 1.0)) < tolerance:
            break
    return sigma
