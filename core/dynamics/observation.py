"""The observation matrix W (the regressor stacked over states), one builder for every arithmetic.

Every source of states (the exciting trajectory, an independent random batch, the exact
solver's random rational states) gives the builder the same few things (:class:`States`):
its independent positions, velocities and accelerations in any backend, all states at
once in float64, and float64 tree coordinates to start a closed loop's Newton from. The
backend decides how W is built and what matrix it is:

- :class:`~baseparams.numeric.backends.Float64`: all states at once, vectorised (the fast
  path); a numpy array.
- :class:`~baseparams.numeric.backends.Arb`: state after state at the backend's digits from
  the start; a closed loop's positions by Newton at full precision from the float64
  solution, then a Krawczyk enclosure, so every ball of W contains its exact value; an
  ``arb_mat``. The builder enters the backend's precision itself and restores the caller's.
- :class:`~baseparams.numeric.backends.Exact`: state after state over the rationals (open
  chains); an ``fmpq_mat``.

Rows are sample-major: the ``f`` rows of the first state, then of the second ...
"""

import contextlib
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Protocol

import numpy as np
from flint import arb

from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.errors import KinematicsError
from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Arb, Backend, BallRows, Float64

Progress = Callable[[int, int], None]


class States(Protocol):
    """What the builder needs from a source of states."""

    @property
    def label(self) -> str:
        """Prefixed (with the mechanism file) to kinematics errors; "" for none."""

    @property
    def reports_closure(self) -> bool:
        """arb: report the worst closure residual (one more closure per state)."""

    @property
    def count(self) -> int:
        """How many states."""

    def where(self, index: int | None) -> str:
        """Message prefix naming state ``index`` (None: all states at once)."""

    def values(self, mechanism: Mechanism, backend: Backend, index: int) -> tuple[list[Any], list[Any], list[Any]]:
        """State ``index``'s independent positions, velocities, accelerations in ``backend``."""

    def float64_sample(self, mechanism: Mechanism) -> Sample:
        """Every state at once in float64 (arrays over states), positions assembled."""

    def starts(self, mechanism: Mechanism) -> list[list[float]] | None:
        """Per state, float64 tree coordinates to start Newton from (used for closed loops),
        or None to start from the reference configuration. Called before the per-state
        arithmetics for every mechanism: a trajectory checks its coordinate limits here."""


@dataclass(frozen=True)
class RationalStates:
    """States given exactly: per state, a tuple of the independent positions (Fraction,
    fmpq, or :class:`~baseparams.numeric.backends.TanHalf` for an angle: exact in every
    backend, rational cos and sin in Exact), one of velocities and one of accelerations;
    for a closed loop, per state the float tree coordinates to start Newton from."""

    z: tuple[tuple[Any, ...], ...]
    zd: tuple[tuple[Any, ...], ...]
    zdd: tuple[tuple[Any, ...], ...]
    start: tuple[Any, ...] | None = None
    name: str = "state"
    label: str = ""
    reports_closure: bool = False

    @property
    def count(self) -> int:
        return len(self.z)

    def where(self, index: int | None) -> str:
        return f"{self.name}s: " if index is None else f"{self.name} {index + 1}: "

    def values(self, mechanism: Mechanism, backend: Backend, index: int) -> tuple[list[Any], list[Any], list[Any]]:
        z, zd, zdd = ([backend.number(v) for v in column[index]] for column in (self.z, self.zd, self.zdd))
        return z, zd, zdd

    def float64_sample(self, mechanism: Mechanism) -> Sample:
        backend = Float64()
        f = len(self.z[0]) if self.z else 0
        columns = [[np.array([backend.number(s[k]) for s in values]) for k in range(f)]
                   for values in (self.z, self.zd, self.zdd)]
        start = None
        if mechanism.loops and self.start is not None:
            start = [np.array([float(v) for v in column]) for column in zip(*self.start)]
        return Evaluator(mechanism, backend).sample(*columns, start, where=self.where(None))

    def starts(self, mechanism: Mechanism) -> list[list[float]] | None:
        return None if self.start is None else [[float(v) for v in s] for s in self.start]


@dataclass(frozen=True)
class Subset:
    """Some states of another source, in its order: W at them is the rows of W at the
    whole source that belong to those states, to the last bit of every ball (the same exact
    values and the same float64 Newton starts). For a proof that needs balls at a few
    states only, where the float64 W of every state chose them; in float64,
    :func:`observation_matrix` takes the source's rows."""

    source: States
    indices: tuple[int, ...]
    reports_closure: bool = False      # no closure residual: one closure less per state

    @property
    def label(self) -> str:
        return self.source.label

    @property
    def count(self) -> int:
        return len(self.indices)

    def where(self, index: int | None) -> str:
        return self.source.where(None if index is None else self.indices[index])

    def values(self, mechanism: Mechanism, backend: Backend, index: int) -> tuple[list[Any], list[Any], list[Any]]:
        return self.source.values(mechanism, backend, self.indices[index])

    def float64_sample(self, mechanism: Mechanism) -> Sample:
        """The source's float64 states at ``indices`` (arrays over the chosen states)."""
        whole = self.source.float64_sample(mechanism)
        pick = list(self.indices)

        def take(v: Any) -> Any:
            return np.asarray(v)[pick] if np.ndim(v) else v

        return Sample([take(v) for v in whole.q], [take(v) for v in whole.qd], [take(v) for v in whole.qdd],
                      None, [[take(v) for v in row] for row in whole.projection], whole.kin)

    def starts(self, mechanism: Mechanism) -> list[list[float]] | None:
        starts = self.source.starts(mechanism)
        return None if starts is None else [starts[i] for i in self.indices]


