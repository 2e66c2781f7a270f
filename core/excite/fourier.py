"""The planned motion's form: a finite Fourier series per independent coordinate (Swevers et al.).

    q_j(t) = c_j + sum_{l=1..L} A_jl sin(w l t) + B_jl cos(w l t),   w = 2 pi / T

It is periodic over T, so it ends as it starts; rest at t = 0 (and so at T) is
qd_j(0) = w sum_l l A_jl = 0 and qdd_j(0) = -w^2 sum_l l^2 B_jl = 0, two linear equations
per coordinate. The optimiser's variables are the coordinates of (c, A, B) in an orthonormal
basis of the solutions (``basis``), so every point it tries starts and ends at rest.
q, qd and qdd are linear in the variables: their derivatives are constant matrices.

Written out (:meth:`FourierForm.expressions`) the coefficients become exact rationals (12
significant digits) with A_j1 and B_j1 recomputed exactly from the others, so the file's
trajectory starts at rest exactly, as the mechanism file's ``[trajectory]`` (``solve``,
``simulate`` and ``identify`` use it unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import scipy.linalg
import sympy

from baseparams.dynamics.trajectory import T as TIME


def _rational(value: float) -> Fraction:
    return Fraction(f"{float(value):.12g}")


@dataclass(frozen=True)
class FourierForm:
    """``names``: the coordinates; ``harmonics`` L; ``period`` T (s)."""
    names: tuple
    harmonics: int
    period: float

    @property
    def omega(self) -> float:
        return 2 * np.pi / self.period

    @property
    def basis(self) -> np.ndarray:
        """(2 L + 1, 2 L - 1): orthonormal solutions of the rest equations in (c, A_1..L, B_1..L)."""
        L = self.harmonics
        rest = np.zeros((2, 2 * L + 1))
        rest[0, 1:L + 1] = np.arange(1, L + 1)
        rest[1, L + 1:] = np.arange(1, L + 1) ** 2
        return scipy.linalg.null_space(rest)

    @property
    def per_coordinate(self) -> int:
        return 2 * self.harmonics - 1

    @property
    def size(self) -> int:
        return len(self.names) * self.per_coordinate

    def rows(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Phi_q, Phi_qd, Phi_qdd), each (N, 2 L - 1): q_j = Phi_q @ x_j at the times ``t``."""
        t = np.asarray(t, dtype=float)
        L, w = self.harmonics, self.omega
        wl = w * np.arange(1, L + 1)
        s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))
        one, zero = np.ones((len(t), 1)), np.zeros((len(t), 1))
        pq = np.hstack([one, s, c])
        pqd = np.hstack([zero, c * wl, -s * wl])
        pqdd = np.hstack([zero, -s * wl ** 2, -c * wl ** 2])
        N = self.basis
        return pq @ N, pqd @ N, pqdd @ N

    def jerk_rows(self, t: np.ndarray) -> np.ndarray:
        """Phi_jerk (N, 2 L - 1): d3q_j/dt3 = Phi_jerk @ x_j (jerk limits are linear too)."""
        t = np.asarray(t, dtype=float)
        L, w = self.harmonics, self.omega
        wl = w * np.arange(1, L + 1)
        s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))
        return np.hstack([np.zeros((len(t), 1)), -c * wl ** 3, s * wl ** 3]) @ self.basis

    def jerk(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """d3q/dt3 (N, f) of the variables ``x``."""
        X = np.asarray(x, dtype=float).reshape(len(self.names), self.per_coordinate).T
        return np.asarray(self.jerk_rows(t) @ X)

    def motion(self, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd), each (N, f), of the variables ``x`` (f blocks of 2 L - 1)."""
        X = np.asarray(x, dtype=float).reshape(len(self.names), self.per_coordinate).T
        return tuple(phi @ X for phi in self.rows(t))

    def coefficients(self, x: np.ndarray) -> np.ndarray:
        """(f, 2 L + 1): (c, A_1..L, B_1..L) per coordinate."""
        X = np.asarray(x, dtype=float).reshape(len(self.names), self.per_coordinate)
        return X @ self.basis.T

    def variables(self, coefficients: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`coefficients` (for coefficients at rest)."""
        return (np.asarray(coefficients, dtype=float) @ self.basis).reshape(-1)

    def exact(self, x: np.ndarray) -> list[list[Fraction]]:
        """Per coordinate the exact (c, A, B), rounded to 12 digits, A_1 and B_1 exact from the rest."""
        L = self.harmonics
        out = []
        for row in self.coefficients(x):
            c = _rational(row[0])
            A = [_rational(v) for v in row[1:L + 1]]
            B = [_rational(v) for v in row[L + 1:]]
            A[0] = -sum((l * a for l, a in enumerate(A[1:], start=2)), Fraction(0))
            B[0] = -sum((l * l * b for l, b in enumerate(B[1:], start=2)), Fraction(0))
            out.append([c] + A + B)
        return out

    def expressions(self, x: np.ndarray) -> dict:
        """Per coordinate the sympy expression of t (exact rationals, pi exact)."""
        L = self.harmonics
        period = sympy.Rational(_rational(self.period).numerator, _rational(self.period).denominator)
        out = {}
        for name, row in zip(self.names, self.exact(x)):
            expr = sympy.Rational(row[0].numerator, row[0].denominator)
            for l in range(1, L + 1):
                arg = 2 * sympy.pi * l * TIME / period
                a, b = row[l], row[L + l]
                expr += sympy.Rational(a.numerator, a.denominator) * sympy.sin(arg)
                expr += sympy.Rational(b.numerator, b.denominator) * sympy.cos(arg)
            out[name] = expr
        return out

    def rounded(self, x: np.ndarray) -> np.ndarray:
        """The variables of the written (rounded) coefficients."""
        return self.variables(np.array([[float(v) for v in row] for row in self.exact(x)]))
