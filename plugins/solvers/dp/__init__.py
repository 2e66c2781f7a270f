"""Built-in solver ``dp``: Gautier's SVD method in double precision (the seed paper's DP).

Registered through the ``baseparams_solvers`` hook by the entry point ``builtin_dp``.
"""

from baseparams.hookspecs import hookimpl
from baseparams.solvers.protocol import Solver

from .solver import DoublePrecisionSolver


@hookimpl
def baseparams_solvers() -> list[Solver]:
    return [DoublePrecisionSolver()]
