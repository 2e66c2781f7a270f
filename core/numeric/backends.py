"""Arithmetic backends behind one small interface, so kinematics and dynamics are written once.

A backend turns exact rationals into its own numbers and supplies the few functions the
kinematics needs (``cos_sin``, ``sqrt``, a dense linear ``solve``). Numbers themselves
are the backend's native type and use Python operators; ``matrix(rows)`` and ``stack``
give the backend's matrix type (numpy array, ``arb_mat``, ``fmpq_mat``, sympy Matrix):

- :class:`Float64`: numpy float64; a scalar may be an array of N samples, so one pass of
  the kinematics evaluates a whole trajectory (vectorised).
- :class:`Arb`: python-flint ``arb`` balls at a chosen number of decimal digits; every
  result carries a rigorous error bound. flint's precision is a process-wide setting, so
  every public function that computes in arb enters its own with ``backend.activate()``
  (python-flint's own ``ctx.workprec``), which restores the caller's on exit.
- :class:`Exact`: python-flint ``fmpq`` rationals. Angles are given as
  :class:`TanHalf` (the rational point of the unit circle ``t = tan(theta/2)``).
- :class:`Symbolic`: sympy expressions, for small mechanisms and for geometry symbols.

:class:`Backend` is the interface, a ``typing.Protocol`` generic in the number type N
(``Backend[arb]``); the four backends satisfy it (they share a few implementations through
:class:`Defaults`, which is not the interface). :func:`evaluate` needs only the scalar
functions (:class:`Functions`), so an arithmetic on other numbers (the trajectory's jets)
evaluates expressions with it too.
"""

import contextlib
import functools
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from fractions import Fraction
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar, Union

import numpy as np
import sympy
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat

from baseparams.errors import KinematicsError

N = TypeVar("N")
T = TypeVar("T")
# numbers given exactly, which every backend can make its own (Backend.number)
ExactValue = Union[int, Fraction, fmpq, "TanHalf"]
# a float64 "number": one float, or an array of one value per sample (vectorised)
Samples = Union[float, np.ndarray]


def in_backend_precision(method: Callable[..., T]) -> Callable[..., T]:
    """Decorator for a method of an object that carries its backend (``self.backend``, or
    ``self.kin.backend`` for an evaluated sample): the method computes in the backend's
    precision, and the caller's is restored, so it never depends on a leftover setting."""
    @functools.wraps(method)
    def run(self: Any, *args: Any, **kwargs: Any) -> T:
        backend = self.backend if hasattr(self, "backend") else self.kin.backend
        with backend.activate():
            return method(self, *args, **kwargs)
    return run


def stack_flint(mats: Sequence[Any]) -> Any:
    """python-flint matrices of one type (arb_mat, fmpq_mat) stacked vertically: python-flint
    0.9 has no concatenation. Entries are copied, never rounded."""
    cols = mats[0].ncols()
    rows = sum(m.nrows() for m in mats)
    if rows == 0 or cols == 0:
        return type(mats[0])(rows, cols)
    return type(mats[0])(rows, cols, [m[i, j] for m in mats for i in range(m.nrows()) for j in range(cols)])


class BallRows:
    """A matrix in balls held as its row-major entries (arb), before any arb_mat: what an
    analysis that reads each entry once needs (vp's certified one: nrows, ncols, entries, as
    an arb_mat answers them). Why: building W's arb_mat and reading its entries back out were
    about 0.13 CPU s of each of the three W in balls of TIAGo's identify (issue 47). Entries
    that are not arb (ints, floats: exact) are made arb at the caller's precision, as
    :meth:`Arb.matrix` does; :meth:`matrix` is the arb_mat, made when first asked for."""

    def __init__(self, rows: int, cols: int, values: list[Any]):
        if len(values) != rows * cols:
            raise ValueError(f"{len(values)} entries for a {rows} x {cols} matrix")
        if set(map(type, values)) - {arb}:
            values = [v if type(v) is arb else arb(v) for v in values]
        self._shape, self.values = (rows, cols), values

    def nrows(self) -> int:
        return self._shape[0]

    def ncols(self) -> int:
        return self._shape[1]

    def entries(self) -> list[arb]:
        """The entries, row after row (the list itself: not to be changed)."""
        return self.values

    @functools.cached_property
    def matrix(self) -> arb_mat:
        rows, cols = self._shape
        return arb_mat(rows, cols, self.values) if rows and cols else arb_mat(rows, cols)

    @staticmethod
    def stack(*parts: "BallRows") -> "BallRows":
        """The parts one under the other (they have the same number of columns)."""
        return BallRows(sum(p.nrows() for p in parts), parts[0].ncols(), [v for p in parts for v in p.values])


