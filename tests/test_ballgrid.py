"""numeric.ballgrid.centred (issue 47): beta_s widened to midpoints on one grid, so that B, its
midpoint, makes cheap products. Checked exactly: every ball of M lies inside its widened ball,
every midpoint is an integer multiple of the grid's step, the radii grow by at most one step, and
M - B is centred on 0 (zero midpoints: the excitation check's 53-bit product stays cheap)."""

from fractions import Fraction

import pytest
from flint import arb, arb_mat, ctx

from baseparams.numeric import ballgrid


def dyadic(x: arb) -> Fraction:
    man, exp = x.man_exp()
    return Fraction(int(man)) * Fraction(2) ** int(exp)


@pytest.mark.parametrize("digits", [30, 60])
def test_centred_contains_m_on_one_grid(digits):
    with ctx.workdps(digits):
        third = arb(1) / 3
        values = [third * 7, -third, arb(10) ** -(digits + 21) * third, -(arb(10) ** -(digits + 21)) * third,
                  arb(0), arb(2) ** -5, third * arb(10) ** -12, -third * 3]
        M = arb_mat(2, 4, values)
        G = ballgrid.centred(M)
        # top = 2^2 > 7/3: every M + 4 lies in [2, 8), rounded to prec + GRID_EXTRA_BITS bits
        step = Fraction(2) ** (3 - ctx.prec - ballgrid.GRID_EXTRA_BITS)
        for x, y in zip(M.entries(), G.entries()):
            assert y.contains(x)                                 # every matrix inside M stays inside
            assert (dyadic(y.mid()) / (step / 2)).denominator == 1     # one grid
            assert dyadic(y.rad()) <= dyadic(x.rad()) + step * (1 + Fraction(1, 2 ** 20))   # mag rounds up
        B = G.mid()
        assert all(d.mid() == 0 for d in (G - B).entries())     # centred on an exact B
        assert all(abs(dyadic(y.mid())) <= step for y in G.entries()[2:4])     # noise: 0 or one step


def test_centred_leaves_empty_and_zero_matrices():
    with ctx.workdps(30):
        assert ballgrid.centred(arb_mat(0, 3)).nrows() == 0
        Z = arb_mat(2, 2)
        assert ballgrid.centred(Z) == Z
