"""The next precision's beta_s from the previous one's inverse (issue 47,
certify._refined_solve): on a chain beyond FAST_DECISIONS_ABOVE parameters, the 60-digit
analysis refines the 30-digit one instead of a verified solve. Checked against the verified
solve on the same W (balls overlap, radii at most 2^REFINE_SLACK_BITS wider: one pass, 342x at most
here; the same ridge to 0.1 decade: B, the midpoint, is that much less accurate) and the
exact solver's rational beta (inside every ball); where it cannot apply (another square
block, a poor inverse) the verified solve runs, with the same result as before."""

from fractions import Fraction

import pytest
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat

from baseparams import registry
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric import certify
from baseparams.numeric.backends import Arb
from baseparams.plugins.solvers.vp import balls
from baseparams.plugins.solvers.vp import solver as vp_solver


@pytest.fixture(scope="module")
def runs():
    """(mechanism, W at 30 and 60 digits, the 30-digit analysis, the exact rref)."""
    mech = parse_mechanism(generate.serial_chain(3, bodies=10), "chain10.toml")
    assert len(mech.parameters) > certify.FAST_DECISIONS_ABOVE
    trajectory = Trajectory.default(mech, samples=vp_solver.default_samples(mech))
    W30, W60 = (observation_matrix(mech, Arb(d), trajectory)[0] for d in (30, 60))
    a30 = certify.analyse(W30, 30)
    rows = registry.solvers()["exact"].item.solve(mech).coefficient_matrix()
    R, _ = fmpq_mat(len(rows), len(rows[0]), [fmpq(v.numerator, v.denominator) for r in rows for v in r]).rref()
    return mech, W30, W60, a30, R, trajectory


def analysed(W, digits, earlier, monkeypatch, refine=True):
    """The analysis, and whether _refined_solve gave its beta_s (``refine=False``: never)."""
    used = []
    original = certify._refined_solve

    def spy(*args):
        out = original(*args) if refine else None
        used.append(out is not None)
        return out
    with monkeypatch.context() as m:
        m.setattr(certify, "_refined_solve", spy)
        return certify.analyse(W, digits, earlier=earlier), used


def test_refined_beta_encloses_the_exact_beta_and_the_verified_solves(runs, monkeypatch):
    _, _, W60, a30, R, _ = runs
    assert a30.decided == "float64" and a30.block_inverse is not None
    fast, used = analysed(W60, 60, a30, monkeypatch)
    slow, not_used = analysed(W60, 60, a30, monkeypatch, refine=False)
    assert used == [True] and not_used == [False]
    assert (fast.rank, fast.kept, fast.rows) == (slow.rank, slow.kept, slow.rows) == (a30.rank, a30.kept, a30.rows)
    widths = []
    for i in range(fast.beta.nrows()):
        for j in range(fast.beta.ncols()):
            x, y = fast.beta[i, j], slow.beta[i, j]
            exact = R[i, fast.eliminated[j]]
            assert balls.contains_rational(x, Fraction(int(exact.p), int(exact.q))), (i, j)
            assert x.overlaps(y)
            if not y.contains(0):
                widths.append(float(x.rad()) / float(y.rad()) if y.rad() != 0 else 0.0)
    # one pass stops within REFINE_SLACK_BITS of the working precision (a second would be tighter than the
    # verified solve's: 0.09x): at most that much wider
    assert widths and max(widths) <= 2.0 ** certify.REFINE_SLACK_BITS
    # s_r's lower bound from ||Y||_F / (1 - c) is the inverse's own to ~1e-20
    assert float(abs(fast.sigma_r_lower - slow.sigma_r_lower) / slow.sigma_r_lower) < 1e-20
    assert fast.ridge_log10 >= 3 and fast.ridge_log10 == pytest.approx(slow.ridge_log10, abs=0.1)
    # below s_r of the scaled W's midpoints (float64 SVD, independent of both bounds)
    assert float(fast.sigma_r_lower) <= float(fast.singular_values[fast.rank - 1]) * (1 + 1e-12)


def test_refinement_declines_another_block_or_a_poor_inverse(runs, monkeypatch):
    _, _, W60, a30, _, _ = runs
    with ctx.workdps(60):
        entries = W60.entries()
        n = W60.ncols()
        scaled = certify.scaled_entries(entries, n, a30.exponents)
        args = (scaled, n, a30.rows, a30.kept, a30.eliminated, a30.exponents)
        assert certify._refined_solve(*args, a30) is not None
        other_rows = [*a30.rows[:-1], next(i for i in range(W60.nrows()) if i not in a30.rows)]
        assert certify._refined_solve(scaled, n, other_rows, a30.kept, a30.eliminated, a30.exponents, a30) is None
        poor = certify.BallAnalysis(**{**a30.__dict__, "block_inverse": a30.block_inverse * 2})
        assert certify._refined_solve(*args, poor) is None        # ||I - Y A|| = 1: no contraction
        none = certify.BallAnalysis(**{**a30.__dict__, "block_inverse": None})
        assert certify._refined_solve(*args, none) is None
    # a poor inverse: the analysis falls back to the verified solve, with its result
    poor = certify.BallAnalysis(**{**a30.__dict__, "block_inverse": a30.block_inverse * 2})
    fallback, used = analysed(W60, 60, poor, monkeypatch)
    slow, _ = analysed(W60, 60, a30, monkeypatch, refine=False)
    assert used == [False]
    assert fallback.kept == slow.kept and fallback.ridge_log10 == slow.ridge_log10
    assert all(fallback.beta[i, j].mid() == slow.beta[i, j].mid() and fallback.beta[i, j].rad() == slow.beta[i, j].rad()
               for i in range(slow.beta.nrows()) for j in range(slow.beta.ncols()))



def test_excitation_check_counts_as_with_the_direct_product(runs, monkeypatch):
    """Beyond FAST_DECISIONS_ABOVE parameters E = Wc_E - Wc_K beta_s is the residual at B less
    Wc_K (beta_s - B) at FLOAT_BITS: the same bound, ridge and proven-nonzero count as the
    direct product, on a batch that obeys the base parameters and on one that does not."""
    mech, _, W60, a30, _, trajectory = runs
    a60 = certify.analyse(W60, 60, earlier=a30)
    Wc = observation_matrix(mech, Arb(60), random_batch(mech, trajectory, 7919))[0]
    with ctx.workdps(60):
        column = a60.eliminated[0]
        off = arb_mat(Wc.nrows(), Wc.ncols(), [x + (arb(10) ** -3 if k % Wc.ncols() == column else 0)
                                               for k, x in enumerate(Wc.entries())])
    for batch in (Wc, off):
        fast = balls.excitation_check(batch, a60)
        with monkeypatch.context() as m:
            m.setattr(balls, "FAST_DECISIONS_ABOVE", 10 ** 9)          # the direct product
            direct = balls.excitation_check(batch, a60)
        assert fast[1] == direct[1] and fast[2] == direct[2]
        assert fast[0].mid() == direct[0].mid() and fast[0].rad() == direct[0].rad()
    assert balls.excitation_check(Wc, a60)[1] == 0
    assert balls.excitation_check(off, a60)[1] > 0
