"""Built-in solvers: Gautier's method in double precision (``dp``), in certified ball
arithmetic with automatic precision (``vp``), and in exact rational arithmetic (``exact``).

Registered through the ``baseparams_solvers`` hook (entry point ``builtin_solvers``),
exactly as a third party's solver would be. Each returns a
:class:`baseparams.result.BaseParameterResult`; ``diagnostics["summary"]`` holds the
lines a reader needs to judge the result (the CLI prints them under the table).
docs/solvers.md explains the algorithms and what "certified" covers.
"""

import math
import time

from baseparams.errors import KinematicsError
from baseparams.excitation import batch_matrix, random_batch, stack_rows
from baseparams.expressions import exact_text
from baseparams.hookspecs import hookimpl
from baseparams.result import BaseParameterResult

RIDGE_DECADES = 3          # vp: a proven ridge of at least 3 decades (s_{r+1} <= 1e-3 s_r)
MIN_DIGITS = 10            # vp: coefficients must agree to 10 digits between two precisions
LADDER = (30, 60, 120, 240, 500)
CHECK_SEED = 7919          # dp, vp: seed of the first independent excitation batch (then +1, +2)
CHECK_ROUNDS = 2           # vp: independent batches that may be added to W before giving up
EXACT_ROUNDS = 6           # exact: independent batches before the rank is declared unsettled


# ----- shared ---------------------------------------------------------------------
def base_rows(parameters, kept, eliminated, coefficient):
    """[{"name": "phi_b01", "expression": {kept: "1", eliminated: coeff, ...}}] in kept order.

    ``coefficient(a, b)``: the string for row a (kept[a]) and column b (eliminated[b]), or
    None for a zero coefficient.
    """
    rows = []
    width = max(2, len(str(len(kept))))
    for a, i in enumerate(kept):
        expression = {parameters[i]: "1"}
        for b, j in enumerate(eliminated):
            text = coefficient(a, b)
            if text is not None:
                expression[parameters[j]] = text
        rows.append({"name": f"phi_b{a + 1:0{width}d}", "expression": expression})
    return rows


def _say(progress, message):
    if progress:
        progress(message)


def _trajectory(mechanism, samples):
    from baseparams.trajectory import Trajectory
    return Trajectory.default(mechanism, samples=samples)


def _g(x, digits=3):
    return f"{x:.{digits}g}"


def untrusted_warning(items):
    return (f"{len(items)} nonzero coefficients have no trusted digit: omitted from the base "
            f"parameter expressions and listed in diagnostics.untrusted")


def raised_warning(mechanism, before, after, states, double_precision=False):
    cause = (f"the trajectory does not excite {mechanism.name}, or double precision lost a small "
             f"singular value of W" if double_precision else f"the trajectory does not excite {mechanism.name}")
    return (f"{cause}: rank raised from {before} to {after} by an independent random batch ({states} "
            f"random positions, velocities and accelerations), analysed together with W; use more "
            f"samples or a richer trajectory" + (", or vp" if double_precision else ""))


