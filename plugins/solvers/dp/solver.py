"""The ``dp`` solver: Gautier's SVD method in double precision (:mod:`.gautier`), checked
against an independent random batch, every coefficient printed with the digits its
first-order error estimate trusts."""

import math
import time
from typing import Any, cast

import numpy as np
from flint import arb

from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import (Trajectory, check_sample_count, float64_bytes, memory_limit,
                                            samples_per_block)
from baseparams.errors import InputError, KinematicsError
from baseparams.numeric.backends import Float64
from baseparams.numeric.certify import decimal_string
from baseparams.numeric.linalg import triangular_factor
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.protocol import (MAX_SAMPLES, MAX_SEED, Capabilities, Progress, SolverOption,
                                         parameter_count)
from baseparams.solvers.result import BaseParameterResult, Diagnostics
from baseparams.solvers.support import base_rows, decimal_coefficients, raised_warning, say

from .gautier import EPS, DPResult, check_finite, dp_gautier

CHECK_SEED = 7919          # seed of the independent excitation batch
MAX_DIGITS = 17            # significant digits that tell float64 values apart


def _g(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


class DoublePrecisionSolver:
    """Gautier's SVD method in numpy float64 (the seed paper's DP)."""

    name = "dp"
    description = ("Gautier's SVD method in double precision (numpy): rank by tolerance, "
                   "with ridge diagnostics and warnings")
    capabilities = Capabilities(closed_loops=True)
    options: tuple[SolverOption, ...] = (
        SolverOption("samples", int, None, "samples of the exciting trajectory (default: the "
                     "mechanism file's)", minimum=2, maximum=MAX_SAMPLES),
        SolverOption("scale", bool, True, "scale W's columns by powers of two near their norms"),
        SolverOption("rank", int, None, "impose the rank (default: the tolerance rule; imposed, "
                     "the excitation check is skipped)", minimum=1, maximum=parameter_count,
                     maximum_text="the number of parameters"),
        SolverOption("seed", int, CHECK_SEED, "seed of the independent random batch", minimum=0, maximum=MAX_SEED),
        SolverOption("pivoting", str, "natural", "the kept parameters: the leftmost independent columns "
                     "(natural, as vp, exact and symbolic) or QR column pivoting's", choices=("natural", "qr")),
    )

    def applicable(self, mechanism: Mechanism) -> str | None:
        """Any mechanism: the SVD needs nothing of the geometry."""
        return None

    def solve(self, mechanism: Mechanism, *, progress: Progress | None = None, samples: int | None = None,
              scale: bool = True, rank: int | None = None, seed: int = CHECK_SEED,
              pivoting: str = "natural") -> BaseParameterResult:
        """The base parameters in float64; the options as declared in ``options`` (checked
        by :func:`baseparams.solvers.run.run_solver`)."""
        start = time.perf_counter()
        warnings: list[str] = []
        trajectory = Trajectory.default(mechanism, samples=samples, memory=False)
        W, rows, info = observation(mechanism, trajectory, progress)
        shape = (rows, W.shape[1])
        say(progress, f"dp: W is {rows} x {W.shape[1]} ({info['samples']} samples"
            + (f", in {_blocks_text(info['blocks'])}" if info.get("blocks") else "") + "); SVD")
        if rank is not None and rank > min(shape):
            # W's row count depends on the samples: known only now (the option's declared
            # maximum, the parameter count, was checked before W was built)
            raise InputError(f"solver {self.name!r}: option 'rank' must be at most {min(shape)} (W is "
                             f"{rows} x {W.shape[1]}: its rank cannot be higher), got {rank}")
        res = dp_gautier(W, scale=scale, rank=rank, columns=mechanism.parameters, rows=rows, pivoting=pivoting)
        check, W, res, rows = self._checked(mechanism, trajectory, W, rows, res, scale, rank, seed, pivoting,
                                            warnings)
        warnings += res.warnings
        params = mechanism.parameters
        rounding = _Rounding(res)
        base = base_rows(params, res.kept, res.eliminated, rounding)
        summary = _dp_summary(res, W, rows, info, check, scale, pivoting, rounding, params)
        details = _dp_details(res, rows, info, check, scale, pivoting, rounding, params)
        diagnostics = Diagnostics(summary=summary, rank_tolerance=float(res.tolerance), details=details)
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=res.rank, base=base,
            eliminated=[params[j] for j in res.eliminated], certified=False, digits=None,
            singular_values=[repr(float(v)) for v in res.singular_values], geometry=mechanism.geometry_text,
            warnings=warnings, elapsed_s=time.perf_counter() - start, diagnostics=diagnostics,
            coefficients=decimal_coefficients(base))

    def _checked(self, mechanism: Mechanism, trajectory: Trajectory, W: np.ndarray, rows: int, res: DPResult,
                 scale: bool, rank: int | None, seed: int, pivoting: str,
                 warnings: list[str]) -> tuple[dict[str, Any], np.ndarray, DPResult, int]:
        """The excitation check, and the W and result to print from: W with the random
        batch when the batch raised the rank or kept it (warnings appended)."""
        check, stacked, both = self._excitation_check(mechanism, trajectory, W, rows, res, scale, rank, seed,
                                                      pivoting)
        if check.get("raised") and stacked is not None and both is not None:
            warnings.append(raised_warning(mechanism, res.rank, both.rank, check["states"], double_precision=True))
            W, res = stacked, both
            rows += int(check["rows"])
        elif stacked is not None and both is not None and both.rank == res.rank:
            # the same rank: beta, its column scaling and its error estimate from W and the
            # random states together, not from one trajectory (one that barely excites a
            # direction shrinks its columns and s_r, and the coefficients printed in its units
            # are then far less accurate on any other data than it estimates: issue 47)
            check["beta_from_both"] = True
            W, res = stacked, both
            rows += int(check["rows"])
        elif check.get("error"):
            warnings.append(f"no excitation check: {check['error']}")
        elif check.get("rank_with_batch", res.rank) < res.rank:
            # more rows can only raise the true rank: a lower count means the tolerance cut is
            # fragile (singular values near it move with the row count)
            warnings.append(f"the rank cut is fragile: W with an independent random batch of "
                            f"{check['states']} states gives rank {check['rank_with_batch']} at the same "
                            f"tolerance rule, not {res.rank}")
        return check, W, res, rows

    @staticmethod
    def _excitation_check(mechanism: Mechanism, trajectory: Trajectory, W: np.ndarray, W_rows: int, res: DPResult,
                          scale: bool, rank: int | None, seed: int,
                          pivoting: str = "natural") -> tuple[dict[str, Any], np.ndarray | None, DPResult | None]:
        """dp on W stacked with an independent random batch: (diagnostics, stacked W, its
        DPResult). W may be the triangular factor of ``W_rows`` rows: then so is the stack."""
        if rank is not None:
            return {"skipped": "rank forced"}, None, None
        batch = random_batch(mechanism, trajectory, seed)
        try:
            rows = cast(np.ndarray, observation_matrix(mechanism, Float64(), cast(Any, batch))[0])
        except KinematicsError as exc:
            return {"seed": seed, "states": batch.states, "error": str(exc)}, None, None
        if W.shape[0] == W_rows:
            stacked = np.vstack([W, rows])
        else:
            stacked = triangular_factor([W, rows], W.shape[1])[0]
        both = dp_gautier(stacked, scale=scale, rows=W_rows + rows.shape[0], pivoting=pivoting)
        return ({"seed": seed, "states": batch.states, "rows": int(rows.shape[0]), "rank": res.rank,
                 "rank_with_batch": both.rank, "raised": both.rank > res.rank}, stacked, both)


