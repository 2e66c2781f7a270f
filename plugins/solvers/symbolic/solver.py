"""The ``symbolic`` solver's plugin object: options in, :func:`.elimination.solve` out."""

from baseparams.dynamics.trajectory import Trajectory
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.protocol import MAX_DIGITS, MAX_SAMPLES, MAX_SEED, Capabilities, Progress, SolverOption
from baseparams.solvers.result import BaseParameterResult

from .elimination import solve

CERTIFY_DIGITS = 40        # the rank check's precision unless the digits option says otherwise
SEED = 1                   # seed of the sampled body conditions and transfers


class SymbolicSolver:
    """Symbolic base parameters by multipole transfers; rank certified in ball arithmetic."""

    name = "symbolic"
    description = ("Ros et al.'s multipole transfers, automated: exact expressions in the geometry "
                   "symbols, rank checked on W in ball arithmetic")
    capabilities = Capabilities(closed_loops=True, certifies=True, exact_coefficients=True,
                                symbolic_coefficients=True, derivation=True)
    options: tuple[SolverOption, ...] = (
        SolverOption("keep", tuple, (), "parameters never to eliminate (names; text: comma or "
                     "space separated)", item=str),
        SolverOption("eliminate_first", tuple, (), "parameters to eliminate whenever a transfer "
                     "allows it", item=str),
        SolverOption("certify", bool, True, "check the rank on W in ball arithmetic"),
        SolverOption("digits", int, None, f"precision of that check (default {CERTIFY_DIGITS})", minimum=10,
                     maximum=MAX_DIGITS),
        SolverOption("samples", int, None, "trajectory samples for that check (default: the "
                     "mechanism file's)", minimum=2, maximum=MAX_SAMPLES),
        SolverOption("seed", int, SEED, "seed of the sampled body conditions and transfers", minimum=0,
                     maximum=MAX_SEED),
    )

    def applicable(self, mechanism: Mechanism) -> str | None:
        """Any mechanism without couplings between joint coordinates: a joint type without
        transfer rules makes the rank an upper bound, which the result says. A coupled joint
        moves with its leader, so the per-joint transfer rules (which assume every joint
        free) do not describe it."""
        if mechanism.couplings:
            names = ", ".join(f"{c.coordinate} follows {c.leader}" for c in mechanism.couplings)
            return (f"the transfer rules assume every joint moves freely, and {names}: use --solver vp "
                    "(certified) instead")
        return None

    def solve(self, mechanism: Mechanism, *, progress: Progress | None = None, keep: tuple[str, ...] = (),
              eliminate_first: tuple[str, ...] = (), certify: bool = True, digits: int | None = None,
              samples: int | None = None, seed: int = SEED) -> BaseParameterResult:
        """Symbolic base parameters and their derivation; the options as declared in
        ``options`` (checked by :func:`baseparams.solvers.run.run_solver`). ``progress`` is
        accepted and not used (the solver has no long phase worth reporting)."""
        trajectory = Trajectory.default(mechanism, samples=samples) if samples else None
        return solve(mechanism, keep=keep, eliminate_first=eliminate_first, certify_rank=certify,
                     digits=digits or CERTIFY_DIGITS, seed=seed, trajectory=trajectory)