# ----- dp -------------------------------------------------------------------------
class DoublePrecisionSolver:
    """Gautier's SVD method in numpy float64 (the seed paper's DP)."""

    name = "dp"
    description = ("Gautier's SVD method in double precision (numpy): rank by tolerance, "
                   "with ridge diagnostics and warnings")

    def solve(self, mechanism, samples=None, scale=True, rank=None, progress=None, seed=CHECK_SEED,
              **options):
        from flint import arb
        from baseparams.backends import Float64
        from baseparams.certify import decimal_string
        from baseparams.gautier import EPS, dp_gautier
        from baseparams.trajectory import observation_matrix

        start = time.perf_counter()
        warnings = []
        if options.get("digits"):
            warnings.append("dp ignores --digits: it always works in double precision")
        trajectory = _trajectory(mechanism, samples)
        W, info = observation_matrix(mechanism, Float64(), trajectory)
        _say(progress, f"dp: W is {W.shape[0]} x {W.shape[1]} ({info['samples']} samples); SVD")
        res = dp_gautier(W, scale=scale, rank=rank)
        check, stacked, both = self._excitation_check(mechanism, trajectory, W, res, scale, rank, seed)
        if check.get("raised"):
            warnings.append(raised_warning(mechanism, res.rank, both.rank, check["states"], double_precision=True))
            W, res = stacked, both
        elif check.get("error"):
            warnings.append(f"no excitation check: {check['error']}")
        elif check.get("rank_with_batch", res.rank) < res.rank:
            # more rows can only raise the true rank: a lower count means the tolerance cut is
            # fragile (singular values near it move with the row count)
            warnings.append(f"the rank cut is fragile: W with an independent random batch of "
                            f"{check['states']} states gives rank {check['rank_with_batch']} at the same "
                            f"tolerance rule, not {res.rank}")
        warnings += res.warnings
        params = mechanism.parameters
        noise = max(res.error_estimate, EPS)      # absolute error of beta_s (scaled units)
        most = int(min(16, math.floor(-math.log10(noise))))
        dropped, largest_dropped, untrusted = 0, 0.0, []

        def coefficient(a, b):
            nonlocal dropped, largest_dropped
            value, scaled = float(res.beta[a, b]), abs(float(res.beta_s[a, b]))
            if value == 0.0:
                return None
            if scaled <= noise:
                dropped += 1
                largest_dropped = max(largest_dropped, scaled)
                return None
            digits = min(most, math.floor(math.log10(scaled / noise)))
            if digits < 1:
                untrusted.append({"base": a, "parameter": params[res.eliminated[b]], "value": repr(value),
                                  "estimated_error": repr(noise / scaled * abs(value))})
                return None
            return decimal_string(arb(value), digits)

        base = base_rows(params, res.kept, res.eliminated, coefficient)
        for item in untrusted:
            item["base"] = base[item["base"]]["name"]
        if untrusted:
            warnings.append(untrusted_warning(untrusted))
        s = res.singular_values
        r = res.rank
        gap_ratio = float(res.ratios.max()) if res.ratios.size else None
        summary = [
            f"W: {W.shape[0]} x {W.shape[1]} ({info['samples']} samples"
            + (f" + {check['states']} random states" if check.get("raised") else "") + "); columns "
            + ("scaled by powers of two near their norms" if scale else "not scaled"),
            f"rank {r} by the tolerance max(shape)*eps*s_max = {_g(res.tolerance)}",
            (f"s_{r} = {_g(s[r - 1])}, s_{r + 1} = {_g(s[r]) if r < len(s) else '-'}; largest gap "
             f"s_{res.largest_gap}/s_{res.largest_gap + 1} = {_g(gap_ratio) if gap_ratio else '-'}; "
             + ("clear ridge at the cut" if res.clear_ridge else "NO clear ridge at the cut")) if r else "rank 0",
            f"beta: estimated error {_g(res.error_estimate, 2)} (first order, scaled units), cond(V22) = "
            f"{_g(res.v22_condition)}; coefficients printed with the digits above it; {dropped} below it "
            f"(largest {_g(largest_dropped, 2)}) are not shown",
            _dp_check_line(check),
        ]
        if res.zero_columns:
            summary.append(f"{len(res.zero_columns)} columns are (numerically) zero: "
                           + " ".join(params[j] for j in res.zero_columns))
        diagnostics = {
            "column_scaling": ("each column divided by the power of two nearest its Euclidean norm "
                               "(exact in binary); beta scaled back") if scale else "none",
            "numerically_zero_columns": [params[j] for j in res.zero_columns],
            "rank_rule": "number of singular values above max(shape) * eps * s_max (scaled W)",
            "tolerance": float(res.tolerance),
            "ridge": {"clear": bool(res.clear_ridge), "criterion":
                      f"largest ratio s_i/s_(i+1) among values above the tolerance (the value below the "
                      f"cut floored at eps*s_max) is >= {1e3:g} and falls at the tolerance cut",
                      "largest_gap_after": int(res.largest_gap), "largest_ratio": gap_ratio,
                      "ratio_at_cut": float(res.ratios[r - 1]) if 0 < r <= res.ratios.size else None},
            "permutation": "QR with column pivoting on V2^T chooses the eliminated parameters",
            "beta_error_estimate": float(res.error_estimate),
            "v22_condition": float(res.v22_condition),
            "coefficients_below_noise_dropped": dropped,
            "largest_dropped_scaled": largest_dropped,
            "untrusted": untrusted,
            "excitation_check": check,
            "samples": info["samples"], "rows": int(W.shape[0]),
            "summary": summary,
        }
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=r, base=base,
            eliminated=[params[j] for j in res.eliminated], certified=False, digits=None,
            singular_values=[repr(float(v)) for v in s], geometry=mechanism.geometry_text,
            warnings=warnings, elapsed_s=time.perf_counter() - start, diagnostics=diagnostics)

    @staticmethod
    def _excitation_check(mechanism, trajectory, W, res, scale, rank, seed):
        """dp on W stacked with an independent random batch: (diagnostics, stacked W, its DPResult)."""
        import numpy as np
        from baseparams.backends import Float64
        from baseparams.gautier import dp_gautier
        if rank is not None:
            return {"skipped": "rank forced"}, None, None
        batch = random_batch(mechanism, trajectory, seed)
        try:
            rows = batch_matrix(mechanism, Float64(), trajectory, batch)
        except KinematicsError as exc:
            return {"seed": seed, "states": batch.states, "error": str(exc)}, None, None
        stacked = np.vstack([W, rows])
        both = dp_gautier(stacked, scale=scale)
        return ({"seed": seed, "states": batch.states, "rows": int(rows.shape[0]), "rank": res.rank,
                 "rank_with_batch": both.rank, "raised": both.rank > res.rank}, stacked, both)


