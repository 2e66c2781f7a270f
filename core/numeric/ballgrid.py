"""Frobenius bounds and grids for python-flint ball matrices (``arb_mat``), the pieces of
:mod:`baseparams.numeric.certify`'s claims that are about the matrices, not the analysis.

Why grids: python-flint's block product turns each row of the left factor and each column of
the right one into integers spanning their entries' exponents and mantissas. A matrix whose
midpoints are multiples of one power of two (a grid some bits finer than the working precision)
gives integers of about that many bits, where noise entries (W's midpoints reach 1e-96, beta_s's
1e-81 where a coefficient is zero) with full mantissas give twice as many.
"""

from flint import arb, arb_mat, ctx

GRID_EXTRA_BITS = 32      # grids 32 bits finer than the working precision


def on_grid(M: arb_mat, extra_bits: int = GRID_EXTRA_BITS, four: arb_mat | None = None) -> arb_mat:
    """A ball matrix containing M whose midpoints are multiples of one power of two:
    ``(M + 4) - 4`` at the working precision plus ``extra_bits`` (each addition's
    rounding error joins the radius, so every exact matrix inside M is inside the result).
    For matrices with entries of magnitude at most about 1 (the column-scaled W), the
    midpoints then share one exponent range and python-flint's block product runs on one
    integer matrix instead of many (W's midpoints reach 1e-96 where an entry is noise)."""
    if not M.nrows() or not M.ncols():
        return M
    with ctx.extraprec(extra_bits):
        if four is None:            # the matrix of 4s of M's shape (callers may pass it)
            four = arb_mat(M.nrows(), 1, [1] * M.nrows()) * arb_mat(1, M.ncols(), [4] * M.ncols())
        return (M + four) - four


def centred(M: arb_mat) -> arb_mat:
    """:func:`on_grid` with the grid set by M's largest midpoint (2^-(prec + GRID_EXTRA_BITS)
    of a power of two above it), whatever its size: every matrix inside M stays inside, the
    radii grow by at most one step of the grid (beta_s at 60 digits: 1e-70, where the radii
    of the coefficients printed are 1e-55). Its midpoint is then an exact B on the grid with
    M - B centred on 0 (TIAGo's tail products 0.47 -> 0.39 CPU s, the 60-digit pass's 0.66 ->
    0.57)."""
    if not M.nrows() or not M.ncols():
        return M
    largest = max((abs(x) for x in M.mid().entries()), default=arb(0))
    if largest == 0 or not largest.is_finite():
        return M
    man, exp = largest.man_exp()
    top = arb(2) ** (int(exp) + int(man).bit_length())          # > every |midpoint|
    return on_grid(M, four=arb_mat(M.nrows(), 1, [1] * M.nrows()) * arb_mat(1, M.ncols(), [top] * M.ncols()))


def frobenius_upper(M: arb_mat) -> arb:
    """An upper bound of ||M||_F as an exact arb (no float underflow at hundreds of digits):
    the entries as one row vector v, ``v v^T`` in ball arithmetic (one dot product, in C)
    encloses the sum of squares of every matrix inside M."""
    if not M.nrows() or not M.ncols():
        return arb(0)
    v = arb_mat(1, M.nrows() * M.ncols(), M.entries())
    total = arb((v * v.transpose())[0, 0].upper())       # >= the sum of squares, exact
    return arb(total.sqrt().upper())


def frobenius_pair(M: arb_mat) -> tuple[arb, ...]:
    """(frobenius_upper(M), frobenius_upper(M.mid())) from one row vector of M's entries: reading
    them out and in is most of either's cost (TIAGo's 624 x 170 residual: 0.04 s a precision)."""
    v = arb_mat(1, M.nrows() * M.ncols(), M.entries())
    return tuple(arb(arb((u * u.transpose())[0, 0].upper()).sqrt().upper()) for u in (v, v.mid()))
