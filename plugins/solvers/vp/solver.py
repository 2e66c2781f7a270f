"""The ``vp`` solver: Gautier's method in python-flint ball arithmetic
(:mod:`baseparams.numeric.certify`), the precision raised along a ladder until two
precisions agree, checked against independent random batches, and exact rationals
recovered from the balls and confirmed at twice the digits (from the final analysis'
square block: W evaluated again only at the states its rows come from)."""

import copy
import functools
import itertools
import math
import sys
import time
from collections.abc import Sequence
from fractions import Fraction
from typing import Any, cast

from flint import arb, arb_mat

try:
    import resource
except ImportError:        # not on Windows: peak memory is then not reported
    resource = None  # type: ignore[assignment]

from baseparams.dynamics.excitation import RandomBatch, random_batch
from baseparams.dynamics.observation import Subset, observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError, KinematicsError
from baseparams.model.expressions import exact_text
from baseparams.numeric import certify, decide
from baseparams.numeric.backends import Arb, BallRows, Float64
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.protocol import (MAX_DIGITS, MAX_SAMPLES, MAX_SEED, Capabilities, Progress, SolverOption,
                                         last_parameter_index)
from baseparams.solvers.result import BaseParameterResult, Diagnostics
from baseparams.dynamics.trajectory import memory_limit
from baseparams.solvers.support import (base_rows, check_memory, decimal_coefficients, raised_warning, say,
                                        size_text, untrusted_warning)

from . import balls

RIDGE_DECADES = 3          # a proven ridge of at least 3 decades (s_{r+1} <= 1e-3 s_r)
MIN_DIGITS = 10            # coefficients must agree to 10 digits between two precisions
LADDER = (30, 60, 120, 240, 500)
CHECK_SEED = 7919          # seed of the first independent excitation batch (then +1, +2)
CHECK_ROUNDS = 2           # independent batches that may be added to W before giving up
ROWS_PER_PARAMETER = 4     # default W when the file's trajectory gives more than MAX_ROWS_PER_PARAMETER
LARGE_ROWS_PER_PARAMETER = 3  # the same beyond certify.FAST_DECISIONS_ABOVE parameters
MAX_ROWS_PER_PARAMETER = 6
MIN_SAMPLES = 10
KEPT_RIDGE_DECADES = 1     # imposed kept columns with less than this ridge after them do not span W
MIN_WORKING_DIGITS = 10    # fewer digits cannot give the 10 agreeing digits (MIN_DIGITS) asked for
ROWS_PER_RANK = 1.5        # beyond certify.FAST_DECISIONS_ABOVE parameters: rows per estimated rank (issue 47;
                           # 2 before: TIAGo, Talos and 16 of 17 others keep rank, basis, expressions, certificate;
                           # icub keeps rank 212 certified, its complete-pivoting basis another one)


BALL_ENTRY_BYTES = 400      # + the digits: one entry of W in balls, with the analysis' share
                           # (measured: chains of 20 and 40 bodies at 30 and 60 digits, 5-15 % above)


def ball_bytes(rows: int, cols: int, steps: Sequence[int]) -> float:
    """Memory of W in balls at each precision of ``steps`` (every run's W is kept until the
    result: the last two are compared): checked against BASEPARAMS_MAX_MEMORY up front."""
    return rows * cols * sum(BALL_ENTRY_BYTES + d for d in steps)


def default_samples(mechanism: Mechanism) -> int | None:
    """Samples of the file's trajectory for W: the file's, unless they give more than 6 rows
    per parameter; then 4 rows per parameter, 3 beyond certify.FAST_DECISIONS_ABOVE
    parameters (the rank is at most the number of parameters: either leaves a wide
    margin; random chains of 24 bodies keep their rank and ridge down to 2). More rows
    only cost time (W and the analysis grow as rows x parameters^2), most on large
    mechanisms; an excitation too poor for the rank is caught by the independent random
    batch, which then joins W."""
    if mechanism.trajectory is None:
        return None
    f = max(1, len(mechanism.independent))
    samples, params = mechanism.trajectory.samples, len(mechanism.parameters)
    if samples * f <= MAX_ROWS_PER_PARAMETER * params:
        return samples
    per = LARGE_ROWS_PER_PARAMETER if params > certify.FAST_DECISIONS_ABOVE else ROWS_PER_PARAMETER
    return max(MIN_SAMPLES, math.ceil(per * params / f))


