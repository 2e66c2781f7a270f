"""Built-in symbolic solver (entry point ``builtin_symbolic``): Ros et al.'s multipole
transfers, automated (:mod:`baseparams.symbolic`), registered like any third party's solver.

The result's coefficients are sympy-parsable expressions in the geometry symbols, with
their exact values under ``expression_values``; ``certified`` is true only when ball
arithmetic proves rank(W) >= the symbolic count and every generator passes its null-vector
check on that W (evidence for rank <= the count). ``result.derivation`` holds the
derivation that :func:`baseparams.report.render` prints (text, Markdown, LaTeX).
"""

from baseparams.hookspecs import hookimpl


def _names(value):
    if value is None:
        return ()
    if isinstance(value, str):
        value = [v for v in value.replace(",", " ").split() if v]
    return tuple(value)


class SymbolicSolver:
    """Symbolic base parameters by multipole transfers; rank certified in ball arithmetic."""

    name = "symbolic"
    description = ("Ros et al.'s multipole transfers, automated: exact expressions in the geometry "
                   "symbols, rank checked on W in ball arithmetic")

    def solve(self, mechanism, keep=None, eliminate_first=None, certify=True, digits=None,
              samples=None, seed=1, **options):
        """``keep``/``eliminate_first``: parameter names (list or comma/space separated text);
        ``certify``: compute W in ball arithmetic at ``digits`` (default 40) to check the rank;
        ``samples``: trajectory samples for that check (default: the mechanism's)."""
        from baseparams.symbolic import solve
        from baseparams.trajectory import Trajectory

        trajectory = Trajectory.default(mechanism, samples=samples) if samples else None
        return solve(mechanism, keep=_names(keep),
                     eliminate_first=_names(eliminate_first),
                     certify_rank=certify, digits=digits or 40, seed=seed, trajectory=trajectory)


@hookimpl
def baseparams_solvers():
    return [SymbolicSolver()]
