"""Model effects: forces on a joint coordinate that are linear in their coefficients.

An effect adds columns to the regressor: the generalized force it needs on its
coordinate is ``sum(coefficient * column(q, qd, qdd))``. On a dependent coordinate of a
closed loop the columns map to the independent coordinates by R^T, like K
(``baseparams.dynamics.evaluator.Sample.projection`` is R); identification and diagnosis, which
add effects to a model, build on this.
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Effect:
    name: str
    description: str
    coefficients: tuple                      # coefficient names, one per column
    columns_fn: Callable                     # (q, qd, qdd, **options) -> list of arrays

    def columns(self, q, qd, qdd, **options):
        """Columns (one per coefficient) evaluated on arrays of q, qd, qdd of one coordinate."""
        cols = self.columns_fn(np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float), **options)
        shape = np.broadcast_shapes(np.shape(q), np.shape(qd), np.shape(qdd))
        return [np.broadcast_to(np.asarray(c, float), shape) for c in cols]

    def coefficient_names(self, coordinate):
        return [f"{c}_{coordinate}" for c in self.coefficients]