def samples_from_rank(mechanism: Mechanism, samples: int) -> tuple[int, int] | None:
    """Beyond certify.FAST_DECISIONS_ABOVE parameters, fewer samples than the default
    ``samples`` when the rank is far below the parameters (a robot's W: Talos 232 of 440):
    (samples giving ROWS_PER_RANK rows per rank, the rank) estimated in float64
    (:func:`baseparams.numeric.decide.rank_estimate`), kept only when that many samples
    still show the same rank; else None. W and the analysis grow with the rows, and the
    certificate does not depend on their number: the rank is proven on the W built, and a
    W too short for the mechanism's rank fails the independent random batch, which then
    joins W."""
    if len(mechanism.parameters) <= certify.FAST_DECISIONS_ABOVE:
        return None
    f = _width(mechanism)
    try:
        W = observation_matrix(mechanism, Float64(), Trajectory.default(mechanism, samples=samples, memory=False))[0]
        rank = decide.rank_estimate(W)
        fewer = max(MIN_SAMPLES, math.ceil(ROWS_PER_RANK * rank / f))
        if not rank or fewer >= samples:          # no estimate (W not finite in float64), or no saving
            return None
        W = observation_matrix(mechanism, Float64(), Trajectory.default(mechanism, samples=fewer, memory=False))[0]
    except KinematicsError:          # the solve itself reports it, with where
        return None
    return (fewer, rank) if decide.rank_estimate(W) == rank else None


def _width(mechanism: Mechanism) -> int:
    return max(1, len(mechanism.independent) or len(mechanism.coordinates))


def samples_in_budget(mechanism: Mechanism, steps: Sequence[int]) -> int | None:
    """The most samples whose W in balls at ``steps`` fits the memory limit, when that still
    gives as many rows per parameter as :func:`default_samples` asks of a long trajectory
    (4, or 3 beyond certify.FAST_DECISIONS_ABOVE parameters) and MIN_SAMPLES samples; else
    None (the default samples are then refused with the estimate). Fewer rows are safe for
    the certificate: the rank is proven on whatever W is built, and a W too short for the
    mechanism's rank fails the independent random batch, which then joins W."""
    f, params = _width(mechanism), len(mechanism.parameters)
    per = LARGE_ROWS_PER_PARAMETER if params > certify.FAST_DECISIONS_ABOVE else ROWS_PER_PARAMETER
    per_sample = ball_bytes(f, params, steps)
    fitted = int(memory_limit() // per_sample) if per_sample else None
    if fitted is None or fitted < MIN_SAMPLES or fitted * f < per * params:
        return None
    return fitted


def _digits_of(beta: arb_mat) -> tuple[list[list[float]], float]:
    """(per entry of beta, rows of lists: the digits its ball proves (radius_digits); the least
    of them over the balls that exclude 0, inf when none does)."""
    cols = beta.ncols()
    values = beta.entries()
    zero = list(map(arb.contains, values, itertools.repeat(0)))      # most of beta: read in C
    exact = list(map(arb.is_exact, values))                          # radius 0, read in C too
    # radius_digits of a ball that contains 0 without the call: inf when it is exact, else 0
    digits = [(math.inf if e else 0) if z else balls.radius_digits(x) for x, z, e in zip(values, zero, exact)]
    least = min((d for d, z in zip(digits, zero) if not z), default=math.inf)
    return [digits[i * cols:(i + 1) * cols] for i in range(beta.nrows())], least


def peak_memory_mb() -> float | None:
    """The process's peak resident memory so far (MB), or None where unknown."""
    if resource is None:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / 2 ** 20 if sys.platform == "darwin" else peak / 2 ** 10, 1)


