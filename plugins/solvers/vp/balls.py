"""What the ``vp`` solver reads from the balls of the shared analysis
(:func:`baseparams.numeric.certify.analyse`), and nothing else uses: the digits a ball
proves and two balls share, the excitation check against an independent batch, the
approximate singular values after the ridge, beta from one square block (to confirm
recovered rationals at twice the digits), and the rationals themselves.

Every function that computes in ball arithmetic enters its own precision (python-flint's
``ctx.workdps`` / ``ctx.workprec``), so none depends on a precision a caller left set.
"""

import itertools
import math
from collections.abc import Iterable, Sequence
from fractions import Fraction
from typing import Any

import numpy as np
from flint import acb_mat, arb, arb_mat, ctx

from baseparams.numeric.backends import BallMatrix
from baseparams.numeric.certify import (FAST_DECISIONS_ABOVE, FLOAT_BITS, SPECTRUM_IN_ARB_UP_TO, BallAnalysis, block,
                                        frobenius_upper, log10, scaled_entries, solve_block, unscaled)


def block_beta(Wr: arb_mat, digits: int, kept: Sequence[int], rows: Sequence[int],
               exponents: Sequence[int]) -> arb_mat:
    """beta (unscaled, ``arb_mat``) from the square block of the rows ``rows`` of ``Wr``:
    ``Ws_RK beta_s = Ws_RE`` solved in ball arithmetic at ``digits``, columns scaled by
    ``2^exponents`` as in the analysis that chose K and R. For W of rank r = |K| this
    encloses W's beta (every nonsingular r x r block of W_K gives the same one); the rank
    is the analysis' claim. ValueError if the block is not proven nonsingular."""
    with ctx.workdps(digits):
        n = Wr.ncols()
        eliminated = [j for j in range(n) if j not in set(kept)]
        scaled = scaled_entries(Wr.entries(), n, exponents)
        found = solve_block(scaled, n, list(rows), list(kept), eliminated, inverse=False) if kept else None
        if kept and found is None:
            raise ValueError(f"the square block of W is not proven nonsingular at {digits} digits")
        beta_s = found[0] if found is not None else arb_mat(0, len(eliminated))
        return unscaled(beta_s, kept, eliminated, exponents)



def excitation_check(Wc: BallMatrix, a: BallAnalysis) -> tuple[arb, int, float]:
    """An independent batch of rows ``Wc`` (W at other states) against the analysis ``a``
    of W: ``(bound, proven_nonzero, ridge_decades)``.

    - ``bound``: a rigorous upper bound of ``||Wcs_E - Wcs_K B||_F`` (B = ``a.refined``,
      exact; Wcs scaled with W's exponents). As for the tail bound, Weyl gives
      ``s_(r+1)([Ws; Wcs]) <= sqrt(tail_bound^2 + bound^2)``, and adding rows never lowers
      ``s_r``: ``ridge_decades`` is the ridge proven on W and the batch together.
    - ``proven_nonzero``: entries of ``Wcs_E - Wcs_K beta_s`` whose ball excludes 0. Each
      proves ``rank([W; Wc]) > r``: if rank W = r, beta_s encloses W's exact null space and
      the batch leaves it; if rank W > r, r was already only a lower bound.

    A trajectory that does not excite the mechanism gives W a clean ridge at too low a
    rank (all the missing directions are exact zeros of W); only other states show it.
    Computed at the analysis' digits.
    """
    with ctx.workdps(a.digits):
        return _excitation_check(Wc, a)


def _excitation_check(Wc: BallMatrix, a: BallAnalysis) -> tuple[arb, int, float]:
    if not a.eliminated:
        return arb(0), 0, math.inf
    m, n = Wc.nrows(), Wc.ncols()
    scaled = scaled_entries(Wc.entries(), n, a.exponents)
    We = block(scaled, n, range(m), a.eliminated)
    if a.kept:
        Wk = block(scaled, n, range(m), a.kept)
        assert a.refined is not None            # every analysis with kept columns has its B
        residual = We - Wk * a.refined
        bound = frobenius_upper(residual)
        if n > FAST_DECISIONS_ABOVE:
            # E = residual - Wk (beta_s - B): beta_s - B holds beta_s's radii (and B's distance
            # to its midpoint, if any), far below 1, so that product runs at FLOAT_BITS. Why:
            # one product at the analysis' digits instead of two (issue 47: TIAGo 0.53 -> 0.32
            # s); E's radii agree with the direct product's to 1e-8 there.
            with ctx.workprec(FLOAT_BITS):
                spread = Wk * (a.beta_s - a.refined)
            E = residual - spread
        else:
            E = We - Wk * a.beta_s
    else:
        bound, E = frobenius_upper(We), We
    values = E.entries()
    nonzero = len(values) - sum(map(arb.contains, values, itertools.repeat(0)))     # iterated in C
    combined = arb((a.tail_bound ** 2 + bound ** 2).sqrt().upper())
    if a.rank == 0 or not a.sigma_r_lower > 0:
        decades = math.inf if combined == 0 else -math.inf
    elif combined == 0:
        decades = math.inf
    else:
        decades = log10(a.sigma_r_lower) - log10(combined)
    return bound, nonzero, decades