BallMatrix = Union[arb_mat, BallRows]
"""What the certified analysis reads: an arb_mat, or its entries (:class:`BallRows`)."""


class TanHalf:
    """An angle given exactly by ``t = tan(theta/2)``: cos and sin are then rational."""

    __slots__ = ("t",)

    def __init__(self, t: int | Fraction | fmpq):
        self.t = fmpq(t.numerator, t.denominator) if isinstance(t, Fraction) else fmpq(t)

    def cos_sin(self) -> tuple[fmpq, fmpq]:
        t2 = self.t * self.t
        return (1 - t2) / (1 + t2), 2 * self.t / (1 + t2)

    def __repr__(self) -> str:
        return f"TanHalf({self.t})"


class Functions(Protocol[N]):
    """The scalar functions :func:`evaluate` needs: what makes an arithmetic of numbers N."""

    def rational(self, value: Fraction) -> N: ...

    def pi(self) -> N: ...

    def cos_sin(self, x: N) -> tuple[N, N]: ...

    def sqrt(self, x: N) -> N: ...

    def exp(self, x: N) -> N: ...


class Backend(Functions[N], Protocol[N]):
    """The interface every arithmetic satisfies, generic in its number type N."""

    name: str
    exact: bool

    def activate(self) -> AbstractContextManager[None]:
        """Context in which this backend's numbers are computed (precision settings)."""
        ...

    def number(self, value: ExactValue) -> N:
        """An exactly given number (int, Fraction, fmpq, or an angle as :class:`TanHalf`)
        in this backend: how every source of states hands its values to any arithmetic."""
        ...

    def angle(self, value: "TanHalf") -> N:
        """The angle ``2 atan(t)`` (its cos and sin are the exact rationals of ``value``)."""
        ...

    def matrix(self, rows: Sequence[Sequence[N]], columns: int | None = None) -> Any:
        """The backend's matrix of ``rows`` (lists of its numbers); ``columns`` when there
        are no rows."""
        ...

    def stack(self, *mats: Any) -> Any:
        """Matrices of this backend stacked vertically (rows of the first, then the next ...)."""
        ...

    def solve(self, a: Sequence[Sequence[N]], b: Sequence[Sequence[N]]) -> list[list[N]]:
        """Solve ``a x = b`` for x; ``a`` is a list of n rows, ``b`` a list of n rows."""
        ...

    def to_float(self, x: N) -> Any:
        """x as a float (or a float array, for samples)."""
        ...

    def point(self, x: N) -> N:
        """``x`` without its error bound (ball midpoint); iterates of Newton's method use it."""
        ...

    def magnitude(self, x: N) -> float:
        """An upper bound (float) of |x|, for messages (may underflow to 0 at high precision)."""
        ...

    def small(self, x: N, exponent: float) -> bool:
        """Is |x| <= 10**exponent (for every sample)? ``exponent`` may be far below float range."""
        ...

    def evaluate(self, expr: Any, env: Mapping[str, N] | None = None) -> N:
        """A sympy expression (rationals, ``env`` symbols, + * ** and sin cos exp sqrt pi)."""
        ...


