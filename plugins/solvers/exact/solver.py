"""The ``exact`` solver: W over the rationals at random rational states of an open chain,
its exact rank and rref (:mod:`baseparams.plugins.solvers.exact.states`)."""

import math
import time

from .states import exact_observation_matrix, rref_base
from baseparams.numeric.backends import Exact
from baseparams.errors import InputError
from baseparams.model.expressions import exact_text
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.protocol import MAX_SAMPLES, MAX_SEED, Capabilities, Progress, SolverOption
from baseparams.solvers.result import BaseParameterResult, Diagnostics
from baseparams.solvers.support import (base_rows, check_memory, exact_coefficients, say, seconds_text,
                                        size_text)

SEED = 2024               # seed of the random rational states
EXACT_ROUNDS = 6           # independent batches before the rank is declared unsettled


BYTES_PER_ENTRY = 64        # + PER_BODY_BYTES x bodies: rationals grow with the chain's depth
PER_BODY_BYTES = 32         # (measured: pendulum ~100 B, 6-body chain ~250 B an entry)
SECONDS_PER_STATE = 7e-5    # x bodies^2 (measured: pendulum 0.07 ms, 6-body chain 2.8 ms a state)


def exact_cost(mechanism: Mechanism, states: int) -> tuple[float, float]:
    """(bytes, seconds) that W over the rationals at ``states`` states should take: printed
    up front, and the bytes checked against BASEPARAMS_MAX_MEMORY before any is spent."""
    f = max(1, len(mechanism.independent or mechanism.coordinates))
    bodies = max(1, len(mechanism.bodies))
    entries = states * f * len(mechanism.parameters)
    return entries * (BYTES_PER_ENTRY + PER_BODY_BYTES * bodies), states * SECONDS_PER_STATE * bodies ** 2


class ExactSolver:
    """Exact rank and beta over the rationals (open chains with rational geometry)."""

    name = "exact"
    description = ("exact rational arithmetic (fmpq) at random rational states: exact rank and "
                   "beta by rref; open chains with rational geometry only")
    capabilities = Capabilities(needs_rational_geometry=True, certifies=True, exact_coefficients=True)
    options: tuple[SolverOption, ...] = (
        SolverOption("samples", int, None, "random rational states of the first batch (default: "
                     "enough for 1.5 rows per parameter)", minimum=1, maximum=MAX_SAMPLES),
        SolverOption("seed", int, SEED, "seed of the random rational states", minimum=0, maximum=MAX_SEED),
    )

    def applicable(self, mechanism: Mechanism) -> str | None:
        """An open chain whose kinematics stays rational at rational states: refused for a
        closed loop (algebraic dependent coordinates) or irrational geometry, found by
        evaluating one random state."""
        try:
            exact_observation_matrix(mechanism, 1, seed=0)
        except InputError as exc:
            return exc.reason
        return None

    def solve(self, mechanism: Mechanism, *, progress: Progress | None = None, samples: int | None = None,
              seed: int = SEED) -> BaseParameterResult:
        """Exact rank and beta; the options as declared in ``options`` (checked by
        :func:`baseparams.solvers.run.run_solver`)."""
        start = time.perf_counter()
        warnings: list[str] = []
        params = mechanism.parameters
        f = max(1, len(mechanism.independent or mechanism.coordinates))
        n = len(params)
        count = samples or max(4, math.ceil(1.5 * n / f))
        per_batch = max(2, math.ceil(n / f))          # each check batch: at least n rows
        need, seconds = exact_cost(mechanism, count + per_batch)
        check_memory(need, f"exact: W over the rationals at {count:,} states ({count * f:,} x {n})",
                     "use fewer samples (--samples or -O samples)", file=mechanism.path)
        say(progress, f"exact: W at {count} random rational states ({count * f:,} x {n}): about "
                      f"{size_text(need)} of memory and {seconds_text(seconds)}")
        W = exact_observation_matrix(mechanism, count, seed=seed)
        first = rank = W.rank()
        batches, settled = 0, False
        while batches < EXACT_ROUNDS:                # an independent batch must not raise the rank
            batches += 1
            W = Exact().stack(W, exact_observation_matrix(mechanism, per_batch, seed=seed + 1000 * batches))
            new = W.rank()
            if new == rank:
                settled = True
                break
            rank = new
        if rank > first:
            warnings.append(f"the {count} random states do not excite {mechanism.name}: rank raised from "
                            f"{first} to {rank} by independent random batches ({per_batch} states each)")
        if not settled:
            warnings.append(f"the rank still rose with the last of {EXACT_ROUNDS} independent random "
                            f"batches: {rank} is only a lower bound, not certified")
        rank, kept, eliminated, beta = rref_base(W)
        base = base_rows(params, kept, eliminated,
                         lambda a, b: exact_text(beta[a][b]) if beta[a][b] != 0 else None)
        summary = [f"W over the rationals: {W.nrows()} x {W.ncols()} at random rational states "
                   f"(angles at rational points of the unit circle): {count} states, then {batches} "
                   f"independent check batches of {per_batch}",
                   (f"exact rank {rank}; the last batch did not raise it" if settled else
                    f"exact rank {rank} at these states; it still rose with the last batch (not certified)"),
                   "beta from the exact rref: kept parameters are the leftmost basis"]
        diagnostics = Diagnostics(
            summary=summary,
            certificate=("exact rank of W at random rational states: the number of base parameters "
                         "unless every sample lies on one algebraic hypersurface (probability zero); "
                         "an extra independent batch (at least as many rows as parameters) did not "
                         "raise it"),
            details={"rows": W.nrows(), "batches": batches, "states_per_batch": per_batch,
                     "rank_first_states": first, "settled": settled, "seed": seed})
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=rank, base=base,
            eliminated=[params[j] for j in eliminated], certified=settled, digits=None, singular_values=None,
            geometry=mechanism.geometry_text, warnings=warnings, elapsed_s=time.perf_counter() - start,
            diagnostics=diagnostics, coefficients=exact_coefficients(base))
