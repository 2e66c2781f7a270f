"""Exciting trajectories: the samples at which W is usually built.

A trajectory gives each independent coordinate as an expression of time (a finite
Fourier series by default); velocities and accelerations are its exact derivatives.
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

import functools
import os
import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import sympy

from baseparams.dynamics import observation
from baseparams.dynamics.evaluator import Evaluator
from baseparams.numeric.backends import Float64
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import MAX_SAMPLES

T = sympy.Symbol("t")
MEMORY_VARIABLE = "BASEPARAMS_MAX_MEMORY"
DEFAULT_MEMORY_LIMIT = 2 * 1024 ** 3
_UNITS = {"": 1, "K": 1024, "M": 1024 ** 2, "G": 1024 ** 3, "T": 1024 ** 4}


def float64_bytes(mechanism, samples: int) -> int:
    """Estimated peak working memory (bytes, beyond the interpreter's) of the float64
    observation matrix over ``samples`` samples and its SVD.

    Per sample: 8 bytes x (400 + 2 n p + 8 f p) with n tree coordinates, f independent ones
    and p columns of W. Measured peaks (benchmarks/sample_memory.py) stay below it on the
    built-in mechanisms: the n p term is the vectorised kinematics and regressor (a few
    arrays per coordinate and parameter), the f p term W itself, its economy SVD and their
    copies, the constant the per-sample scalars."""
    n = len(mechanism.coordinates)
    f = len(mechanism.independent) or n
    p = len(mechanism.parameters) + 4 * len(getattr(mechanism, "effects", ()))
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


def check_sample_count(mechanism, samples: int, key: str | None = "trajectory.samples") -> None:
    """Refuse (InputError) a sample count above MAX_SAMPLES or whose estimated float64 memory
    exceeds :func:`memory_limit`, before anything is allocated; the message gives the
    estimate and how to raise the limit."""
    if not 2 <= samples <= MAX_SAMPLES:
        raise InputError(f"{samples} samples: from 2 to {MAX_SAMPLES:,} are accepted",
                         file=mechanism.path, key=key)
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
    expressions: dict          # independent coordinate -> sympy expression of t
    times: tuple               # exact sample times (Fractions)
    label = "trajectory"       # kinematics errors name the trajectory (and the file)
    reports_closure = True     # arb: the worst closure residual along it is reported

    @classmethod
    def default(cls, mechanism, samples=None, t_start=None, t_end=None):
        spec = mechanism.trajectory
        if spec is None:
            raise InputError("the mechanism file has no [trajectory] section", file=mechanism.path,
                             key="trajectory")
        n = samples or spec.samples
        check_sample_count(mechanism, n, None if samples else "trajectory.samples")
        t0 = spec.t_start if t_start is None else Fraction(t_start)
        t1 = spec.t_end if t_end is None else Fraction(t_end)
        times = tuple(t0 + (t1 - t0) * k / (n - 1) for k in range(n))
        return cls(dict(spec.expressions), times)

    def derivatives(self, names):
        """For each coordinate name: (q, qd, qdd) as sympy expressions of t."""
        return [_derivatives(self.expressions[name]) for name in names]

    def independent_values(self, mechanism, backend, t):
        """(z, zd, zdd) at time ``t`` (backend number or, for float64, an array of times)."""
        names = mechanism.independent
        env = {"t": t}
        values = []
        for name, derivatives in zip(names, self.derivatives(names)):
            try:
                with np.errstate(all="ignore"):          # non-finite values are reported below
                    values.append([backend.evaluate(e, env) for e in derivatives])
            except (ValueError, ZeroDivisionError) as exc:
                raise InputError(f"cannot evaluate {derivatives[0]} or its derivatives: {exc}",
                                 file=mechanism.path, key=f"trajectory.q.{name}") from None
            if isinstance(backend, Float64) and not all(np.all(np.isfinite(v)) for v in values[-1]):
                bad = np.atleast_1d(t)[~np.all([np.isfinite(np.broadcast_to(v, np.shape(t)))
                                                 for v in values[-1]], axis=0)]
                raise KinematicsError(f"{name} or its derivatives are not finite at t = {float(bad[0]):.6g} s")
        z, zd, zdd = ([v[k] for v in values] for k in range(3))
        return z, zd, zdd

    # ----- a source of states (baseparams.dynamics.observation.States) -----------------
    @property
    def count(self):
        return len(self.times)

    def where(self, index):
        return "" if index is None else f"at t = {float(self.times[index]):.6g} s: "

    def values(self, mechanism, backend, index):
        """Sample ``index`` computed in ``backend`` from its exact time."""
        return self.independent_values(mechanism, backend, backend.number(self.times[index]))

    def float64_sample(self, mechanism):
        return samples_float64(mechanism, self)[0]

    def starts(self, mechanism):
        """The float64 positions of every sample (which also checks the coordinate limits)."""
        sample, t = samples_float64(mechanism, self)
        columns = [np.broadcast_to(np.asarray(v, dtype=float), t.shape) for v in sample.q]
        return [[float(v[k]) for v in columns] for k in range(len(t))]


@functools.lru_cache(maxsize=1024)
def _derivatives(expression: sympy.Expr) -> tuple:
    """(q, qd, qdd) of one expression of t, differentiated once per process: the per-state
    arithmetics ask for them at every sample (sympy took 3.5 s of a 12-body chain's dp run)."""
    d1 = sympy.diff(expression, T)
    return expression, d1, sympy.diff(d1, T)


def samples_float64(mechanism, trajectory):
    """All samples at once, vectorised; positions followed by continuation from q = 0."""
    backend = Float64()
    ev = Evaluator(mechanism, backend)
    t = np.array([float(x) for x in trajectory.times])
    z, zd, zdd = trajectory.independent_values(mechanism, backend, t)
    # a constant expression evaluates to one number: give every coordinate a value per sample
    z, zd, zdd = ([np.broadcast_to(np.asarray(v, float), t.shape).copy() for v in vals] for vals in (z, zd, zdd))
    try:
        sample = ev.sample(z, zd, zdd, None, where="")
    except KinematicsError:
        # Each sample followed separately from q = 0 failed somewhere: follow the trajectory
        # in time instead (each sample from the previous one); this names the first bad time.
        guess = _follow_in_time(ev, trajectory, t)
        sample = ev.sample(z, zd, zdd, guess, where="")
    check_limits(mechanism, sample.q, t)
    return sample, t


def _follow_in_time(ev, trajectory, times):
    """Positions sample after sample, each Newton started from the previous solution."""
    backend, mechanism = ev.backend, ev.mechanism
    solutions, q = [], None
    for tk in times:
        z, _, _ = trajectory.independent_values(mechanism, backend, float(tk))
        q = ev.assemble([float(v) for v in z], q, where=f"at t = {float(tk):.6g} s: ")
        solutions.append([float(v) for v in q])
    return [np.array(column) for column in zip(*solutions)]


def check_limits(mechanism, q, times):
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


def observation_matrix(mechanism, backend, trajectory=None, progress=None):
    """W over ``trajectory`` (the mechanism's default one if None): the one builder,
    :func:`baseparams.dynamics.observation.observation_matrix`, at the trajectory's samples."""
    return observation.observation_matrix(mechanism, backend, trajectory or Trajectory.default(mechanism),
                                          progress)