class Defaults(Generic[N]):
    """Implementations the backends share (not the interface: :class:`Backend` is)."""

    exact = False

    def activate(self) -> AbstractContextManager[None]:
        return contextlib.nullcontext()

    def number(self: Backend[N], value: ExactValue) -> N:
        if isinstance(value, TanHalf):
            return self.angle(value)
        if isinstance(value, fmpq):
            value = Fraction(int(value.p), int(value.q))
        return self.rational(Fraction(value))

    def point(self, x: N) -> N:
        return x

    def magnitude(self: Backend[N], x: N) -> float:
        return float(np.max(np.abs(self.to_float(x))))

    def small(self: Backend[N], x: N, exponent: float) -> bool:
        return bool(np.all(np.abs(self.to_float(x)) <= 10.0 ** exponent))

    def evaluate(self: Backend[N], expr: Any, env: Mapping[str, N] | None = None) -> N:
        return evaluate(self, expr, env)


def evaluate(functions: Functions[N], expr: Any, env: Mapping[str, N] | None = None) -> N:
    """Evaluate a sympy expression with ``functions``: rationals, ``env`` symbols (values
    by name), + * ** (integer and half-integer powers) and sin cos exp sqrt pi."""
    return _program(sympy.sympify(expr))(functions, env or {})


# An expression's evaluation as nested closures, built once per expression (the sympy tree
# walked once, its rationals made Fractions once): the same calls to ``functions``, in the
# same order, as walking the tree at each evaluation, which cost 1.2 ms a state of TIAGo's
# trajectory (48 coordinates; issue 47).
Program = Callable[[Any, Mapping[str, Any]], Any]


@functools.lru_cache(maxsize=8192)
def _program(expr: Any) -> Program:
    if expr.is_Rational:
        value = Fraction(int(expr.p), int(expr.q))
        return lambda backend, env: backend.rational(value)
    if expr.is_Symbol:
        name = expr.name

        def symbol(backend: Any, env: Mapping[str, Any]) -> Any:
            try:
                return env[name]
            except KeyError:
                raise KeyError(f"no value for symbol {name}") from None
        return symbol
    if expr is sympy.pi:
        return lambda backend, env: backend.pi()
    if expr.is_Pow:
        return _power(expr)
    parts = [_program(a) for a in expr.args]
    if expr.is_Add or expr.is_Mul:
        first, rest = parts[0], parts[1:]
        if expr.is_Add:
            def add(backend: Any, env: Mapping[str, Any]) -> Any:
                total = first(backend, env)
                for value in [part(backend, env) for part in rest]:
                    total = total + value
                return total
            return add

        def mul(backend: Any, env: Mapping[str, Any]) -> Any:
            total = first(backend, env)
            for value in [part(backend, env) for part in rest]:
                total = total * value
            return total
        return mul
    if isinstance(expr, (sympy.sin, sympy.cos)):
        (argument,) = parts
        which = 1 if isinstance(expr, sympy.sin) else 0
        return lambda backend, env: backend.cos_sin(argument(backend, env))[which]
    if isinstance(expr, sympy.exp):
        (argument,) = parts
        return lambda backend, env: backend.exp(argument(backend, env))

    def unknown(backend: Any, env: Mapping[str, Any]) -> Any:
        for part in parts:
            part(backend, env)
        raise ValueError(f"cannot evaluate {expr} in backend {getattr(backend, 'name', type(backend).__name__)}")
    return unknown


def _power(expr: Any) -> Program:
    """b**e for an integer or half-integer e: repeated products (and a square root)."""
    base, exponent = expr.args
    of = _program(base)
    if not (exponent.is_Integer or (exponent.is_Rational and exponent.q == 2)):
        def unsupported(backend: Any, env: Mapping[str, Any]) -> Any:
            of(backend, env)
            raise ValueError(f"power {exponent} is not supported in backend evaluation")
        return unsupported
    # integer and half-integer powers (derivatives of sqrt give b**(-3/2) ...)
    doubled = int(exponent * 2)
    n = doubled // 2 if doubled % 2 == 0 else (doubled - 1) // 2
    one = Fraction(1)

    def power(backend: Any, env: Mapping[str, Any]) -> Any:
        b = of(backend, env)
        result = backend.rational(one)
        for _ in range(abs(n)):
            result = result * b
        if n < 0:
            result = backend.rational(one) / result
        return result * backend.sqrt(b) if doubled % 2 else result
    return power


