"""Built-in solver ``vp``: Gautier's method in certified ball arithmetic, precision raised
automatically (the seed paper's VP, with a proof of the rank).

Registered through the ``baseparams_solvers`` hook by the entry point ``builtin_vp``.
"""

from baseparams.hookspecs import hookimpl
from baseparams.solvers.protocol import Solver

from .solver import VariablePrecisionSolver


@hookimpl
def baseparams_solvers() -> list[Solver]:
    return [VariablePrecisionSolver()]