class BallRun:
    """One precision: W at D digits and its certified analysis."""

    def __init__(self, mechanism: Mechanism, digits: int, trajectory: Trajectory,
                 kept: Sequence[int] | None = None, pivoting: str = "natural", progress: Progress | None = None,
                 batches: Sequence[RandomBatch] = (), earlier: certify.BallAnalysis | None = None,
                 spectrum: bool = True):

        self.digits = digits
        start = time.perf_counter()
        backend = Arb(digits)
        total = len(trajectory.times)
        marks = {max(1, round(total * k / 4)) for k in (1, 2, 3)}

        def tick(done: int, count: int) -> None:
            if done in marks:
                say(progress, f"vp: {digits} digits: sample {done}/{count}")

        W, info = observation_matrix(mechanism, backend, trajectory, progress=tick, entries=True)
        self.W: BallRows = W
        self.info: dict[str, Any] = info
        if batches:             # independent random states added after a failed excitation check
            extra = [observation_matrix(mechanism, backend, cast(Any, b), entries=True)[0] for b in batches]
            self.W = BallRows.stack(self.W, *extra)
        self.info["random_states"] = sum(b.states for b in batches)
        self.analysis = certify.analyse(self.W, digits, kept=kept, pivoting=pivoting, earlier=earlier,
                                        approximate_spectrum=spectrum)
        self.seconds = time.perf_counter() - start
        self.digits_of, self._least = _digits_of(self.analysis.beta)
        self.agreement: tuple[Any, dict[int, float]] | None = None     # (the other analysis, compare_runs')

    def reanalyse(self, kept: Sequence[int], earlier: certify.BallAnalysis | None = None) -> "BallRun | None":
        """This run's W analysed with imposed kept columns (a copy), or None if they are not
        proven independent at this precision. ``earlier``: an analysis that kept them (its
        rows are tried first)."""
        other = copy.copy(self)
        other.__dict__.pop("tail_values", None)
        try:
            other.analysis = certify.analyse(self.W, self.digits, kept=kept, earlier=earlier)
        except ValueError:
            return None
        other.digits_of, other._least = _digits_of(other.analysis.beta)
        other.agreement = None
        return other

    @functools.cached_property
    def tail_values(self) -> list[str]:
        """Approximate singular values after the ridge (only the final run's are reported)."""
        return balls.tail_singular_values(self.W, self.analysis)

    @property
    def rank(self) -> int:
        return self.analysis.rank

    def min_digits(self) -> float:
        """The fewest digits a ball of beta that excludes 0 proves."""
        return self._least

    def summary(self) -> dict[str, Any]:
        a = self.analysis
        return {"digits": self.digits, "rank": a.rank, "pivoting": a.pivoting,
                "ridge_decades": _finite(a.ridge_log10), "sigma_r_lower": a.sigma_r_lower.str(4, radius=False),
                "tail_bound": a.tail_bound.str(4, radius=False), "min_beta_digits": _finite(self.min_digits()),
                "closure_residual": self.info.get("closure_residual"), "seconds": round(self.seconds, 3)}


def _beta_from_rows(mechanism: Mechanism, digits: int, trajectory: Trajectory, batches: Sequence[RandomBatch],
                    a: certify.BallAnalysis) -> arb_mat:
    """beta at ``digits`` from the square block of the analysis ``a``: W evaluated only at
    the states its rows R come from, then ``W_RK beta = W_RE`` solved in ball arithmetic
    (:func:`baseparams.plugins.solvers.vp.balls.block_beta`). For W of rank r every nonsingular
    r x r block gives the same beta, so these balls enclose the beta that the whole W at
    ``digits`` would give; the rank itself was proven at the final precision."""
    f = max(1, len(mechanism.independent) or len(mechanism.coordinates))
    sources: list[Any] = [trajectory, *batches]
    starts = [0]
    for source in sources:
        starts.append(starts[-1] + source.count * f)
    wanted: list[set[int]] = [set() for _ in sources]
    located = []
    for row in a.rows:
        k = next(k for k in range(len(sources)) if row < starts[k + 1])
        state, within = divmod(row - starts[k], f)
        wanted[k].add(state)
        located.append((k, state, within))
    backend = Arb(digits)
    blocks: list[Any] = []
    position: dict[tuple[int, int], int] = {}
    for k, source in enumerate(sources):
        picked = sorted(wanted[k])
        if not picked:
            continue
        for i, state in enumerate(picked):
            position[k, state] = sum(b.nrows() for b in blocks) // f + i
        subset: Any = Subset(source, tuple(picked))
        blocks.append(observation_matrix(mechanism, backend, subset)[0])
    W = backend.stack(*blocks) if blocks else backend.matrix([], len(mechanism.parameters))
    rows = [position[k, state] * f + within for k, state, within in located]
    return balls.block_beta(W, digits, a.kept, rows, a.exponents)


def _finite(x: Any) -> Any:
    if x == math.inf:
        return "inf"
    if x == -math.inf:
        return "-inf"
    return round(x, 2) if isinstance(x, float) else x


def _vp_check_line(check: dict[str, Any]) -> str:
    if "error" in check:
        return f"the random states could not be evaluated ({check['error']})"
    verdict = ("obey the base parameters" if check["passed"] else
               f"do NOT obey the base parameters ({check['proven_nonzero']} entries of W_batch N proven "
               f"nonzero)" if check["proven_nonzero"] else "do not keep the ridge")
    return (f"{check['states']} independent random states ({check['rows']} rows) at {check['digits']} digits "
            f"{verdict}: a ridge of {check['ridge_decades_with_batch']} decades on W and the batch together")