def _dp_check_line(check):
    if check.get("skipped") or check.get("error"):
        return f"excitation check: not done ({check.get('skipped') or check.get('error')})"
    if check["raised"]:
        return (f"excitation check: {check['states']} independent random states raised the rank from "
                f"{check['rank']} to {check['rank_with_batch']}: W above includes them")
    return (f"excitation check: {check['states']} independent random states ({check['rows']} rows) "
            f"added to W give rank {check['rank_with_batch']}")


# ----- vp -------------------------------------------------------------------------
class BallRun:
    """One precision: W at D digits and its certified analysis."""

    def __init__(self, mechanism, digits, trajectory, kept=None, pivoting="natural", progress=None,
                 batches=()):
        from baseparams import certify
        from baseparams.backends import Arb
        from baseparams.trajectory import observation_matrix

        self.digits = digits
        start = time.perf_counter()
        backend = Arb(digits)
        total = len(trajectory.times)
        marks = {max(1, round(total * k / 4)) for k in (1, 2, 3)}

        def tick(done, count):
            if done in marks:
                _say(progress, f"vp: {digits} digits: sample {done}/{count}")

        self.W, self.info = observation_matrix(mechanism, backend, trajectory, progress=tick)
        if batches:             # independent random states added after a failed excitation check
            self.W = stack_rows(self.W, *(batch_matrix(mechanism, backend, trajectory, b) for b in batches))
        self.info["random_states"] = sum(b.states for b in batches)
        with backend.activate():
            self.analysis = certify.analyse(self.W, digits, kept=kept, pivoting=pivoting)
            self.tail_values = certify.tail_singular_values(self.W, self.analysis)
        self.seconds = time.perf_counter() - start
        a = self.analysis
        self.digits_of = [[certify.radius_digits(a.beta[i, j]) for j in range(a.beta.ncols())]
                          for i in range(a.beta.nrows())]

    def reanalyse(self, kept):
        """This run's W analysed with imposed kept columns (a copy), or None if they are not
        proven independent at this precision."""
        import copy
        from baseparams import certify
        from baseparams.backends import Arb
        other = copy.copy(self)
        with Arb(self.digits).activate():
            try:
                other.analysis = certify.analyse(self.W, self.digits, kept=kept)
            except ValueError:
                return None
            other.tail_values = certify.tail_singular_values(self.W, other.analysis)
        a = other.analysis
        other.digits_of = [[certify.radius_digits(a.beta[i, j]) for j in range(a.beta.ncols())]
                           for i in range(a.beta.nrows())]
        return other

    @property
    def rank(self):
        return self.analysis.rank

    def min_digits(self):
        a = self.analysis
        values = [d for i, row in enumerate(self.digits_of) for j, d in enumerate(row)
                  if not a.beta[i, j].contains(0)]
        return min(values, default=math.inf)

    def summary(self):
        a = self.analysis
        return {"digits": self.digits, "rank": a.rank, "pivoting": a.pivoting,
                "ridge_decades": _finite(a.ridge_log10), "sigma_r_lower": a.sigma_r_lower.str(4, radius=False),
                "tail_bound": a.tail_bound.str(4, radius=False), "min_beta_digits": _finite(self.min_digits()),
                "closure_residual": self.info.get("closure_residual"), "seconds": round(self.seconds, 3)}