class Float64(Defaults[Samples]):
    """numpy float64; scalars may be arrays over samples (vectorised evaluation)."""

    name = "float64"

    def rational(self, value: Fraction) -> Samples:
        return float(value)

    def cos_sin(self, x: Samples) -> tuple[Samples, Samples]:
        return np.cos(x), np.sin(x)

    def sqrt(self, x: Samples) -> Samples:
        return np.sqrt(x)

    def exp(self, x: Samples) -> Samples:
        return np.exp(x)

    def pi(self) -> Samples:
        return math.pi

    def angle(self, value: TanHalf) -> Samples:
        return 2.0 * math.atan(float(Fraction(int(value.t.p), int(value.t.q))))

    def matrix(self, rows: Sequence[Sequence[Samples]], columns: int | None = None) -> np.ndarray:
        return np.array(rows, dtype=float) if rows else np.zeros((0, columns or 0))

    def stack(self, *mats: np.ndarray) -> np.ndarray:
        return np.vstack(mats)

    def solve(self, a: Sequence[Sequence[Samples]], b: Sequence[Sequence[Samples]]) -> list[list[Samples]]:
        n = len(a)
        k = len(b[0])
        if all(isinstance(v, float) for row in a for v in row) and all(isinstance(v, float) for row in b for v in row):
            X = self.solve_arrays(np.array(a, dtype=float), np.array(b, dtype=float))    # one state
            return [[X[i, j] for j in range(k)] for i in range(n)]
        # every entry to one shape: a row may be all constants (a coupling's closure equation)
        flat_a = np.broadcast_arrays(*(v for row in a for v in row))
        flat_b = np.broadcast_arrays(*(v for row in b for v in row))
        A = np.stack([np.stack(flat_a[i * n:(i + 1) * n], axis=-1) for i in range(n)], axis=-2)
        B = np.stack([np.stack(flat_b[i * k:(i + 1) * k], axis=-1) for i in range(n)], axis=-2)
        shape = np.broadcast_shapes(A.shape[:-2], B.shape[:-2])
        X = self.solve_arrays(np.broadcast_to(A, shape + (n, n)), np.broadcast_to(B, shape + (n, k)))
        return [[X[..., i, j] for j in range(k)] for i in range(n)]

    @staticmethod
    def solve_arrays(A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """:meth:`solve` on stacked arrays, A (..., n, n) and B (..., n, k): the batched
        closed-loop paths call it without building per-entry lists. Refuses (KinematicsError)
        a system whose 2-norm condition number exceeds 1e13."""
        cond = _condition_numbers(A)
        if np.any(~np.isfinite(cond)) or np.any(cond > 1e13):
            raise KinematicsError(f"singular linear system (condition number {np.max(cond):.3g})")
        return np.linalg.solve(A, B)

    def to_float(self, x: Samples) -> np.ndarray:
        return np.asarray(x, dtype=float)

    def magnitude(self, x: Samples) -> float:
        return abs(x) if isinstance(x, float) else float(np.max(np.abs(x)))

    def small(self, x: Samples, exponent: float) -> bool:
        return abs(x) <= 10.0 ** exponent if isinstance(x, float) else bool(np.all(np.abs(x) <= 10.0 ** exponent))


class Arb(Defaults[arb]):
    """python-flint ball arithmetic at ``digits`` decimal digits.

    Numbers made here (``rational``, ``pi``, ``number``) are born at these digits whatever
    precision is current; arithmetic on them (operators, ``cos_sin``, ``solve``) follows
    the current precision, which the public functions that compute set with ``activate``.
    """

    name = "arb"

    def __init__(self, digits: int = 50):
        self.digits = int(digits)
        with ctx.workdps(self.digits):
            self.bits = int(ctx.prec)

    def activate(self) -> AbstractContextManager[None]:
        return ctx.workprec(self.bits)

    def _made(self, make: Callable[[], arb]) -> arb:
        """``make()`` at this backend's precision (cheap when it is already current)."""
        if ctx.prec == self.bits:
            return make()
        with ctx.workprec(self.bits):
            return make()

    def rational(self, value: Fraction) -> arb:
        return self._made(lambda: arb(fmpq(value.numerator, value.denominator)))

    def cos_sin(self, x: arb) -> tuple[arb, arb]:
        return x.cos(), x.sin()

    def sqrt(self, x: arb) -> arb:
        return x.sqrt()

    def exp(self, x: arb) -> arb:
        return x.exp()

    def pi(self) -> arb:
        return self._made(arb.pi)

    def angle(self, value: TanHalf) -> arb:
        return self._made(lambda: 2 * arb(value.t).atan())

    def matrix(self, rows: Sequence[Sequence[arb]], columns: int | None = None) -> arb_mat:
        if not rows:
            return arb_mat(0, columns or 0)
        # arb entries are copied as they are (no conversion call per entry: W has 10^6); so
        # are ints and floats (exact), and the list is not checked entry by entry in Python
        # (0.05 s of TIAGo's 0.26 s W at 30 digits); anything else is made an arb first
        try:
            return arb_mat(len(rows), len(rows[0]), list(itertools.chain.from_iterable(rows)))
        except TypeError:
            return arb_mat(len(rows), len(rows[0]), [v if type(v) is arb else arb(v) for row in rows for v in row])

    def stack(self, *mats: arb_mat) -> arb_mat:
        return stack_flint(mats)

    def solve(self, a: Sequence[Sequence[arb]], b: Sequence[Sequence[arb]]) -> list[list[arb]]:
        return _solve_flint(arb_mat, arb, a, b, "singular linear system (no pivot excludes zero)")

    def to_float(self, x: arb) -> float:
        return float(arb(x).mid())

    def point(self, x: arb) -> arb:
        return arb(x).mid()

    def magnitude(self, x: arb) -> float:
        return float(abs(arb(x)).upper())

    def small(self, x: arb, exponent: float) -> bool:
        return bool(abs(arb(x)).upper() <= arb(10) ** exponent)


class Exact(Defaults[Union[fmpq, TanHalf]]):
    """Exact rationals (python-flint ``fmpq``); angles as :class:`TanHalf`."""

    name = "exact"
    exact = True

    def rational(self, value: Fraction) -> fmpq:
        return fmpq(value.numerator, value.denominator)

    def cos_sin(self, x: fmpq | TanHalf) -> tuple[fmpq, fmpq]:
        if isinstance(x, TanHalf):
            return x.cos_sin()
        if x == 0:
            return fmpq(1), fmpq(0)
        raise KinematicsError("exact arithmetic needs angles as TanHalf (rational cos and sin)")

    def sqrt(self, x: fmpq | TanHalf) -> fmpq:
        if isinstance(x, TanHalf):
            raise KinematicsError("sqrt of an angle")
        x = fmpq(x)
        p, q = int(x.p), int(x.q)
        rp, rq = math.isqrt(p) if p >= 0 else -1, math.isqrt(q)
        if p < 0 or rp * rp != p or rq * rq != q:
            raise KinematicsError(f"sqrt({x}) is not rational: exact arithmetic is not available here")
        return fmpq(rp, rq)

    def exp(self, x: fmpq | TanHalf) -> fmpq:
        if x == 0:
            return fmpq(1)
        raise KinematicsError("exp of a nonzero rational is not rational")

    def pi(self) -> fmpq:
        raise KinematicsError("pi is not rational")

    def angle(self, value: TanHalf) -> TanHalf:
        return value

    def matrix(self, rows: Sequence[Sequence[Any]], columns: int | None = None) -> fmpq_mat:
        if not rows:
            return fmpq_mat(0, columns or 0)
        return fmpq_mat(len(rows), len(rows[0]), [_as_fmpq(v) for row in rows for v in row])

    def stack(self, *mats: fmpq_mat) -> fmpq_mat:
        return stack_flint(mats)

    def solve(self, a: Sequence[Sequence[Any]], b: Sequence[Sequence[Any]]) -> list[list[Any]]:
        return _solve_flint(fmpq_mat, fmpq, a, b, "singular linear system")

    def to_float(self, x: Any) -> float:
        return float(int(x.p)) / float(int(x.q)) if isinstance(x, fmpq) else float(x)


class Symbolic(Defaults[Union[sympy.Expr, TanHalf]]):
    """sympy expressions; angles are sympy expressions (symbols or numbers)."""

    name = "symbolic"
    exact = True

    def rational(self, value: Fraction) -> sympy.Expr:
        return sympy.Rational(value.numerator, value.denominator)

    def cos_sin(self, x: Any) -> tuple[Any, Any]:
        if isinstance(x, TanHalf):
            c, s = x.cos_sin()
            return sympy.Rational(int(c.p), int(c.q)), sympy.Rational(int(s.p), int(s.q))
        return sympy.cos(x), sympy.sin(x)

    def sqrt(self, x: Any) -> Any:
        return sympy.sqrt(x)

    def exp(self, x: Any) -> Any:
        return sympy.exp(x)

    def pi(self) -> Any:
        return sympy.pi

    def angle(self, value: TanHalf) -> TanHalf:
        return value

    def matrix(self, rows: Sequence[Sequence[Any]], columns: int | None = None) -> sympy.Matrix:
        return sympy.Matrix(rows) if rows else sympy.zeros(0, columns or 0)

    def stack(self, *mats: sympy.Matrix) -> sympy.Matrix:
        return sympy.Matrix.vstack(*mats)

    def solve(self, a: Sequence[Sequence[Any]], b: Sequence[Sequence[Any]]) -> list[list[Any]]:
        A = sympy.Matrix(a)
        B = sympy.Matrix(b)
        X = A.LUsolve(B)
        return [[sympy.simplify(X[i, j]) for j in range(X.cols)] for i in range(X.rows)]

    def to_float(self, x: Any) -> float:
        return float(sympy.N(x))


def _solve_flint(kind: Any, convert: Callable[[Any], Any], a: Sequence[Sequence[Any]],
                 b: Sequence[Sequence[Any]], singular: str) -> list[list[Any]]:
    """``a x = b`` in python-flint matrices of ``kind`` (arb_mat: a verified solve;
    fmpq_mat: exact), entries made by ``convert``; KinematicsError(``singular``) when no
    solution is proven."""
    A = kind(len(a), len(a[0]), [convert(v) for row in a for v in row])
    B = kind(len(b), len(b[0]), [convert(v) for row in b for v in row])
    try:
        X = A.solve(B)
    except ZeroDivisionError:
        raise KinematicsError(singular) from None
    return [[X[i, j] for j in range(X.ncols())] for i in range(X.nrows())]


def _condition_numbers(A: np.ndarray) -> np.ndarray:
    """2-norm condition numbers of a batch of square matrices, or upper bounds of them that
    are all <= 1e13: cond_2 <= n cond_1, and cond_1 needs only an inverse (LU), several
    times cheaper than the SVD of np.linalg.cond, which is kept for the doubtful ones."""
    n = A.shape[-1]
    try:
        with np.errstate(all="ignore"):
            bound = n * np.abs(A).sum(axis=-2).max(axis=-1) * np.abs(np.linalg.inv(A)).sum(axis=-2).max(axis=-1)
    except np.linalg.LinAlgError:
        return np.linalg.cond(A)
    doubtful = ~(bound <= 1e13)
    if np.any(doubtful):
        bound = np.array(bound, dtype=float)
        bound[doubtful] = np.linalg.cond(A[doubtful])
    return bound


def _as_fmpq(v: Any) -> fmpq:
    if isinstance(v, fmpq):
        return v
    if isinstance(v, Fraction):
        return fmpq(v.numerator, v.denominator)
    return fmpq(v)


if TYPE_CHECKING:       # mypy checks here that each backend satisfies the interface
    _float64: Backend[Samples] = Float64()
    _arb: Backend[arb] = Arb()
    _exact: Backend[Union[fmpq, TanHalf]] = Exact()
    _symbolic: Backend[Union[sympy.Expr, TanHalf]] = Symbolic()