def observation_matrix(mechanism: Mechanism, backend: Backend, states: States,
                       progress: Progress | None = None, *, entries: bool = False) -> tuple[Any, dict[str, Any]]:
    """W at ``states`` in ``backend``'s arithmetic and matrix type: (W, info).

    info: ``samples`` (the number of states); in arb also ``positions_enclosed`` and, when
    the source asks for it, ``closure_residual`` (an upper bound of the worst loop-closure
    residual, text).
    ``progress(done, count)`` is called after each state (per-state arithmetics).
    ``entries`` (arb only): W as its entries (:class:`~baseparams.numeric.backends.BallRows`),
    not an arb_mat, for an analysis that reads each entry once (vp's certified one).
    """
    if entries and not isinstance(backend, Arb):
        raise ValueError(f"entries=True is for arb, not {type(backend).__name__}")
    with _where(mechanism, states):
        if isinstance(backend, Float64):
            return _vectorised(mechanism, states)
        return _per_state(mechanism, backend, states, progress, entries)


@contextlib.contextmanager
def _where(mechanism: Mechanism, states: States) -> Iterator[None]:
    """A KinematicsError raised inside names the file and the states (their label), if any."""
    try:
        yield
    except KinematicsError as exc:
        if not states.label:
            raise
        where = f"{mechanism.path}: {states.label}: " if mechanism.path else f"{states.label}: "
        raise KinematicsError(where + str(exc)) from None


def evaluate_states(mechanism: Mechanism, backend: Backend, states: States, certify: bool = True) -> list[Sample]:
    """The evaluated states themselves (for analyses other than W), state after state in
    ``backend``; ``certify`` (arb): closed-loop positions enclosed by Krawczyk's test."""
    ev = Evaluator(mechanism, backend, certify=certify)
    with backend.activate():
        return list(_each_sample(ev, states))


def _width(mechanism: Mechanism) -> int:
    return len(mechanism.independent) or len(mechanism.coordinates)


def _vectorised(mechanism: Mechanism, states: States) -> tuple[np.ndarray, dict[str, Any]]:
    if isinstance(states, Subset):
        f = _width(mechanism)
        rows = [index * f + k for index in states.indices for k in range(f)]
        return _vectorised(mechanism, states.source)[0][rows], {"samples": states.count}
    k = states.float64_sample(mechanism).regressor_array()        # (states, f, parameters)
    return k.reshape(states.count * _width(mechanism), len(mechanism.parameters)), {"samples": states.count}


def _each_sample(ev: Evaluator, states: States) -> Iterator[Sample]:
    """Each state evaluated in turn (call within the backend's precision)."""
    mechanism, backend = ev.mechanism, ev.backend
    starts = states.starts(mechanism)
    for index in range(states.count):
        guess = ([backend.number(Fraction(v)) for v in starts[index]] if starts is not None and mechanism.loops
                 else None)     # a float start is the rational it stands for
        z, zd, zdd = states.values(mechanism, backend, index)
        yield ev.sample(z, zd, zdd, guess, where=states.where(index))


def _per_state(mechanism: Mechanism, backend: Backend, states: States,
               progress: Progress | None, entries: bool = False) -> tuple[Any, dict[str, Any]]:
    ev = Evaluator(mechanism, backend, certify=True)
    enclosing = isinstance(backend, Arb)
    residual = enclosing and states.reports_closure
    rows: list[list[Any]] = []
    with backend.activate():
        worst = arb(0)
        for index, sample in enumerate(_each_sample(ev, states)):
            rows.extend(sample.regressor())
            if residual and mechanism.loops:
                values, _ = ev.closure(sample.q)
                for v in values:
                    bound = abs(arb(v)).upper()
                    if bound > worst:
                        worst = bound
            if progress:
                progress(index + 1, states.count)
        cols = len(mechanism.parameters)
        W = BallRows(len(rows), cols, list(itertools.chain.from_iterable(rows))) if entries else \
            backend.matrix(rows, cols)
        info: dict[str, Any] = {"samples": states.count}
        if enclosing:
            info["positions_enclosed"] = bool(mechanism.loops)
        if residual:
            info["closure_residual"] = worst.str(3, radius=False)
    return W, info