def _finite(x):
    if x == math.inf:
        return "inf"
    if x == -math.inf:
        return "-inf"
    return round(x, 2) if isinstance(x, float) else x


def _vp_check_line(check):
    if "error" in check:
        return f"the random states could not be evaluated ({check['error']})"
    verdict = ("obey the base parameters" if check["passed"] else
               f"do NOT obey the base parameters ({check['proven_nonzero']} entries of W_batch N proven "
               f"nonzero)" if check["proven_nonzero"] else "do not keep the ridge")
    return (f"{check['states']} independent random states ({check['rows']} rows) at {check['digits']} digits "
            f"{verdict}: a ridge of {check['ridge_decades_with_batch']} decades on W and the batch together")


def compare_runs(prev, cur):
    """Agreement between two precisions: (ok, minimum agreement digits, reasons)."""
    from baseparams import certify
    reasons = []
    a, b = prev.analysis, cur.analysis
    if a.rank != b.rank:
        reasons.append(f"rank {a.rank} at {prev.digits} digits, {b.rank} at {cur.digits}")
        return False, 0, reasons
    if a.kept != b.kept:
        reasons.append(f"the kept parameters differ between {prev.digits} and {cur.digits} digits")
        return False, 0, reasons
    worst = math.inf
    for i in range(b.beta.nrows()):
        for j in range(b.beta.ncols()):
            x, y = a.beta[i, j], b.beta[i, j]
            if x.contains(0) and y.contains(0):
                continue
            if not x.overlaps(y):
                reasons.append(f"a coefficient's balls at {prev.digits} and {cur.digits} digits do not overlap")
                return False, 0, reasons
            if x.contains(0) != y.contains(0):
                worst = 0
                continue
            worst = min(worst, certify.agreement_digits(x, y))
    if worst < MIN_DIGITS:
        reasons.append(f"coefficients agree to only {worst} digits between {prev.digits} and "
                       f"{cur.digits} digits (need {MIN_DIGITS})")
    if b.ridge_log10 < RIDGE_DECADES:
        reasons.append(f"the proven ridge at {cur.digits} digits is {_finite(b.ridge_log10)} decades "
                       f"(need {RIDGE_DECADES})")
    if not (b.ridge_log10 > a.ridge_log10 or b.ridge_log10 == math.inf):
        reasons.append("the bound after the ridge did not shrink with more digits")
    return not reasons, worst, reasons