def compare_runs(prev: BallRun, cur: BallRun) -> tuple[bool, float, list[str]]:
    """Agreement between two precisions: (ok, minimum agreement digits, reasons)."""
    reasons = []
    a, b = prev.analysis, cur.analysis
    if a.rank != b.rank:
        reasons.append(f"rank {a.rank} at {prev.digits} digits, {b.rank} at {cur.digits}")
        return False, 0, reasons
    if a.kept != b.kept:
        reasons.append(f"the kept parameters differ between {prev.digits} and {cur.digits} digits")
        return False, 0, reasons
    worst = math.inf
    theirs, mine = a.beta.entries(), b.beta.entries()
    both = []                          # entries whose balls exclude 0 at both precisions
    for k, (x, y) in enumerate(zip(theirs, mine)):
        x0, y0 = x.contains(0), y.contains(0)
        if x0 and y0:
            continue
        if not x.overlaps(y):
            reasons.append(f"a coefficient's balls at {prev.digits} and {cur.digits} digits do not overlap")
            return False, 0, reasons
        if x0 != y0:
            worst = 0
            continue
        both.append(k)
    found = balls.agreements(theirs, mine, both)
    cur.agreement = (a, found)        # kept for the printed digits (_vp_coefficients): the same pairs
    worst = min([worst, *found.values()])
    if worst < MIN_DIGITS:
        reasons.append(f"coefficients agree to only {worst} digits between {prev.digits} and "
                       f"{cur.digits} digits (need {MIN_DIGITS})")
    if b.ridge_log10 < RIDGE_DECADES:
        reasons.append(f"the proven ridge at {cur.digits} digits is {_finite(b.ridge_log10)} decades "
                       f"(need {RIDGE_DECADES})")
    if not (b.ridge_log10 > a.ridge_log10 or b.ridge_log10 == math.inf):
        reasons.append("the bound after the ridge did not shrink with more digits")
    return not reasons, worst, reasons


def _vp_coefficients(final: BallRun, prev: BallRun | None,
                     params: Sequence[str]) -> tuple[list[dict[str, Any]], list[int], list[dict[str, Any]]]:
    """Base rows with each coefficient printed to the digits trusted: its ball's own, capped
    by the agreement with the previous precision. Returns (rows, trusted digits of the
    printed ones, untrusted): a nonzero coefficient with no trusted digit is left out of
    its expression and listed in ``untrusted`` with its ball."""
    a = final.analysis
    same = prev is not None and prev.analysis.kept == a.kept and prev.rank == a.rank
    cols = a.beta.ncols()
    mine, theirs = a.beta.entries(), prev.analysis.beta.entries() if same and prev is not None else None
    digits = [d for row in final.digits_of for d in row]
    live = [k for k, x in enumerate(mine) if not x.contains(0)]      # printed, or listed untrusted
    # the agreement caps the digits of a ball that has some; the pairs compare_runs found reused
    cached = getattr(final, "agreement", None)
    known = cached[1] if cached is not None and prev is not None and cached[0] is prev.analysis else {}
    agree = ({**known, **balls.agreements(theirs, mine, (k for k in live if digits[k] > 0 and k not in known))}
             if theirs is not None else {})
    texts: dict[tuple[int, int], str] = {}
    printed: list[int] = []
    untrusted: list[dict[str, Any]] = []
    for k in live:                     # row by row, as the expressions are written
        i, j = divmod(k, cols)
        trusted = int(max(0, min(digits[k], agree.get(k, math.inf), final.digits)))
        if trusted < 1:
            untrusted.append({"base": i, "parameter": params[a.eliminated[j]], "ball": mine[k].str(5)})
            continue
        texts[i, j] = certify.decimal_string(mine[k], trusted)
        printed.append(trusted)
    rows = base_rows(params, a.kept, a.eliminated, lambda i, j: texts.get((i, j)))
    for item in untrusted:
        item["base"] = rows[item["base"]]["name"]
    return rows, printed, untrusted


def _vp_samples(mechanism: Mechanism, samples: int | None, first: Sequence[int], notes: list[str],
                progress: Progress | None) -> tuple[int | None, str | None]:
    """The samples of W: the option's, or the default lowered to the rows the rank estimate
    needs and to what fits the memory limit (each lowering noted): (samples, budget note)."""
    budget_note: str | None = None
    chosen = samples or default_samples(mechanism)
    fewer = samples_from_rank(mechanism, chosen) if not samples and chosen else None
    if fewer is not None:
        notes.append(f"{fewer[0]} samples ({fewer[0] * _width(mechanism):,} rows, {ROWS_PER_RANK} per rank "
                     f"{fewer[1]} estimated in float64) instead of the default {chosen}")
        say(progress, "vp: " + notes[-1])
        chosen = fewer[0]
    if not samples and chosen:
        params = mechanism.parameters
        fitted = samples_in_budget(mechanism, first)
        if fitted is not None and fitted < chosen:
            notes.append(f"{chosen} samples (the default) would need about "
                         f"{size_text(ball_bytes(chosen * _width(mechanism), len(params), first))} in balls, above "
                         f"the memory limit of {size_text(memory_limit())}: {fitted} samples "
                         f"({fitted * _width(mechanism):,} rows for {len(params)} parameters) chosen to fit")
            say(progress, "vp: " + notes[-1])
            budget_note, chosen = notes[-1], fitted
    return chosen, budget_note


