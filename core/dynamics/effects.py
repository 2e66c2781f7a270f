"""Model effects: forces on a joint coordinate that are linear in their coefficients.

An effect adds columns to the regressor: the generalized force it needs on its
coordinate is ``sum(coefficient * column(q, qd, qdd))``. On a dependent coordinate of a
closed loop the columns map to the independent coordinates by R^T, like K
(``baseparams.dynamics.evaluator.Sample.projection`` is R); identification and diagnosis, which
add effects to a model, build on this.
"""

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Shape:
    """A nonlinear parameter of an effect's columns (Coulomb friction's transition speed):
    the columns stay linear in the coefficients at a fixed shape value; diagnosis fits the
    value (variable projection over a grid of ``grid`` values, each a multiple of the
    coordinate's RMS speed when ``relative`` is "speed"), and a mechanism file may give it
    among the effect's ``values``. ``default`` is used when nothing gives it."""
    name: str
    default: float
    grid: tuple[float, ...] = ()             # candidate values (times the RMS speed if relative)
    relative: str = ""                       # "speed": grid values are multiples of RMS |qd|


@runtime_checkable
class EffectKind(Protocol):
    """What the ``baseparams_effects`` hook returns and what identification, diagnosis, the
    builder and excitation design use of an effect kind; :class:`Effect` satisfies it.

    ``coefficients``: the coefficient names, one per column; ``shapes``: the nonlinear
    parameters :meth:`columns` takes by keyword; ``generalises``: the kinds this one
    generalises (where the data cannot tell the two apart, diagnosis names the simpler one).
    Optional: ``angular`` (True: the columns are harmonics of q, so diagnosis does not try the
    kind on a length coordinate unless asked for by name; :class:`Effect` has it, default False).
    """

    @property
    def name(self) -> str: ...

    @property
    def description(self) -> str: ...

    @property
    def coefficients(self) -> tuple[str, ...]: ...

    @property
    def shapes(self) -> tuple[Shape, ...]: ...

    @property
    def generalises(self) -> tuple[str, ...]: ...

    def columns(self, q: npt.ArrayLike, qd: npt.ArrayLike, qdd: npt.ArrayLike,
                **options: float) -> list[FloatArray]:
        """Columns (one per coefficient) on one coordinate's samples of q, qd, qdd."""
        ...

    def coefficient_names(self, coordinate: str) -> list[str]:
        """The coefficients' names on ``coordinate`` (``fv_q1``)."""
        ...

    @property
    def shape_names(self) -> tuple[str, ...]:
        """The names of :attr:`shapes`."""
        ...

    def shape_values(self, values: Mapping[str, Any]) -> dict[str, float]:
        """The shape parameters among an effect's given ``values`` (name -> float)."""
        ...


@dataclass(frozen=True)
class Effect:
    """An effect kind given by a function of (q, qd, qdd) returning its columns."""
    name: str
    description: str
    coefficients: tuple[str, ...]            # coefficient names, one per column
    columns_fn: Callable[..., list[Any]]     # (q, qd, qdd, **shapes) -> list of arrays
    shapes: tuple[Shape, ...] = ()           # Shape parameters passed to columns_fn by name
    # kinds this one generalises: where the data cannot tell the two apart, diagnosis names the
    # simpler one (cogging's harmonics look like an offset or a spring over a small range)
    generalises: tuple[str, ...] = ()
    # columns that are harmonics of q, so q must be an angle: by default not a candidate on a
    # length coordinate (q in metres has no period: a prismatic leg's cos q is ~1 over its travel)
    angular: bool = False

    def columns(self, q: npt.ArrayLike, qd: npt.ArrayLike, qdd: npt.ArrayLike,
                **options: float) -> list[FloatArray]:
        """Columns (one per coefficient) evaluated on arrays of q, qd, qdd of one coordinate."""
        cols = self.columns_fn(np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float), **options)
        shape = np.broadcast_shapes(np.shape(q), np.shape(qd), np.shape(qdd))
        return [np.broadcast_to(np.asarray(c, float), shape) for c in cols]

    def coefficient_names(self, coordinate: str) -> list[str]:
        return [f"{c}_{coordinate}" for c in self.coefficients]

    @property
    def shape_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.shapes)

    def shape_values(self, values: Mapping[str, Any]) -> dict[str, float]:
        """The shape parameters among an effect's given ``values`` (name -> float)."""
        return {name: float(values[name]) for name in self.shape_names if name in values}