def observation(mechanism: Mechanism, trajectory: Trajectory,
                progress: Progress | None = None) -> tuple[np.ndarray, int, dict[str, Any]]:
    """(W or its triangular factor R, W's row count, info). W's R (W itself when it is not
    taller than wide) when its float64 stage fits the memory limit
    (:func:`~baseparams.dynamics.trajectory.float64_bytes`); else W
    is built in row blocks that fit, each folded into R as it comes (``R^T R = W^T W``: the
    same singular values, right singular vectors and column norms, hence the same base
    parameters), so the default samples give an answer instead of a refusal; info then
    says ``blocks`` and ``block_samples``. Refused only when not one sample fits."""
    count = len(trajectory.times)
    if float64_bytes(mechanism, count) <= memory_limit():
        W, info = cast(tuple[np.ndarray, dict[str, Any]], observation_matrix(mechanism, Float64(), trajectory))
        if W.shape[0] <= W.shape[1]:
            return W, int(W.shape[0]), info
        # a tall W: its triangular factor (one QR, which LAPACK's SVD of a tall matrix starts
        # with anyway) is all the analysis needs, without the SVD's rows x columns U; the
        # random batch then joins R, not W (about 2.5x less CPU on a 32-joint humanoid)
        check_finite(W, mechanism.parameters)
        return triangular_factor([W], W.shape[1])[0], int(W.shape[0]), info
    per = samples_per_block(mechanism)
    if per < 1:
        check_sample_count(mechanism, count, None)        # raises, with the estimate and the advice
    pieces = trajectory.pieces(min(per, count))
    say(progress, f"dp: W over {count} samples is above the memory limit as one matrix: built in "
                  f"{_blocks_text(len(pieces))} of at most {min(per, count)} samples, folded into its "
                  f"triangular factor")

    def blocks() -> Any:
        for piece in pieces:
            block = cast(np.ndarray, observation_matrix(mechanism, Float64(), piece)[0])
            check_finite(block, mechanism.parameters)
            yield block

    R, rows = triangular_factor(blocks(), len(mechanism.parameters))
    return R, rows, {"samples": count, "blocks": len(pieces), "block_samples": min(per, count)}


