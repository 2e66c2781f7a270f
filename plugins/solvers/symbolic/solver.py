"""The ``symbolic`` solver's plugin object: options in, :func:`.elimination.solve` out."""

from baseparams.dynamics.trajectory import Trajectory
from baseparams.solvers.protocol import (MAX_DIGITS, MAX_SAMPLES, MAX_SEED, Capabilities, SolverOption,
                                         check_options, require_applicable)

from .elimination import solve


class SymbolicSolver:
    """Symbolic base parameters by multipole transfers; rank certified in ball arithmetic."""

    name = "symbolic"
    description = ("Ros et al.'s multipole transfers, automated: exact expressions in the geometry "
                   "symbols, rank checked on W in ball arithmetic")
    capabilities = Capabilities(closed_loops=True, certifies=True, exact_coefficients=True,
                                symbolic_coefficients=True, derivation=True)
    options = (
        SolverOption("keep", tuple, (), "parameters never to eliminate (names; text: comma or "
                     "space separated)", item=str),
        SolverOption("eliminate_first", tuple, (), "parameters to eliminate whenever a transfer "
                     "allows it", item=str),
        SolverOption("certify", bool, True, "check the rank on W in ball arithmetic"),
        SolverOption("digits", int, None, "precision of that check (default 40)", minimum=10,
                     maximum=MAX_DIGITS),
        SolverOption("samples", int, None, "trajectory samples for that check (default: the "
                     "mechanism file's)", minimum=2, maximum=MAX_SAMPLES),
        SolverOption("seed", int, 1, "seed of the sampled body conditions and transfers", minimum=0,
                     maximum=MAX_SEED),
    )

    def applicable(self, mechanism):
        """Any mechanism without couplings between joint coordinates: a joint type without
        transfer rules makes the rank an upper bound, which the result says. A coupled joint
        moves with its leader, so the per-joint transfer rules (which assume every joint
        free) do not describe it."""
        if mechanism.couplings:
            names = ", ".join(f"{c.coordinate} follows {c.leader}" for c in mechanism.couplings)
            return (f"the transfer rules assume every joint moves freely, and {names}: use --solver vp "
                    "(certified) instead")
        return None

    def solve(self, mechanism, progress=None, **options):
        """Symbolic base parameters and their derivation; ``options`` as declared in
        ``options``. ``progress`` is accepted and not used (the solver has no long phase
        worth reporting)."""
        chosen = check_options(self, options, mechanism)
        require_applicable(self, mechanism)
        samples = chosen["samples"]
        trajectory = Trajectory.default(mechanism, samples=samples) if samples else None
        return solve(mechanism, keep=chosen["keep"], eliminate_first=chosen["eliminate_first"],
                     certify_rank=chosen["certify"], digits=chosen["digits"] or 40, seed=chosen["seed"],
                     trajectory=trajectory)
