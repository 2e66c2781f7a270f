"""Issue 47's cheaper bookkeeping of the vp solver and the certified analysis, checked against
what each replaced, entry by entry: the digits two balls share (one precision context for all
of them), the least digits a ball of beta proves, and the tail bound with its midpoints' bound
from one vector of entries (the refinement of B decided as before)."""

import math

import numpy as np
from flint import arb, arb_mat, ctx

from baseparams.numeric import certify
from baseparams.plugins.solvers.vp import balls
from baseparams.plugins.solvers.vp import solver as vp_solver


def _balls() -> list[arb]:
    """Exact, zero, containing zero, wide and tight balls, huge and tiny exponents, infinite."""
    with ctx.workdps(60):
        third = arb(1) / 3
        return [arb(0), arb(5), arb(-2) ** -200, third, -third, arb("1.25", "0.5"), arb("0", "1e-40"),
                arb("1e-3000", "1e-3050"), arb("-7e4000", "3e3990"), third * arb(10) ** 40, arb(1, "1e-58"),
                arb("inf"), arb(1, "inf"), arb(2) ** 100000 / 3, arb(0, 1)]


def test_agreements_are_agreement_digits_one_by_one():
    with ctx.workdps(60):
        mine = _balls()
    with ctx.workdps(30):
        theirs = [x * (1 + arb(10) ** -25) if x.is_finite() else x for x in mine]
    where = [k for k, x in enumerate(mine) if x.is_finite()]
    found = balls.agreements(theirs, mine, where)
    assert found == {k: balls.agreement_digits(theirs[k], mine[k]) for k in where}
    assert all(isinstance(d, int) or d == math.inf for d in found.values())
    assert any(24 <= d <= 26 for d in found.values())
    assert ctx.prec == 53                 # the caller's precision restored