def _vp_coefficients(final, prev, params):
    """Base rows with each coefficient printed to the digits trusted: its ball's own, capped
    by the agreement with the previous precision. Returns (rows, trusted digits of the
    printed ones, untrusted): a nonzero coefficient with no trusted digit is left out of
    its expression and listed in ``untrusted`` with its ball."""
    from baseparams import certify
    a = final.analysis
    same = prev is not None and prev.analysis.kept == a.kept and prev.rank == a.rank
    trusted, untrusted = {}, []
    for i in range(a.beta.nrows()):
        for j in range(a.beta.ncols()):
            d = final.digits_of[i][j]
            if same:
                d = min(d, certify.agreement_digits(prev.analysis.beta[i, j], a.beta[i, j]))
            trusted[i, j] = max(0, min(d, final.digits))

    def coefficient(i, j):
        x = a.beta[i, j]
        if x.contains(0):
            return None
        if trusted[i, j] < 1:
            untrusted.append({"base": i, "parameter": params[a.eliminated[j]], "ball": x.str(5)})
            return None
        return certify.decimal_string(x, trusted[i, j])

    rows = base_rows(params, a.kept, a.eliminated, coefficient)
    for item in untrusted:
        item["base"] = rows[item["base"]]["name"]
    printed = [trusted[i, j] for i in range(a.beta.nrows()) for j in range(a.beta.ncols())
               if not a.beta[i, j].contains(0) and trusted[i, j] >= 1]
    return rows, printed, untrusted