def _blocks_text(count: int) -> str:
    return "1 row block" if count == 1 else f"{count} row blocks"


def _dp_check_line(check: dict[str, Any]) -> str:
    if check.get("skipped") or check.get("error"):
        return f"excitation check: not done ({check.get('skipped') or check.get('error')})"
    if check["raised"]:
        return (f"excitation check: {check['states']} independent random states raised the rank from "
                f"{check['rank']} to {check['rank_with_batch']}: W above includes them")
    return (f"excitation check: {check['states']} independent random states ({check['rows']} rows) "
            f"added to W give rank {check['rank_with_batch']}")

class _Rounding:
    """Each row's printed coefficients share its error: every one rounded (or dropped) to
    within noise / sqrt(nonzero coefficients of the row) in scaled units, so the printed
    row is within the estimate of the computed one, however many coefficients it has
    (rounding each to the estimate itself let hundreds of errors add up: issue 47).
    Counts what it drops."""

    def __init__(self, res: DPResult) -> None:
        self.res = res
        self.noise = max(res.error_estimate, EPS)      # absolute error of beta_s (scaled units)
        self.nonzero = np.count_nonzero(res.beta, axis=1) if res.beta.size else np.zeros(res.rank, dtype=int)
        self.dropped, self.largest_dropped = 0, 0.0

    def __call__(self, a: int, b: int) -> str | None:
        value, scaled = float(self.res.beta[a, b]), abs(float(self.res.beta_s[a, b]))
        if value == 0.0:
            return None
        quantum = self.noise / math.sqrt(max(1, int(self.nonzero[a])))
        if scaled <= quantum / 2:
            self.dropped += 1
            self.largest_dropped = max(self.largest_dropped, scaled)
            return None
        # the digits down to the quantum in the printed value's own units (scaled and
        # unscaled values may sit in different decades: counting them on the scaled
        # value printed a digit more than trusted, 0.59999999999999976 for 3/5)
        unit = quantum * abs(value) / scaled
        digits = min(MAX_DIGITS, max(1, math.floor(math.log10(abs(value))) - math.floor(math.log10(unit)) + 1))
        return decimal_string(arb(value), digits)


