"""Built-in symbolic solver (entry point ``builtin_symbolic``): Ros et al.'s multipole
transfers, automated (:mod:`baseparams.plugins.solvers.symbolic.elimination`), registered like any third party's solver.

The result's coefficients are sympy-parsable expressions in the geometry symbols, with
their exact values under ``expression_values``; ``certified`` is true only when ball
arithmetic proves rank(W) >= the symbolic count and every generator passes its null-vector
check on that W (evidence for rank <= the count). ``result.derivation`` holds the
derivation that :func:`baseparams.cli.report.render` prints (text, Markdown, LaTeX).
"""

from baseparams.hookspecs import hookimpl
from baseparams.solvers.protocol import Solver

from .solver import SymbolicSolver


@hookimpl
def baseparams_solvers() -> list[Solver]:
    return [SymbolicSolver()]