class VariablePrecisionSolver:
    """Gautier's method in python-flint ball arithmetic, precision escalated automatically."""

    name = "vp"
    description = ("Gautier's method in ball arithmetic (python-flint): proven rank, precision "
                   "raised until the ridge is evident and beta agrees at two precisions")

    def solve(self, mechanism, digits=None, samples=None, progress=None, ladder=LADDER,
              pivoting="natural", recover=True, kept=None, seed=CHECK_SEED, **options):
        start = time.perf_counter()
        trajectory = _trajectory(mechanism, samples)
        params = mechanism.parameters
        warnings, notes = [], []
        steps = [int(digits)] if digits else [int(d) for d in ladder]
        batches, checks = [], []
        for round_ in range(CHECK_ROUNDS + 1):
            runs, accepted, agreement, reasons = self._escalate(mechanism, trajectory, batches, steps,
                                                                kept, pivoting, progress)
            check, batch = self._excitation_check(mechanism, trajectory, runs[-1], seed + round_, progress)
            checks.append(check)
            if check["passed"] or "error" in check or round_ == CHECK_ROUNDS:
                break
            _say(progress, f"vp: the excitation check failed (rank {check['rank']}): W and the batch "
                           f"analysed together")
            batches.append(batch)
        final = runs[-1]
        a = final.analysis
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

        from baseparams.backends import Arb
        with Arb(final.digits).activate():
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

        recovery = {"attempted": False}
        if recover:
            recovery = self._recover(mechanism, final, trajectory, batches, params, progress)

        sv = a.singular_values[:a.rank] + final.tail_values
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
            "excitation check: " + _vp_check_line(checks[-1]),
            (f"coefficients printed with {min(printed)} to {max(printed)} trusted digits "
             f"(kept parameters: {a.pivoting} order)" if printed else
             f"no coefficient of beta printed (kept parameters: {a.pivoting} order)"),
        ]
        if recovery.get("attempted"):
            summary.append("exact rationals: " + (
                f"recovered and confirmed inside the balls at {recovery['confirmed_at_digits']} digits "
                f"(largest denominator {recovery['largest_denominator']})" if recovery["succeeded"]
                else f"not recovered ({recovery['reason']})"))
        diagnostics = {
            "certificate": ("rank >= r: an r x r block of the column-scaled W proven nonsingular; "
                            "s_(r+1) <= tail_bound (Weyl); s_r >= sigma_r_lower (interlacing); "
                            "certified when the ridge is >= 3 decades, rank, kept parameters and "
                            "beta (>= 10 digits) agree at two precisions, and an independent random "
                            "batch keeps a ridge of >= 3 decades with no entry of W_batch N proven nonzero"),
            "runs": [r.summary() for r in runs],
            "pivoting": a.pivoting,
            "ridge_decades": _finite(a.ridge_log10),
            "sigma_r_lower": a.sigma_r_lower.str(6, radius=False),
            "tail_bound": a.tail_bound.str(6, radius=False),
            "agreement_digits": _finite(agreement) if agreement is not None else None,
            "excitation_checks": checks,
            "random_states_in_W": extra,
            "trusted_digits": {"min": min(printed, default=None), "max": max(printed, default=None)},
            "untrusted": untrusted,
            "column_scaling": "each column divided by the power of two nearest its norm (exact)",
            "singular_values_note": (f"the first {a.rank}: sqrt of approximate eigenvalues of the scaled "
                                     f"Gram matrix; the rest: singular values of the residual "
                                     f"W_E - W_K beta, which bound them (Weyl)"),
            "zero_columns": [params[j] for j in a.zero_columns],
            "rational_recovery": recovery,
            "notes": notes + a.notes,
            "summary": summary,
        }
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=a.rank, base=base,
            eliminated=[params[j] for j in a.eliminated], certified=bool(certified), digits=final.digits,
            singular_values=sv, geometry=mechanism.geometry_text, warnings=warnings,
            elapsed_s=time.perf_counter() - start, diagnostics=diagnostics)

    @staticmethod
    def _escalate(mechanism, trajectory, batches, steps, kept, pivoting, progress):
        """W at each precision of ``steps`` until two consecutive ones agree:
        (runs, accepted, agreement digits, reasons)."""
        runs, accepted, agreement, reasons = [], False, None, []
        for D in steps:
            _say(progress, f"vp: W at {D} digits ({len(trajectory.times)} samples"
                           + (f" + {sum(b.states for b in batches)} random states" if batches else "") + ")")
            run = BallRun(mechanism, D, trajectory, kept=kept, pivoting=pivoting, progress=progress,
                          batches=batches)
            runs.append(run)
            a = run.analysis
            _say(progress, f"vp: {D} digits: rank {a.rank} ({a.pivoting} order), proven ridge "
                           f"{_finite(a.ridge_log10)} decades (s_r >= {a.sigma_r_lower.str(3, radius=False)}, "
                           f"s_r+1 <= {a.tail_bound.str(3, radius=False)}), beta to >= "
                           f"{_finite(run.min_digits())} digits; {run.seconds:.1f} s")
            if len(runs) >= 2:
                prev = runs[-2]
                if prev.rank == run.rank and prev.analysis.kept != run.analysis.kept:
                    # same rank, other basis choice: the previous W with this run's kept columns
                    redone = prev.reanalyse(run.analysis.kept)
                    if redone is not None:
                        runs[-2] = prev = redone
                accepted, agreement, reasons = compare_runs(prev, run)
                if accepted:
                    break
                _say(progress, "vp: not yet: " + "; ".join(reasons))
        return runs, accepted, agreement, reasons

    @staticmethod
    def _excitation_check(mechanism, trajectory, final, seed, progress):
        """An independent random batch at the final precision against the null space of the
        final analysis (:func:`baseparams.certify.excitation_check`): (diagnostics, batch)."""
        from baseparams import certify
        from baseparams.backends import Arb
        a = final.analysis
        batch = random_batch(mechanism, trajectory, seed)
        _say(progress, f"vp: excitation check: {batch.states} random states at {final.digits} digits")
        out = {"seed": seed, "states": batch.states, "digits": final.digits, "rank": a.rank}
        backend = Arb(final.digits)
        try:
            Wc = batch_matrix(mechanism, backend, trajectory, batch)
        except KinematicsError as exc:
            return {**out, "passed": False, "error": str(exc)}, batch
        with backend.activate():
            bound, nonzero, decades = certify.excitation_check(Wc, a)
            bound = bound.str(3, radius=False)
        passed = nonzero == 0 and decades >= RIDGE_DECADES
        return {**out, "rows": Wc.nrows(), "residual_bound": bound, "proven_nonzero": nonzero,
                "ridge_decades_with_batch": _finite(decades), "passed": passed}, batch

    def _recover(self, mechanism, final, trajectory, batches, params, progress):
        """Exact rationals for beta from the digits its balls prove, then confirmed: each
        must lie inside its ball at twice the digits."""
        from baseparams import certify
        from baseparams.backends import Arb
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
                q = certify.recover_rational(x, digits)
                if q is None:
                    return {"attempted": True, "succeeded": False,
                            "reason": f"no rational with a denominator below 10^{max(1, (digits - 2) // 2)} "
                                      f"matches {params[a.kept[i]]}'s coefficient of {params[a.eliminated[j]]}"}
                values[i, j] = q
        D2 = 2 * final.digits
        _say(progress, f"vp: confirming {len(values)} recovered rationals at {D2} digits")
        try:
            check = BallRun(mechanism, D2, trajectory, kept=a.kept, progress=progress, batches=batches)
        except (ValueError, KinematicsError) as exc:     # the result stands; only the recovery fails
            return {"attempted": True, "succeeded": False, "reason": str(exc)}
        b = check.analysis.beta
        with Arb(D2).activate():            # the rationals as balls at least as tight as b's
            return self._confirm(values, b, final, D2, a, params)

    @staticmethod
    def _confirm(values, b, final, D2, a, params):
        from baseparams import certify
        for i in range(b.nrows()):
            for j in range(b.ncols()):
                q = values.get((i, j))
                if q is None and not b[i, j].contains(0):
                    return {"attempted": True, "succeeded": False,
                            "reason": f"a coefficient zero at {final.digits} digits is not zero at {D2}"}
                if q is not None and not certify.contains_rational(b[i, j], q):
                    return {"attempted": True, "succeeded": False,
                            "reason": f"{q} is outside the ball at {D2} digits"}
        rows = base_rows(params, a.kept, a.eliminated,
                         lambda i, j: exact_text(values[i, j]) if (i, j) in values else None)
        return {"attempted": True, "succeeded": True, "confirmed_at_digits": D2,
                "largest_denominator": max((q.denominator for q in values.values()), default=1),
                "base": rows}


