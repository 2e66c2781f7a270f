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

# A weighted fit's per-coordinate statistics: given each coordinate's weight (f,), the
# residual sum of squares (f,) in the measurement's units and the leverage (f,) the fit spends
# on each coordinate's rows (the hat matrix's diagonal summed over them).
CoordinateStatistics = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def coordinate_statistics(residual: np.ndarray, basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sum of squares, leverage) per coordinate of a fit's residual (n, f) and the orthonormal
    basis (n f, rank) of its weighted range (rows sample-major)."""
    n, f = residual.shape
    leverage = np.sum(basis ** 2, axis=1).reshape(n, f).sum(axis=0) if basis.size else np.zeros(f)
    return np.sum(residual ** 2, axis=0), leverage


# The smallest noise level relative to the largest coordinate's: far below any real ratio (data
# simulated without noise have 1e-16), it only keeps a weight finite (squares below 1e308).
LEVEL_FLOOR = 1e-100


def noise_levels(rss: np.ndarray, leverage: np.ndarray, samples: int, floor: float = 0.0) -> np.ndarray:
    """Per-coordinate noise SD from its residual sum of squares, each with its own degrees of
    freedom ``samples`` - (leverage of that coordinate's rows); at least ``floor`` (a
    coordinate fitted exactly must not get an infinite weight)."""
    dof = np.maximum(samples - leverage, 1.0)
    level = np.sqrt(rss / dof)
    positive = level[level > 0]
    # relative to the largest level: relative to the smallest, a coordinate the model can fit
    # exactly (a torque not recorded, all zeros) sank by 1e-12 each pass (to 1e-161 on a
    # PUMA), until its weight overflowed
    tiny = (positive.max() if positive.size else 1.0) * LEVEL_FLOOR or 1e-300
    return np.maximum(level, max(floor, tiny))


def fixed_point(statistics: CoordinateStatistics, samples: int, coordinates: int, floor: float = 0.0,
                start: np.ndarray | None = None, tolerance: float = TOLERANCE) -> tuple[np.ndarray, bool]:
    """(the noise SDs (f,) at which refitting with weights 1/SD no longer changes them, whether
    they settled within PASSES), starting from ``start`` (default: equal weights, the ordinary
    fit; a previous model's SDs save passes when a model grows by one effect at a time);
    ``tolerance``: the largest relative change of an SD that ends the passes."""
    sigma = np.ones(coordinates) if start is None else np.asarray(start, dtype=float)
    for _ in range(PASSES):
        previous, sigma = sigma, noise_levels(*statistics(1.0 / sigma), samples, floor)
        if np.max(np.abs(sigma / previous - 1.0)) < tolerance:
            return sigma, True
    return sigma, False
