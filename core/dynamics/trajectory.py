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
"""

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import sympy

from baseparams.dynamics import observation
from baseparams.dynamics.evaluator import Evaluator
from baseparams.numeric.backends import Float64
from baseparams.errors import InputError, KinematicsError

T = sympy.Symbol("t")


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
        if n < 2:
            raise InputError(f"a trajectory needs at least 2 samples, not {n}", file=mechanism.path,
                             key="trajectory.samples")
        t0 = spec.t_start if t_start is None else Fraction(t_start)
        t1 = spec.t_end if t_end is None else Fraction(t_end)
        times = tuple(t0 + (t1 - t0) * k / (n - 1) for k in range(n))
        return cls(dict(spec.expressions), times)

    def derivatives(self, names):
        """For each coordinate name: (q, qd, qdd) as sympy expressions of t."""
        out = []
        for name in names:
            e = self.expressions[name]
            d1 = sympy.diff(e, T)
            out.append((e, d1, sympy.diff(d1, T)))
        return out

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