def tail_singular_values(W: BallMatrix, a: BallAnalysis) -> list[str]:
    """Approximate singular values of the residual ``E = Ws_E - Ws_K B`` (B = ``a.refined``),
    largest first: by Weyl's inequality ``s_{r+i}(Ws) <= s_i(E)``, so they bound the
    singular values after the ridge one by one. Exactly zero columns of E give exact zeros.
    Computed at the analysis' digits (E is the analysis' own when W is the matrix analysed)."""
    with ctx.workdps(a.digits):
        return _tail_singular_values(W, a)


def _tail_singular_values(W: BallMatrix, a: BallAnalysis) -> list[str]:
    if not a.eliminated:
        return []
    source, E = a._residual if a._residual is not None else (None, None)
    if source is not W or E is None:
        assert a.refined is not None or not a.kept
        m, n = W.nrows(), W.ncols()
        scaled = scaled_entries(W.entries(), n, a.exponents)
        We = block(scaled, n, range(m), a.eliminated)
        E = (We - block(scaled, n, range(m), a.kept) * a.refined).mid() if a.refined is not None and a.kept \
            else We.mid()
    rows, cols = E.nrows(), E.ncols()
    values = E.entries()
    live = [j for j in range(cols) if any(values[i * cols + j] != 0 for i in range(rows))]
    out: list[Any] = []
    if live and W.ncols() > SPECTRUM_IN_ARB_UP_TO:       # float64, as _approximate_singular_values
        picked = [values[i * cols + j] for i in range(rows) for j in live]
        a64 = np.fromiter(map(float, picked), dtype=float, count=len(picked)).reshape(rows, len(live))
        exponent = 0
        biggest64 = float(np.max(np.abs(a64)))
        if not 1e-280 < biggest64 < 1e280:      # out of float range: scaled by 2^-exponent first
            biggest = max(abs(x) for x in picked)
            exponent = int(math.floor(log10(biggest) / math.log10(2)))
            scale = arb(2) ** (-exponent)
            a64 = np.array([float(x * scale) for x in picked]).reshape(rows, len(live))
        sv = np.linalg.svd(a64, compute_uv=False)
        two = arb(2) ** exponent
        out = [arb(float(v)) * two for v in sv] + [arb(0)] * (len(live) - len(sv))
    elif live:
        Ml = block(values, cols, range(rows), live)
        M = Ml.transpose() * Ml
        out = [abs(e.real.mid()).sqrt() for e in acb_mat(M).eig(algorithm="approx")]
        out.sort(key=lambda v: -log10(v))
    return [v.str(6, radius=False) for v in out] + ["0"] * (cols - len(live))




# ----- digits, agreement, rationals ------------------------------------------------
def radius_digits(x: arb) -> float:
    """Significant decimal digits a ball proves about its midpoint (inf when exact, 0 when
    it contains zero)."""
    if x.rad() == 0:
        return math.inf
    if x.contains(0):
        return 0
    return max(0, math.floor(log10(x.mid()) - log10(arb(x.rad()))))


def agreement_digits(a: arb, b: arb) -> float:
    """Leading decimal digits on which two balls' midpoints agree (relative to ``b``). The
    difference of the exact midpoints is rounded once, at FLOAT_BITS: enough for an integer."""
    with ctx.workprec(FLOAT_BITS):
        return _agreement(a, b)


def agreements(theirs: Sequence[arb], mine: Sequence[arb], where: Iterable[int]) -> dict[int, float]:
    """{k: agreement_digits(theirs[k], mine[k])} for each k of ``where``, under one precision
    context (entering one costs as much as the rest of an entry's work)."""
    with ctx.workprec(FLOAT_BITS):
        return {k: _agreement(theirs[k], mine[k]) for k in where}


def _agreement(a: arb, b: arb) -> float:
    """:func:`agreement_digits` at the caller's precision (FLOAT_BITS)."""
    da, db = a.mid(), b.mid()
    if da == db:
        return math.inf
    if db == 0:
        return 0
    difference = da - db
    return max(0, math.floor(log10(db) - log10(difference)))




def recover_rational(x: arb, digits: int) -> Fraction | None:
    """The simplest rational agreeing with ``digits`` significant digits of a ball's
    midpoint (continued fractions, ``Fraction.limit_denominator``), or None.

    Denominators up to about 10^(digits/2) are searched: below that bound a rational is
    determined uniquely by ``digits`` correct digits.
    """
    digits = int(digits)
    mid = Fraction(x.mid().str(digits + 10, radius=False))
    if mid == 0:
        return Fraction(0)
    bound = 10 ** max(1, (digits - 2) // 2)
    candidate = mid.limit_denominator(bound)
    if abs(candidate - mid) <= abs(mid) * Fraction(10) ** (1 - digits):
        return candidate
    return None


def contains_rational(x: arb, q: Fraction | int) -> bool:
    """Does the ball ``x`` contain the rational ``q``? Decided exactly, from the ball's
    exact (binary) midpoint and radius: no precision, no rounding of ``q``."""
    if not x.is_finite():
        return not x.mid().is_nan()          # an infinite radius contains every real
    q = Fraction(q)
    return abs(q - _dyadic(x.mid())) <= _dyadic(x.rad())


def _dyadic(x: arb) -> Fraction:
    """An exact arb (a binary floating-point number) as a Fraction."""
    man, exp = x.man_exp()
    mantissa, exponent = int(man), int(exp)
    return Fraction(mantissa * 2 ** exponent) if exponent >= 0 else Fraction(mantissa, 2 ** -exponent)
