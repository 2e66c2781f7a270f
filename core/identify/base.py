"""Base parameters as a linear map, for fitting: phi_b = B phi.

Any solver's :class:`~baseparams.solvers.result.BaseParameterResult` gives the rows of B
(each base parameter's coefficients over the standard parameters; the symbolic solver's
exact values). Every row of the regressor K lies in B's row space (that is what makes the
base parameters identifiable and the others not), so K phi = K_b (B phi) with
K_b = K B^+ = K B^T (B B^T)^-1, computed here by least squares on B^T (no normal
equations). Identification fits phi_b with K_b.
"""

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse

from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.result import BaseParameterResult, Coefficient


@dataclass(frozen=True)
class BaseModel:
    """``names`` (phi_b01 ...), ``parameters`` (the standard ones, mechanism order), ``B``
    (rank x P, float64), ``expressions`` (each base parameter as the solver printed it), the
    solver's name and its ``coefficients`` (the result's data, from which the JSON writes
    them: :func:`~baseparams.solvers.result.base_json`)."""
    names: tuple[str, ...]
    parameters: tuple[str, ...]
    B: np.ndarray
    expressions: tuple[dict, ...] = ()
    solver: str = ""
    coefficients: tuple[dict[str, Coefficient], ...] = ()

    @classmethod
    def from_result(cls, result: BaseParameterResult, mechanism: Mechanism | None = None) -> "BaseModel":
        """B from a solver's result (symbolic coefficients: their exact values), columns in
        the mechanism's parameter order."""
        rows = result.coefficient_matrix(values=True)
        # most entries are zero (TIAGo: all but 2,143 of 148,800): 0.0 without Fraction.__float__
        B = np.array([[float(v) if v else 0.0 for v in row] for row in rows], dtype=float).reshape(len(rows), -1)
        parameters = tuple(result.parameters)
        if mechanism is not None and tuple(mechanism.parameters) != parameters:
            order = [parameters.index(p) for p in mechanism.parameters]
            B, parameters = B[:, order], tuple(mechanism.parameters)
        if not np.all(np.isfinite(B)):
            raise InputError(f"the {result.solver} solver's base parameters of {result.mechanism} "
                             "have non-finite coefficients in float64")
        return cls(tuple(b["name"] for b in result.base), parameters, B,
                   tuple(dict(b["expression"]) for b in result.base), result.solver, tuple(result.coefficients or ()))

    @property
    def rank(self) -> int:
        return len(self.names)

    def values(self, phi: np.ndarray) -> np.ndarray:
        """phi_b = B phi (phi: (P,) or (P, k))."""
        return self.B @ phi

    @functools.cached_property
    def _pseudo_inverse(self) -> np.ndarray:
        """(B^T)^+ (rank x P), once per model: min || B^T X - I || (gelsy). Why: solving for
        each K's rows made K_b = K B^+ 0.3 s of identify on TIAGo (9,600 x 480 K, issue 47);
        one product is 0.13 s, the same to 1e-15 of K_b."""
        solution, *_ = scipy.linalg.lstsq(self.B.T, np.eye(self.B.shape[1]), lapack_driver="gelsy")
        return solution

    def columns(self, K: np.ndarray) -> np.ndarray:
        """The base regressor K_b = K B^+ for K (..., P): (..., rank)."""
        K = np.asarray(K, dtype=float)
        if K.shape[-1] != self.B.shape[1]:
            raise ValueError(f"K has {K.shape[-1]} columns, B {self.B.shape[1]}")
        if self.rank == 0:
            return np.zeros(K.shape[:-1] + (0,))
        flat = K.reshape(-1, K.shape[-1])
        return (flat @ self._pseudo_inverse.T).reshape(K.shape[:-1] + (self.rank,))

    def residual_outside(self, K: np.ndarray, columns: np.ndarray | None = None) -> float:
        """How far K's rows are from B's row space, relative to K: 0 when K phi = K_b B phi
        holds exactly; a check that the base model fits this regressor. ``columns``: K_b if
        already computed (:meth:`columns`)."""
        K = np.asarray(K, dtype=float).reshape(-1, self.B.shape[1])
        scale = np.linalg.norm(K)
        if scale == 0:
            return 0.0
        Kb = (self.columns(K) if columns is None else columns).reshape(len(K), self.rank)
        # B is sparse (a solver's rows: one kept parameter, few others): K_b B as a sparse product
        return float(np.linalg.norm(K - (scipy.sparse.csr_array(self.B.T) @ Kb.T).T) / scale)