def _vp_trajectory(mechanism: Mechanism, samples: int | None, first: Sequence[int], steps: Sequence[int],
                   progress: Progress | None) -> Trajectory:
    """The trajectory of W, once W in balls at the first two precisions is known to fit in memory."""
    trajectory = Trajectory.default(mechanism, samples=samples)
    rows, cols = len(trajectory.times) * _width(mechanism), len(mechanism.parameters)
    check_memory(ball_bytes(rows, cols, first), f"vp: W ({rows:,} x {cols}) in balls at "
                 f"{', '.join(map(str, first))} digits", "use fewer samples (--samples or -O samples), "
                 "or fix the precision (--digits)", file=mechanism.path)
    say(progress, f"vp: W is {rows:,} x {cols}: about {size_text(ball_bytes(rows, cols, first))} of memory "
                  f"at {', '.join(map(str, first))} digits"
                  + (f", up to {size_text(ball_bytes(rows, cols, steps))} if the ladder climbs to "
                     f"{steps[-1]}" if len(steps) > 2 else ""))
    return trajectory


def _vp_summary(runs: list[BallRun], prev: BallRun | None, accepted: bool, agreement: float | None,
                check: dict[str, Any], printed: list[int], budget_note: str | None,
                recovery: dict[str, Any]) -> list[str]:
    """The summary lines: W, the proven rank and ridge, the agreement, the check, the digits."""
    final = runs[-1]
    a = final.analysis
    extra = final.info["random_states"]
    summary = [
        f"W: {final.W.nrows()} x {final.W.ncols()} ({final.info['samples']} samples"
        + (f" + {extra} random states" if extra else "") + ") at "
        f"{', '.join(str(r.digits) for r in runs)} digits; columns scaled by powers of two",
        f"rank >= {a.rank} proven (a {a.rank} x {a.rank} block of W is nonsingular in ball arithmetic); "
        f"s_{a.rank} >= {a.sigma_r_lower.str(3, radius=False)}, every later singular value <= "
        f"{a.tail_bound.str(3, radius=False)}: a ridge of {_finite(a.ridge_log10)} decades",
        (f"agreement with {prev.digits} digits: rank, kept parameters and beta to >= {agreement} digits"
         if prev is not None and accepted else "not confirmed at a second precision"),
        "excitation check: " + _vp_check_line(check),
        (f"coefficients printed with {min(printed)} to {max(printed)} trusted digits "
         f"(kept parameters: {a.pivoting} order)" if printed else
         f"no coefficient of beta printed (kept parameters: {a.pivoting} order)"),
    ]
    if budget_note:
        summary.append(budget_note)
    if recovery.get("attempted"):
        summary.append("exact rationals: " + (
            f"recovered and confirmed inside the balls at {recovery['confirmed_at_digits']} digits "
            f"(largest denominator {recovery['largest_denominator']})" if recovery["succeeded"]
            else f"not recovered ({recovery['reason']})"))
    return summary


