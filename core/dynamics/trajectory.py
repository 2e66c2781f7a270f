"""Exciting trajectories: the samples at which W is usually built.

A trajectory gives each independent coordinate as an expression of time (a finite
Fourier series by default); velocities and accelerations are its exact derivatives,
evaluated by forward-mode differentiation (:class:`Jet`: value, first and second
derivative carried through each operation of the expression, in the backend's own
arithmetic): no symbolic derivative is built, which cost sympy most of dp's time on a
generated chain (docs/performance.md), and every operation is still the backend's, so
arb balls contain the exact derivatives and rationals are exact.
Sample times are exact rationals, so at D digits every sample is computed at D digits
from the start. Positions on the constraint manifold: in float64 all samples at once, by
continuation from the reference configuration (or, if that fails, sample after sample
along the trajectory); at D digits each sample's Newton starts from its float64 solution
and ends in a Krawczyk enclosure. A sample that leaves the reachable range, passes a
singular configuration or a coordinate limit stops the run with the time, the
coordinates and the residual. W itself is built by :mod:`baseparams.dynamics.observation`
(:func:`observation_matrix` here is W over a trajectory, the default one if none is given).

Sample counts are bounded before anything is allocated: at most
:data:`~baseparams.model.mechanism.MAX_SAMPLES`, and the float64 working memory that
:func:`float64_bytes` estimates must stay below :func:`memory_limit` (2 GiB unless the
environment variable ``BASEPARAMS_MAX_MEMORY`` says otherwise, e.g. ``8G``). The estimate
is what the float64 stage every solver runs (dp's W and SVD; vp's starting positions)
measured on the built-in mechanisms (benchmarks/sample_memory.py), rounded up.
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import sympy

from baseparams.dynamics import observation
from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.numeric.backends import Backend, Float64, evaluate
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import MAX_SAMPLES, Mechanism

T = sympy.Symbol("t")
MEMORY_VARIABLE = "BASEPARAMS_MAX_MEMORY"
DEFAULT_MEMORY_LIMIT = 2 * 1024 ** 3
_UNITS = {"": 1, "K": 1024, "M": 1024 ** 2, "G": 1024 ** 3, "T": 1024 ** 4}


def float64_bytes(mechanism: Mechanism, samples: int) -> int:
    """Estimated peak working memory (bytes, beyond the interpreter's) of the float64
    observation matrix over ``samples`` samples and its SVD.

    Per sample: 8 bytes x (400 + 2 n p + 8 f p) with n tree coordinates, f independent ones
    and p columns of W. Measured peaks (benchmarks/sample_memory.py) stay below it on the
    built-in mechanisms: the n p term is the vectorised kinematics and regressor (a few
    arrays per coordinate and parameter), the f p term W itself, its economy SVD and their
    copies, the constant the per-sample scalars."""
    n = len(mechanism.coordinates)
    f = len(mechanism.independent) or n
    p = len(mechanism.parameters) + 4 * len(mechanism.effects)
    return int(samples) * 8 * (400 + 2 * n * p + 8 * f * p)


def memory_limit() -> int:
    """Bytes the float64 stage may use: ``BASEPARAMS_MAX_MEMORY`` (``8G``, ``512M``, ``2.5G``,
    bytes) or 2 GiB."""
    text = os.environ.get(MEMORY_VARIABLE, "").strip()
    if not text:
        return DEFAULT_MEMORY_LIMIT
    match = re.fullmatch(r"([0-9]+(?:\.[0-9]*)?)\s*([KMGT]?)(?:i?B)?", text, re.IGNORECASE)
    if match is None or float(match[1]) <= 0:
        raise InputError(f"{MEMORY_VARIABLE} must be a size such as 8G, 512M or a number of bytes, "
                         f"not {text[:20]!r}")
    return int(float(match[1]) * _UNITS[match[2].upper()])


def blocked_bytes(mechanism: Mechanism, samples: int) -> int:
    """Estimated peak working memory (bytes) of the float64 stage built in row blocks of
    ``samples`` samples each (:meth:`Trajectory.pieces`, compressed into W's triangular
    factor as they come: :func:`baseparams.numeric.linalg.triangular_factor`): one block's
    kinematics and regressor (the 2 n p term of :func:`float64_bytes`), the block and its
    stacking under R (4 f p), and R with its SVD (8 p^2, whatever the sample count)."""
    n = len(mechanism.coordinates)
    f = len(mechanism.independent) or n
    p = len(mechanism.parameters) + 4 * len(mechanism.effects)
    return int(samples) * 8 * (400 + 2 * n * p + 4 * f * p) + 8 * 8 * p * p


def samples_per_block(mechanism: Mechanism) -> int:
    """The most samples a row block may have for :func:`blocked_bytes` to stay within
    :func:`memory_limit`; 0 when not even one sample fits (R alone is above the limit)."""
    limit, fixed = memory_limit(), blocked_bytes(mechanism, 0)
    per = blocked_bytes(mechanism, 1) - fixed
    return max(0, (limit - fixed) // per)


def check_sample_count(mechanism: Mechanism, samples: int, key: str | None = "trajectory.samples",
                       memory: bool = True) -> None:
    """Refuse (InputError) a sample count above MAX_SAMPLES or whose estimated float64 memory
    exceeds :func:`memory_limit`, before anything is allocated; the message gives the
    estimate and how to raise the limit. ``memory=False``: the count only (a caller that
    builds W in row blocks within the limit checks its own memory)."""
    if not 2 <= samples <= MAX_SAMPLES:
        raise InputError(f"{samples} samples: from 2 to {MAX_SAMPLES:,} are accepted",
                         file=mechanism.path, key=key)
    if not memory:
        return
    need, limit = float64_bytes(mechanism, samples), memory_limit()
    if need > limit:
        f = len(mechanism.independent) or len(mechanism.coordinates)
        raise InputError(
            f"{samples:,} samples need about {_size(need)} of working memory (W is {samples * f:,} x "
            f"{len(mechanism.parameters)}), above the limit of {_size(limit)}: use fewer samples "
            f"(at most about {max(2, samples * limit // need):,}), or raise the limit with the "
            f"environment variable {MEMORY_VARIABLE} (e.g. {MEMORY_VARIABLE}=16G)",
            file=mechanism.path, key=key)


def _size(n: int) -> str:
    return f"{n / 1024 ** 3:.1f} GiB" if n >= 1024 ** 3 else f"{n / 1024 ** 2:.0f} MiB"


@dataclass(frozen=True)
class Trajectory:
    """The independent coordinates as expressions of time, sampled at exact times; its
    samples are a source of states for :mod:`baseparams.dynamics.observation`."""
    expressions: Mapping[str, Any]   # independent coordinate -> sympy expression of t
    times: tuple[Fraction, ...]      # exact sample times
    label = "trajectory"       # kinematics errors name the trajectory (and the file)
    reports_closure = True     # arb: the worst closure residual along it is reported

    @classmethod
    def default(cls, mechanism: Mechanism, samples: int | None = None, t_start: Fraction | str | int | None = None,
                t_end: Fraction | str | int | None = None, memory: bool = True) -> Trajectory:
        """The mechanism file's trajectory (``samples`` overrides its count). ``memory=False``:
        no refusal by the float64 memory estimate (:func:`check_sample_count`), for a caller
        that builds W in row blocks (:meth:`pieces`)."""
        spec = mechanism.trajectory
        if spec is None:
            raise InputError("the mechanism file has no [trajectory] section", file=mechanism.path,
                             key="trajectory")
        n = samples or spec.samples
        check_sample_count(mechanism, n, None if samples else "trajectory.samples", memory=memory)
        t0 = spec.t_start if t_start is None else Fraction(t_start)
        t1 = spec.t_end if t_end is None else Fraction(t_end)
        return cls(dict(spec.expressions), even_times(t0, t1, n))

    def derivatives(self, names: Sequence[str]) -> list[tuple[Any, Any, Any]]:
        """For each coordinate name: (q, qd, qdd) as sympy expressions of t (symbolic
        differentiation, slow: for display; values come from :func:`values_at`)."""
        return [_derivatives(self.expressions[name]) for name in names]

    def independent_values(self, mechanism: Mechanism, backend: Backend,
                           t: Any) -> tuple[list[Any], list[Any], list[Any]]:
        """(z, zd, zdd) at time ``t`` (backend number or, for float64, an array of times)."""
        names = mechanism.independent
        values: list[list[Any]] = []
        for name in names:
            expression = self.expressions[name]
            try:
                with np.errstate(all="ignore"):          # non-finite values are reported below
                    values.append(list(values_at(expression, backend, t)))
            except (ValueError, ZeroDivisionError) as exc:
                raise InputError(f"cannot evaluate {expression} or its derivatives: {exc}",
                                 file=mechanism.path, key=f"trajectory.q.{name}") from None
            if isinstance(backend, Float64) and not all(np.all(np.isfinite(v)) for v in values[-1]):
                bad = np.atleast_1d(t)[~np.all([np.isfinite(np.broadcast_to(v, np.shape(t)))
                                                 for v in values[-1]], axis=0)]
                raise KinematicsError(f"{name} or its derivatives are not finite at t = {float(bad[0]):.6g} s")
        z, zd, zdd = ([v[k] for v in values] for k in range(3))
        return z, zd, zdd

    def pieces(self, samples: int) -> list[Trajectory]:
        """The same trajectory cut into consecutive pieces of at most ``samples`` samples: W
        over the pieces, stacked in order, is W over the whole (rows are sample-major)."""
        step = max(1, int(samples))
        return [Trajectory(self.expressions, self.times[k:k + step]) for k in range(0, len(self.times), step)]

    # ----- a source of states (baseparams.dynamics.observation.States) -----------------
    @property
    def count(self) -> int:
        return len(self.times)

    def where(self, index: int | None) -> str:
        return "" if index is None else f"at t = {float(self.times[index]):.6g} s: "

    def values(self, mechanism: Mechanism, backend: Backend, index: int) -> tuple[list[Any], list[Any], list[Any]]:
        """Sample ``index`` computed in ``backend`` from its exact time."""
        return self.independent_values(mechanism, backend, backend.number(self.times[index]))

    def float64_sample(self, mechanism: Mechanism) -> Sample:
        return samples_float64(mechanism, self)[0]

    def starts(self, mechanism: Mechanism) -> list[list[float]]:
        """The float64 positions of every sample (which also checks the coordinate limits)."""
        sample, t = samples_float64(mechanism, self)
        columns = [np.broadcast_to(np.asarray(v, dtype=float), t.shape) for v in sample.q]
        return [[float(v[k]) for v in columns] for k in range(len(t))]


def even_times(t0: Fraction, t1: Fraction, n: int) -> tuple[Fraction, ...]:
    """``n`` exact times evenly spaced from ``t0`` to ``t1``: t0 + (t1 - t0) k / (n - 1),
    over one common denominator (a Fraction per sample, not four Fraction operations)."""
    t0, t1 = Fraction(t0), Fraction(t1)
    a, b, c, d = t0.numerator, t0.denominator, t1.numerator, t1.denominator
    start, span, den = a * d * (n - 1), c * b - a * d, b * d * (n - 1)
    return tuple(Fraction(start + span * k, den) for k in range(n))


def values_at(expression: sympy.Expr, backend: Backend, t: Any) -> tuple[Any, Any, Any]:
    """(q, qd, qdd) of an expression of t at ``t`` (a backend number; float64: an array of
    times), in ``backend``'s arithmetic, by forward-mode differentiation: exact in
    rationals and sympy, enclosing in arb, as evaluating the symbolic derivatives would be."""
    jet = evaluate(_JetBackend(backend), expression, {"t": Jet(t, backend.rational(Fraction(1)))})
    zero = backend.rational(Fraction(0))
    return jet.v, zero if jet.d1 is None else jet.d1, zero if jet.d2 is None else jet.d2


def _plus(a: Any, b: Any) -> Any:
    return b if a is None else a if b is None else a + b


def _times(a: Any, b: Any) -> Any:
    return None if a is None or b is None else a * b


def _negative(a: Any) -> Any:
    return None if a is None else -a


class Jet:
    """A value with its first and second derivatives in t (None: identically zero), in any
    backend's numbers; arithmetic applies the product and quotient rules."""

    __slots__ = ("v", "d1", "d2")

    def __init__(self, v: Any, d1: Any = None, d2: Any = None) -> None:
        self.v, self.d1, self.d2 = v, d1, d2

    def __add__(self, other: Jet) -> Jet:
        return Jet(self.v + other.v, _plus(self.d1, other.d1), _plus(self.d2, other.d2))

    def __mul__(self, other: Jet) -> Jet:
        cross = _times(self.d1, other.d1)
        return Jet(self.v * other.v, _plus(_times(self.d1, other.v), _times(self.v, other.d1)),
                   _plus(_plus(_times(self.d2, other.v), None if cross is None else cross + cross),
                         _times(self.v, other.d2)))

    def __truediv__(self, other: Jet) -> Jet:
        # w = u / v: w' = (u' - w v') / v, w'' = (u'' - 2 w' v' - w v'') / v
        w = self.v / other.v
        d1 = _plus(self.d1, _negative(_times(w, other.d1)))
        d1 = None if d1 is None else d1 / other.v
        cross = _times(d1, other.d1)
        d2 = _plus(self.d2, _plus(_negative(_plus(cross, cross)), _negative(_times(w, other.d2))))
        return Jet(w, d1, None if d2 is None else d2 / other.v)


class _JetBackend:
    """The functions of an expression (sin, cos, exp, sqrt) on jets, computed by ``base``:
    :func:`baseparams.numeric.backends.evaluate` then differentiates while it evaluates."""

    def __init__(self, base: Backend) -> None:
        self.base = base

    def rational(self, value: Fraction) -> Jet:
        return Jet(self.base.rational(value))

    def pi(self) -> Jet:
        return Jet(self.base.pi())

    def cos_sin(self, x: Jet) -> tuple[Jet, Jet]:
        c, s = self.base.cos_sin(x.v)
        if x.d1 is None:
            return Jet(c), Jet(s)
        u1 = x.d1
        u1u1 = u1 * u1
        return (Jet(c, -(s * u1), _plus(-(c * u1u1), _times(-s, x.d2))),
                Jet(s, c * u1, _plus(-(s * u1u1), _times(c, x.d2))))

    def sqrt(self, x: Jet) -> Jet:
        r = self.base.sqrt(x.v)
        if x.d1 is None:
            return Jet(r)
        # r^2 = u: r' = u' / (2 r), r'' = (u'' - 2 r'^2) / (2 r)
        d1 = x.d1 / (r + r)
        d1d1 = d1 * d1
        return Jet(r, d1, _plus(x.d2, -(d1d1 + d1d1)) / (r + r))

    def exp(self, x: Jet) -> Jet:
        e = self.base.exp(x.v)
        if x.d1 is None:
            return Jet(e)
        return Jet(e, e * x.d1, e * _plus(x.d2, x.d1 * x.d1))


@functools.lru_cache(maxsize=1024)
def _derivatives(expression: sympy.Expr) -> tuple[Any, Any, Any]:
    """(q, qd, qdd) of one expression of t, differentiated once per process: the per-state
    arithmetics ask for them at every sample (sympy's derivatives dominated a 12-body chain's
    dp run before this cache: docs/performance.md)."""
    d1 = sympy.diff(expression, T)
    return expression, d1, sympy.diff(d1, T)


def samples_float64(mechanism: Mechanism, trajectory: Trajectory) -> tuple[Sample, np.ndarray]:
    """All samples at once, vectorised; positions followed by continuation from q = 0."""
    backend = Float64()
    ev = Evaluator(mechanism, backend)
    t = np.array([float(x) for x in trajectory.times])
    values = trajectory.independent_values(mechanism, backend, t)
    # a constant expression evaluates to one number: give every coordinate a value per sample
    z, zd, zdd = ([np.broadcast_to(np.asarray(v, float), t.shape).copy() for v in vals] for vals in values)
    try:
        sample = ev.sample(z, zd, zdd, None, where="")
    except KinematicsError:
        # Each sample followed separately from q = 0 failed somewhere: follow the trajectory
        # in time instead (each sample from the previous one); this names the first bad time.
        guess = _follow_in_time(ev, trajectory, t)
        sample = ev.sample(z, zd, zdd, guess, where="")
    check_limits(mechanism, sample.q, t)
    return sample, t


def _follow_in_time(ev: Evaluator, trajectory: Trajectory, times: np.ndarray) -> list[np.ndarray]:
    """Positions sample after sample, each Newton started from the previous solution."""
    backend, mechanism = ev.backend, ev.mechanism
    solutions: list[list[float]] = []
    q: list[Any] | None = None
    for tk in times:
        z, _, _ = trajectory.independent_values(mechanism, backend, float(tk))
        q = ev.assemble([float(v) for v in z], q, where=f"at t = {float(tk):.6g} s: ")
        solutions.append([float(v) for v in q])
    return [np.array(column) for column in zip(*solutions)]


def check_limits(mechanism: Mechanism, q: Sequence[Any], times: Any) -> None:
    """Raise a KinematicsError at the first time a coordinate leaves its joint's limits."""
    for joint in mechanism.joints:
        for name, (lo, hi) in joint.limits.items():
            if name not in mechanism.coordinates:
                continue
            values = np.atleast_1d(np.asarray(q[mechanism.coordinates.index(name)], dtype=float))
            bad = np.nonzero((values < lo) | (values > hi))[0]
            if bad.size:
                k = int(bad[0])
                tk = np.atleast_1d(times)[k] if np.size(times) > 1 else times
                raise KinematicsError(f"at t = {float(tk):.6g} s coordinate {name} = {values[k]:.6g} "
                                      f"leaves its range [{lo:.6g}, {hi:.6g}]")


def observation_matrix(mechanism: Mechanism, backend: Backend, trajectory: Trajectory | None = None,
                       progress: observation.Progress | None = None) -> tuple[Any, dict[str, Any]]:
    """W over ``trajectory`` (the mechanism's default one if None): the one builder,
    :func:`baseparams.dynamics.observation.observation_matrix`, at the trajectory's samples."""
    return observation.observation_matrix(mechanism, backend, trajectory or Trajectory.default(mechanism),
                                          progress)