def _dp_summary(res: DPResult, W: np.ndarray, rows: int, info: dict[str, Any], check: dict[str, Any],
                scale: bool, pivoting: str, rounding: _Rounding, params: list[str]) -> list[str]:
    """The summary lines: W, the rank rule, the ridge, beta's error and the check."""
    s = res.singular_values
    r = res.rank
    gap_ratio = float(res.ratios.max()) if res.ratios.size else None
    summary = [
        f"W: {rows} x {W.shape[1]} ({info['samples']} samples"
        + (f" + {check['states']} random states" if check.get("raised") else "")
        + (f"; above the memory limit as one matrix: built in {_blocks_text(info['blocks'])} of at most "
           f"{info['block_samples']} samples, folded into W's triangular factor R (R^T R = W^T W)"
           if info.get("blocks") else "") + "); columns "
        + ("scaled by powers of two near their norms" if scale else "not scaled"),
        f"rank {r} by the tolerance max(shape)*eps*s_max = {_g(res.tolerance)}",
        (f"s_{r} = {_g(s[r - 1])}, s_{r + 1} = {_g(s[r]) if r < len(s) else '-'}; largest gap "
         f"s_{res.largest_gap}/s_{res.largest_gap + 1} = {_g(gap_ratio) if gap_ratio else '-'}; "
         + ("clear ridge at the cut" if res.clear_ridge else "NO clear ridge at the cut")) if r else "rank 0",
        f"beta: estimated error {_g(res.error_estimate, 2)} (first order, scaled units), cond(V22) = "
        f"{_g(res.v22_condition)}" + ("; W and the random states together"
                                      if check.get("beta_from_both") else "")
        + f"; each row's coefficients printed down to its share of it (the estimate / sqrt(the row's "
        f"nonzero coefficients)); {rounding.dropped} below half that share (largest "
        f"{_g(rounding.largest_dropped, 2)}) are not shown",
        _dp_check_line(check),
    ]
    natural = "natural order (the leftmost independent columns, as vp and exact)"
    summary.append(res.kept_note or "kept parameters: " + (natural if pivoting == "natural" else "QR column pivoting"))
    if res.zero_columns:
        summary.append(f"{len(res.zero_columns)} columns are (numerically) zero: "
                       + " ".join(params[j] for j in res.zero_columns))
    return summary


def _dp_details(res: DPResult, rows: int, info: dict[str, Any], check: dict[str, Any], scale: bool,
                pivoting: str, rounding: _Rounding, params: list[str]) -> dict[str, Any]:
    """The diagnostics' details (JSON keys of docs/design.md)."""
    r = res.rank
    gap_ratio = float(res.ratios.max()) if res.ratios.size else None
    untrusted: list[dict[str, Any]] = []     # stays empty: every coefficient above q / 2 has a digit
    return {
        "column_scaling": ("each column divided by the power of two nearest its Euclidean norm "
                           "(exact in binary); beta scaled back") if scale else "none",
        "numerically_zero_columns": [params[j] for j in res.zero_columns],
        "pivoting": pivoting if not res.kept_note else "qr",
        "lifted_by_scaling": {"directions": int(res.lifted), "columns": list(res.lifted_columns)},
        "rank_rule": "number of singular values above max(shape) * eps * s_max (scaled W)",
        "ridge": {"clear": bool(res.clear_ridge), "criterion":
                  f"largest ratio s_i/s_(i+1) among values above the tolerance (the value below the "
                  f"cut floored at eps*s_max) is >= {1e3:g} and falls at the tolerance cut",
                  "largest_gap_after": int(res.largest_gap), "largest_ratio": gap_ratio,
                  "ratio_at_cut": float(res.ratios[r - 1]) if 0 < r <= res.ratios.size else None},
        "permutation": "QR with column pivoting on V2^T chooses the eliminated parameters",
        "beta_error_estimate": float(res.error_estimate),
        "v22_condition": float(res.v22_condition),
        "coefficients_below_noise_dropped": rounding.dropped,
        "largest_dropped_scaled": rounding.largest_dropped,
        "untrusted": untrusted,
        "excitation_check": check,
        "samples": info["samples"], "rows": int(rows),
        "row_blocks": ({"blocks": info["blocks"], "samples_per_block": info["block_samples"],
                        "reason": "W over the default samples is above the memory limit: built in row "
                                  "blocks, each compressed into W's triangular factor as it comes"}
                       if info.get("blocks") else None),
    }