class VariablePrecisionSolver:
    """Gautier's method in python-flint ball arithmetic, precision escalated automatically."""

    name = "vp"
    description = ("Gautier's method in ball arithmetic (python-flint): proven rank, precision "
                   "raised until the ridge is evident and beta agrees at two precisions")
    capabilities = Capabilities(closed_loops=True, certifies=True)
    options: tuple[SolverOption, ...] = (
        SolverOption("digits", int, None, "fix the working precision (default: raised along the "
                     "ladder until two precisions agree)", minimum=MIN_WORKING_DIGITS, maximum=MAX_DIGITS),
        SolverOption("samples", int, None, "samples of the exciting trajectory (default: the "
                     "mechanism file's)", minimum=2, maximum=MAX_SAMPLES),
        SolverOption("ladder", tuple, LADDER, "precisions tried in turn without digits (increasing)",
                     item=int, minimum=MIN_WORKING_DIGITS, maximum=MAX_DIGITS, length=(1, 12), increasing=True),
        SolverOption("pivoting", str, "natural", "the kept parameters: the leftmost independent "
                     "columns (natural) or complete pivoting's", choices=("natural", "complete")),
        SolverOption("recover", bool, True, "recover exact rationals from the balls and confirm "
                     "them at twice the digits"),
        SolverOption("kept", tuple, None, "impose the kept columns, as indices into the parameters "
                     "(default: chosen by the pivoting)", item=int, minimum=0, maximum=last_parameter_index,
                     maximum_text="the last parameter's index", length=(1, 10 ** 6), unique=True),
        SolverOption("seed", int, CHECK_SEED, "seed of the first independent random batch", minimum=0,
                     maximum=MAX_SEED),
    )

    def applicable(self, mechanism: Mechanism) -> str | None:
        """Any mechanism: ball arithmetic evaluates square roots and closed loops alike."""
        return None

    def solve(self, mechanism: Mechanism, *, progress: Progress | None = None, digits: int | None = None,
              samples: int | None = None, ladder: tuple[int, ...] = LADDER, pivoting: str = "natural",
              recover: bool = True, kept: tuple[int, ...] | None = None,
              seed: int = CHECK_SEED) -> BaseParameterResult:
        """Certified base parameters; the options as declared in ``options`` (checked by
        :func:`baseparams.solvers.run.run_solver`)."""
        start = time.perf_counter()
        params = mechanism.parameters
        warnings: list[str] = []
        notes: list[str] = []
        steps = [int(digits)] if digits else [int(d) for d in ladder]
        first = steps[:2]          # the least the ladder needs: two precisions that agree
        chosen, budget_note = _vp_samples(mechanism, samples, first, notes, progress)
        trajectory = _vp_trajectory(mechanism, chosen, first, steps, progress)
        runs, accepted, agreement, reasons, checks, batches = self._checked_runs(
            mechanism, trajectory, steps, kept, pivoting, seed, progress)
        final = runs[-1]
        a = final.analysis
        if kept is not None and a.ridge_log10 < KEPT_RIDGE_DECADES:
            # too few imposed columns: the rest of W is not a combination of them, so the
            # rank printed would be the number of columns imposed, not W's (a wrong answer)
            raise InputError(f"solver {self.name!r}: option 'kept': the {len(kept)} imposed columns do not "
                             f"span W at {final.digits} digits (after them a singular value up to "
                             f"{a.tail_bound.str(3, radius=False)} remains, s_r >= "
                             f"{a.sigma_r_lower.str(3, radius=False)}): impose as many independent columns "
                             f"as W's rank")
        prev = runs[-2] if len(runs) >= 2 else None
        excited = checks[-1]["passed"]
        if batches:
            before = checks[0]["rank"]
            warnings.append(raised_warning(mechanism, before, a.rank, sum(b.states for b in batches))
                            if a.rank > before else
                            f"an independent random batch did not fit the base parameters of the "
                            f"trajectory's W (rank {before}): W and the batch analysed together")
        if not excited:
            warnings.append("excitation check failed: " + _vp_check_line(checks[-1])
                            + "; the rank is not certified")

        base, printed, untrusted = _vp_coefficients(final, prev, params)
        ridge_ok = a.ridge_log10 >= RIDGE_DECADES
        if digits:
            certified = ridge_ok and excited
            if not ridge_ok:
                warnings.append(f"no evident ridge at {final.digits} digits: proven ridge "
                                f"{_finite(a.ridge_log10)} decades < {RIDGE_DECADES}; raise --digits")
            notes.append("--digits fixes the precision: not confirmed at a second precision")
        else:
            certified = accepted and excited
            if not accepted:
                warnings.append("no agreement between two precisions up to "
                                f"{final.digits} digits: " + "; ".join(reasons))
        if untrusted:
            warnings.append(untrusted_warning(untrusted))
        warnings += [n for n in a.notes if "lowered" in n]

        recovery: dict[str, Any] = {"attempted": False}
        if recover:
            recovery = self._recover(mechanism, final, trajectory, batches, params, progress)

        summary = _vp_summary(runs, prev, accepted, agreement, checks[-1], printed, budget_note, recovery)
        details = {
            "runs": [r.summary() for r in runs],
            "pivoting": a.pivoting,
            "agreement_digits": _finite(agreement) if agreement is not None else None,
            "excitation_checks": checks,
            "random_states_in_W": final.info["random_states"],
            "trusted_digits": {"min": min(printed, default=None), "max": max(printed, default=None)},
            "untrusted": untrusted,
            "column_scaling": "each column divided by the power of two nearest its norm (exact)",
            "singular_values_note": (f"the first {a.rank}: sqrt of approximate eigenvalues of the scaled "
                                     f"Gram matrix; the rest: singular values of the residual "
                                     f"W_E - W_K beta, which bound them (Weyl)"),
            "zero_columns": [params[j] for j in a.zero_columns],
            "rational_recovery": recovery,
            "notes": notes + a.notes,
            "peak_memory_mb": peak_memory_mb(),
        }
        diagnostics = Diagnostics(
            summary=summary, details=details,
            certificate=("rank >= r: an r x r block of the column-scaled W proven nonsingular; "
                         "s_(r+1) <= tail_bound (Weyl); s_r >= sigma_r_lower (interlacing); "
                         "certified when the ridge is >= 3 decades, rank, kept parameters and "
                         "beta (>= 10 digits) agree at two precisions, and an independent random "
                         "batch keeps a ridge of >= 3 decades with no entry of W_batch N proven nonzero"),
            ridge_decades=float(a.ridge_log10),
            sigma_r_lower=a.sigma_r_lower.str(6, radius=False),
            tail_bound=a.tail_bound.str(6, radius=False))
        rationals = ([{p: Fraction(t) for p, t in row["expression"].items()} for row in recovery["base"]]
                     if recovery.get("succeeded") else None)
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=a.rank, base=base,
            eliminated=[params[j] for j in a.eliminated], certified=bool(certified), digits=final.digits,
            singular_values=a.singular_values[:a.rank] + final.tail_values, geometry=mechanism.geometry_text,
            warnings=warnings, elapsed_s=time.perf_counter() - start, diagnostics=diagnostics,
            coefficients=decimal_coefficients(base, rationals))

    def _checked_runs(self, mechanism: Mechanism, trajectory: Trajectory, steps: Sequence[int],
                      kept: Sequence[int] | None, pivoting: str, seed: int, progress: Progress | None
                      ) -> tuple[list[BallRun], bool, float | None, list[str], list[dict[str, Any]], list[RandomBatch]]:
        """The ladder (:meth:`_escalate`), then the excitation check; a failed check adds its
        random batch to W and climbs again, up to CHECK_ROUNDS times: (runs, accepted,
        agreement, reasons, checks, batches added)."""
        batches: list[RandomBatch] = []
        checks: list[dict[str, Any]] = []
        for round_ in range(CHECK_ROUNDS + 1):
            try:
                runs, accepted, agreement, reasons = self._escalate(mechanism, trajectory, batches, steps,
                                                                    kept, pivoting, progress)
            except ValueError as exc:
                if kept is None:
                    raise
                raise InputError(f"solver {self.name!r}: option 'kept': {exc}: impose columns that are "
                                 f"independent in W (or leave kept to the pivoting)") from None
            check, batch = self._excitation_check(mechanism, trajectory, runs[-1], seed + round_, progress)
            checks.append(check)
            if check["passed"] or "error" in check or round_ == CHECK_ROUNDS:
                break
            say(progress, f"vp: the excitation check failed (rank {check['rank']}): W and the batch "
                           f"analysed together")
            batches.append(batch)
        return runs, accepted, agreement, reasons, checks, batches

    @staticmethod
    def _escalate(mechanism: Mechanism, trajectory: Trajectory, batches: Sequence[RandomBatch], steps: Sequence[int],
                  kept: Sequence[int] | None, pivoting: str,
                  progress: Progress | None) -> tuple[list[BallRun], bool, float | None, list[str]]:
        """W at each precision of ``steps`` until two consecutive ones agree:
        (runs, accepted, agreement digits, reasons)."""
        runs: list[BallRun] = []
        accepted, agreement = False, None
        reasons: list[str] = []
        rows = len(trajectory.times) * max(1, len(mechanism.independent) or len(mechanism.coordinates))
        rows += sum(b.states for b in batches) * max(1, len(mechanism.independent) or len(mechanism.coordinates))
        for k, D in enumerate(steps):
            need = ball_bytes(rows, len(mechanism.parameters), steps[:k + 1])
            if k >= 2 and need > memory_limit():
                reasons = reasons + [f"the next precision ({D} digits) would need about {size_text(need)}, above "
                                     f"the memory limit {size_text(memory_limit())} (BASEPARAMS_MAX_MEMORY)"]
                break
            say(progress, f"vp: W at {D} digits ({len(trajectory.times)} samples"
                           + (f" + {sum(b.states for b in batches)} random states" if batches else "") + ")")
            # the first of two or more precisions is never the final run, whose approximate
            # spectrum alone is reported: the first's is not computed (an SVD or an eig at D digits)
            run = BallRun(mechanism, D, trajectory, kept=kept, pivoting=pivoting, progress=progress,
                          batches=batches, earlier=runs[-1].analysis if runs else None,
                          spectrum=k > 0 or len(steps) == 1)
            runs.append(run)
            a = run.analysis
            say(progress, f"vp: {D} digits: rank {a.rank} ({a.pivoting} order), proven ridge "
                           f"{_finite(a.ridge_log10)} decades (s_r >= {a.sigma_r_lower.str(3, radius=False)}, "
                           f"s_r+1 <= {a.tail_bound.str(3, radius=False)}), beta to >= "
                           f"{_finite(run.min_digits())} digits; {run.seconds:.1f} s")
            if len(runs) >= 2:
                prev = runs[-2]
                if prev.rank == run.rank and prev.analysis.kept != run.analysis.kept:
                    # same rank, other basis choice: the previous W with this run's kept columns
                    redone = prev.reanalyse(run.analysis.kept, run.analysis)
                    if redone is not None:
                        runs[-2] = prev = redone
                accepted, agreement, reasons = compare_runs(prev, run)
                if accepted:
                    break
                say(progress, "vp: not yet: " + "; ".join(reasons))
        return runs, accepted, agreement, reasons

    @staticmethod
    def _excitation_check(mechanism: Mechanism, trajectory: Trajectory, final: BallRun, seed: int,
                          progress: Progress | None) -> tuple[dict[str, Any], RandomBatch]:
        """An independent random batch at the final precision against the null space of the
        final analysis (:func:`baseparams.plugins.solvers.vp.balls.excitation_check`): (diagnostics, batch)."""
        a = final.analysis
        batch = random_batch(mechanism, trajectory, seed)
        say(progress, f"vp: excitation check: {batch.states} random states at {final.digits} digits")
        out = {"seed": seed, "states": batch.states, "digits": final.digits, "rank": a.rank}
        backend = Arb(final.digits)
        try:
            Wc = observation_matrix(mechanism, backend, cast(Any, batch), entries=True)[0]
        except KinematicsError as exc:
            return {**out, "passed": False, "error": str(exc)}, batch
        bound, nonzero, decades = balls.excitation_check(Wc, a)
        bound_text = bound.str(3, radius=False)
        passed = nonzero == 0 and decades >= RIDGE_DECADES
        return {**out, "rows": Wc.nrows(), "residual_bound": bound_text, "proven_nonzero": nonzero,
                "ridge_decades_with_batch": _finite(decades), "passed": passed}, batch

    def _recover(self, mechanism: Mechanism, final: BallRun, trajectory: Trajectory, batches: Sequence[RandomBatch],
                 params: Sequence[str], progress: Progress | None) -> dict[str, Any]:
        """Exact rationals for beta from the digits its balls prove, then confirmed: each
        must lie inside its ball at twice the digits (:func:`_beta_from_rows`)."""
        a = final.analysis
        values = {}
        for i in range(a.beta.nrows()):
            for j in range(a.beta.ncols()):
                x = a.beta[i, j]
                if x.contains(0):
                    continue
                digits = min(final.digits_of[i][j], final.digits)
                if digits < 8:
                    return {"attempted": True, "succeeded": False,
                            "reason": f"a coefficient has only {digits} proven digits"}
                q = balls.recover_rational(x, int(digits))
                if q is None:
                    return {"attempted": True, "succeeded": False,
                            "reason": f"no rational with a denominator below 10^{max(1, (digits - 2) // 2)} "
                                      f"matches {params[a.kept[i]]}'s coefficient of {params[a.eliminated[j]]}"}
                values[i, j] = q
        D2 = 2 * final.digits
        say(progress, f"vp: confirming {len(values)} recovered rationals at {D2} digits")
        try:
            b = _beta_from_rows(mechanism, D2, trajectory, batches, a)
        except (ValueError, KinematicsError) as exc:     # the result stands; only the recovery fails
            return {"attempted": True, "succeeded": False, "reason": str(exc)}
        return self._confirm(values, b, final, D2, a, params)      # exact containment: no precision

    @staticmethod
    def _confirm(values: dict[tuple[int, int], Fraction], b: arb_mat, final: BallRun, D2: int,
                 a: certify.BallAnalysis, params: Sequence[str]) -> dict[str, Any]:
        for i in range(b.nrows()):
            for j in range(b.ncols()):
                q = values.get((i, j))
                if q is None and not b[i, j].contains(0):
                    return {"attempted": True, "succeeded": False,
                            "reason": f"a coefficient zero at {final.digits} digits is not zero at {D2}"}
                if q is not None and not balls.contains_rational(b[i, j], q):
                    return {"attempted": True, "succeeded": False,
                            "reason": f"{q} is outside the ball at {D2} digits"}
        rows = base_rows(params, a.kept, a.eliminated,
                         lambda i, j: exact_text(values[i, j]) if (i, j) in values else None)
        return {"attempted": True, "succeeded": True, "confirmed_at_digits": D2,
                "largest_denominator": max((q.denominator for q in values.values()), default=1),
                "base": rows}
