"""The ``symbolic`` solver's plugin object: options in, :func:`.elimination.solve` out."""

from baseparams.dynamics.trajectory import Trajectory

from .elimination import solve




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

        trajectory = Trajectory.default(mechanism, samples=samples) if samples else None
        return solve(mechanism, keep=_names(keep),
                     eliminate_first=_names(eliminate_first),
                     certify_rank=certify, digits=digits or 40, seed=seed, trajectory=trajectory)