def test_least_digits_of_beta():
    """The least digits a ball of beta proves, over the balls that exclude 0 (as min_digits
    read them entry by entry before), beside every entry's own digits."""
    values = [x for x in _balls() if x.is_finite()]
    with ctx.workdps(60):
        beta = arb_mat(2, len(values) // 2, values[:len(values) // 2 * 2])
    rows, least = vp_solver._digits_of(beta)
    entries = beta.entries()
    assert [d for row in rows for d in row] == [balls.radius_digits(x) for x in entries]
    assert least == min(balls.radius_digits(x) for x in entries if not x.contains(0))
    assert vp_solver._digits_of(arb_mat(1, 2, [0, arb(0, 1)]))[1] == math.inf


def test_unscaled_is_each_entry_times_its_power_of_two():
    rng = np.random.default_rng(5)
    kept, eliminated = [0, 2, 3], [1, 4, 5, 6]
    exponents = [int(e) for e in rng.integers(-40, 40, 7)]
    with ctx.workdps(30):
        beta_s = arb_mat(3, 4, [arb(int(v)) / 7 for v in rng.integers(-100, 100, 12)])
        beta = certify.unscaled(beta_s, kept, eliminated, exponents)
        for a, i in enumerate(kept):
            for b, j in enumerate(eliminated):
                want = beta_s[a, b] * arb(2) ** (exponents[j] - exponents[i])
                assert beta[a, b].mid() == want.mid() and beta[a, b].rad() == want.rad()
        assert certify.unscaled(beta_s, kept, [], exponents).ncols() == 0


def test_frobenius_pair_is_both_bounds():
    with ctx.workdps(30):
        M = arb_mat(2, 3, [arb(1, "1e-20"), arb(-2), arb(0, "1e-5"), arb(1) / 3, arb(4, 1), arb(0)])
        upper, middle = certify._frobenius_pair(M)
        for found, want in ((upper, certify.frobenius_upper(M)), (middle, certify.frobenius_upper(M.mid()))):
            assert found.mid() == want.mid() and found.rad() == want.rad() == 0
        assert float(middle) ** 2 >= sum(float(x.mid()) ** 2 for x in M.entries()) * (1 - 1e-15)
        assert certify._frobenius_pair(arb_mat(0, 3)) == (0, 0)


def _refined_before(scaled, shape, scaled64, kept, eliminated, Wk, beta_s):
    """The refinement decision as it was before issue 47's shortcut: ||mid(E)||_F formed."""
    m, n = shape
    We = certify.block(scaled, n, range(m), eliminated)
    B = beta_s.mid()
    residual = We - Wk * B
    tail = certify.frobenius_upper(residual)
    size = certify.frobenius_upper(residual.mid())
    return bool(4 * size > tail and size > 0), tail


def test_refinement_decided_as_before():
    """Two W of rank 3 (6 columns): one whose balls are tight (the residual's midpoints, from a
    rounded beta, dominate: refined) and one whose balls are wide (radii dominate: not)."""
    rng = np.random.default_rng(2)
    K = rng.standard_normal((40, 3))
    exact = np.hstack([K, K @ rng.standard_normal((3, 3))])
    for radius, refined in (("1e-40", True), ("1e-8", False)):
        with ctx.workdps(30):
            W = arb_mat(40, 6, [arb(float(v), radius) for v in exact.ravel()])
            kept, eliminated = [0, 1, 2], [3, 4, 5]
            scaled = W.entries()
            Wk = certify.block(scaled, 6, range(40), kept)
            beta_s = arb_mat(3, 3, [arb(float(v)) for v in np.linalg.lstsq(K, exact[:, 3:], rcond=None)[0].ravel()])
            before, tail_before = _refined_before(scaled, (40, 6), exact, kept, eliminated, Wk, beta_s)
            B, _, tail = certify._refined_fast(scaled, (40, 6), exact, kept, eliminated, Wk, beta_s)
            changed = any(x.mid() != y.mid() for x, y in zip(B.entries(), beta_s.mid().entries()))
            assert before is refined
            assert changed is (refined and tail < tail_before)
            if not changed:
                assert tail.mid() == tail_before.mid()


def test_printed_digits_reuse_the_agreements_of_compare_runs(monkeypatch):
    """The agreement digits compare_runs found are the ones the printed digits are capped by:
    the rows, digits and untrusted list are the same with and without them kept."""
    from baseparams.io.loader import resolve
    seen = {}
    original = vp_solver._vp_coefficients

    def keep(final, prev, params):
        seen.update(final=final, prev=prev, params=params)
        return original(final, prev, params)
    monkeypatch.setattr(vp_solver, "_vp_coefficients", keep)
    vp_solver.VariablePrecisionSolver().solve(resolve("puma560"), recover=False)
    final, prev = seen["final"], seen["prev"]
    assert final.agreement is not None and final.agreement[0] is prev.analysis
    with_them = original(final, prev, seen["params"])
    final.agreement = None
    assert original(final, prev, seen["params"]) == with_them
    final.agreement = (prev.analysis, {})                      # none kept: all computed again
    assert original(final, prev, seen["params"]) == with_them


def test_only_the_final_run_computes_its_approximate_spectrum(monkeypatch):
    """The first of the ladder's precisions is never the final run: its approximate singular
    values (never reported) are not computed; the final run's are, and are the result's."""
    from baseparams.io.loader import resolve
    runs = []
    original = vp_solver.compare_runs

    def keep(prev, cur):
        runs[:] = [prev, cur]
        return original(prev, cur)
    monkeypatch.setattr(vp_solver, "compare_runs", keep)
    result = vp_solver.VariablePrecisionSolver().solve(resolve("puma560"), recover=False)
    first, final = runs
    assert first.analysis.singular_values == [] and final.analysis.singular_values
    assert result.singular_values[:result.rank] == final.analysis.singular_values[:result.rank]
    fixed = vp_solver.VariablePrecisionSolver().solve(resolve("puma560"), digits=30, recover=False)
    assert len(fixed.singular_values) == len(result.singular_values)