# ----- exact ----------------------------------------------------------------------
class ExactSolver:
    """Exact rank and beta over the rationals (open chains with rational geometry)."""

    name = "exact"
    description = ("exact rational arithmetic (fmpq) at random rational states: exact rank and "
                   "beta by rref; open chains with rational geometry only")

    def solve(self, mechanism, samples=None, seed=2024, progress=None, **options):
        from baseparams.exact_samples import check_exact_possible, exact_observation_matrix, rref_base

        start = time.perf_counter()
        warnings = []
        if options.get("digits"):
            warnings.append("exact ignores --digits: its arithmetic is exact (rationals)")
        check_exact_possible(mechanism)
        params = mechanism.parameters
        f = max(1, len(mechanism.independent or mechanism.coordinates))
        n = len(params)
        count = samples or max(4, math.ceil(1.5 * n / f))
        per_batch = max(2, math.ceil(n / f))          # each check batch: at least n rows
        _say(progress, f"exact: W at {count} random rational states")
        W = exact_observation_matrix(mechanism, count, seed=seed)
        first = rank = W.rank()
        batches, settled = 0, False
        while batches < EXACT_ROUNDS:                # an independent batch must not raise the rank
            batches += 1
            W = stack_rows(W, exact_observation_matrix(mechanism, per_batch, seed=seed + 1000 * batches))
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
        diagnostics = {
            "rank_meaning": ("exact rank of W at random rational states: the number of base parameters "
                             "unless every sample lies on one algebraic hypersurface (probability zero); "
                             "an extra independent batch (at least as many rows as parameters) did not "
                             "raise it"),
            "rows": W.nrows(), "batches": batches, "states_per_batch": per_batch,
            "rank_first_states": first, "settled": settled, "seed": seed, "summary": summary,
        }
        return BaseParameterResult(
            mechanism=mechanism.name, solver=self.name, parameters=list(params), rank=rank, base=base,
            eliminated=[params[j] for j in eliminated], certified=settled, digits=None, singular_values=None,
            geometry=mechanism.geometry_text, warnings=warnings, elapsed_s=time.perf_counter() - start,
            diagnostics=diagnostics)


@hookimpl
def baseparams_solvers():
    return [DoublePrecisionSolver(), VariablePrecisionSolver(), ExactSolver()]
