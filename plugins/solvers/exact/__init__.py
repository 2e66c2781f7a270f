"""Built-in solver ``exact``: Gautier's method over the rationals, for open chains.

Registered through the ``baseparams_solvers`` hook by the entry point ``builtin_exact``.
"""

from baseparams.hookspecs import hookimpl
from baseparams.solvers.protocol import Solver

from .solver import ExactSolver


@hookimpl
def baseparams_solvers() -> list[Solver]:
    return [ExactSolver()]
