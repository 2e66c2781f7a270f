"""Gautier's method in ball arithmetic (python-flint ``arb``): a rank that is proven.

python-flint has no SVD. The work is split into *decisions*, made on midpoints, and
*claims*, each verified in ball arithmetic on the column-scaled observation matrix Ws
(every column divided by an exact power of two near its norm, so scaling adds no
rounding and ``beta = D_K^-1 beta_s D_E`` is exact):

1. Decisions. On the midpoints of the Gram matrix ``G = Ws^T Ws`` (70 x 70 for the
   SLA whatever the number of samples; one ``arb_mat`` product, in C), Cholesky with
   diagonal (complete) pivoting gives the rank r: the pivots above the noise threshold
   ``1e3 * n * 10^-D * max G_jj``. The kept columns K are then, by default, the
   leftmost basis (each pivot above ``10^(-D/2) max G_jj``, since rounding noise in this
   possibly ill-conditioned basis is amplified) (parameter order: what an exact ``rref`` picks, so ``vp`` and
   ``exact`` results compare entry by entry), else the complete-pivoting columns. Then
   r rows R of Ws_K making a well-conditioned square block (QR with column pivoting on
   Ws_K^T, in float64).
2. Claims, each rigorous for every W inside the computed W ball:
   - ``rank(W) >= r``: ``arb_mat.solve`` proves the r x r block ``Ws_RK`` nonsingular
     (it refuses otherwise);
   - ``beta_s``: the enclosure of the solution of ``Ws_RK beta_s = Ws_RE``. For a W of
     rank exactly r, ``Ws_E = Ws_K beta_s`` holds on every row, so these r rows give
     its beta; solving a square block costs ``log10 cond`` digits, where the normal
     equations would cost twice that;
   - ``s_{r+1}(Ws) <= tail_bound = ||Ws_E - Ws_K B||_F`` for an exact matrix B (the
     midpoint of beta_s, refined once by least squares), by Weyl's inequality, since
     ``[Ws_K, Ws_K B]`` has rank r: every singular value after the ridge lies in a ball
     around zero, and that ball shrinks as D grows;
   - ``s_r(Ws) >= sigma_r_lower = ||Ws_RK^-1||_F^-1`` (dropping columns or rows never
     raises the smallest singular value). ``sigma_r_lower / tail_bound`` is the proven
     height of the ridge.

Why not eliminate in ball arithmetic directly: naive interval elimination widens the
balls at every step (on the SLA at 30 digits it proved only 39 of 41 pivots), while a
verified solve (python-flint's preconditioned one) and a residual bound stay tight.
Eigenvalues of G (``acb_mat.eig``) are rigorous only when isolated and fail on the
cluster of zero eigenvalues; they serve only for the approximate singular values that
are plotted.
"""

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
from flint import acb_mat, arb, arb_mat

from baseparams.numeric.backends import precision
from baseparams.numeric.linalg import pivoted_qr_columns, power_of_two_exponents

NOISE_FACTOR = 1000       # pivots below NOISE_FACTOR * n * 10^-D * max G_jj are noise
SPECTRUM_IN_ARB_UP_TO = 80  # parameters: approximate spectra by an eig at D digits up to here
FLOAT_BITS = 53           # precision of the helpers whose result is a float or an integer


@dataclass
class BallAnalysis:
    digits: int
    rank: int
    kept: list
    eliminated: list
    pivoting: str                 # "natural", "complete" or "imposed"
    pivots: list                  # complete-pivoting pivots of the scaled G (midpoints), in order
    pivot_order: list             # their columns
    beta_s: object                # arb_mat r x (n - r), scaled
    beta: object                  # arb_mat r x (n - r), unscaled: phi_b = phi_1 + beta phi_2
    exponents: list               # column j scaled by 2^-exponents[j]
    zero_columns: list            # columns no entry of which is proven nonzero
    tail_bound: object            # arb: rigorous upper bound of s_{r+1}(Ws) (0 if r = n)
    sigma_r_lower: object         # arb: rigorous lower bound of s_r(Ws)
    singular_values: list         # approximate singular values of Ws (strings), largest first
    refined: object = None        # exact (midpoint) B used for tail_bound
    notes: list = field(default_factory=list)

    @property
    def ridge_log10(self):
        """log10(sigma_r_lower / tail_bound): the proven height of the ridge, in decades."""
        if self.rank == 0 or not self.sigma_r_lower > 0:
            return -math.inf
        if self.tail_bound == 0:
            return math.inf
        return log10(self.sigma_r_lower) - log10(self.tail_bound)


def log10(x):
    """log10 |midpoint| as a float (-inf for zero); fine for 10^-100000. Computed at
    FLOAT_BITS whatever the caller's precision: the result is a float anyway."""
    with precision(bits=FLOAT_BITS):
        x = abs(arb(x).mid())
        if x == 0:
            return -math.inf
        return float(x.log() / arb(10).log())


# ----- decisions (midpoints) ---------------------------------------------------
def _column_exponents(W):
    """Per column: round(log2(norm)) from the midpoints, and the zero columns.

    A column is zero when every entry's ball contains 0: nothing proves it nonzero, and
    scaling its rounding noise up to norm 1 would invent a rank (the PUMA 560's ``mz2``
    is such a column: exactly zero, but its balls have midpoints ~1e-31 at 30 digits).
    Zero columns are eliminated with zero coefficients; if one is in fact tiny and
    nonzero, a higher precision shows it (and the ``vp`` solver's ranks then differ).
    """
    rows, cols = W.nrows(), W.ncols()
    entries = W.entries()
    log2_norms, zero = [], []
    for j in range(cols):
        column = entries[j::cols] if rows else []
        if all(x.contains(0) for x in column):
            zero.append(j)
            log2_norms.append(None)
            continue
        total = arb(0)
        for x in column:
            m = x.mid()
            total += m * m
        log2_norms.append(log10(total) / 2 / math.log10(2))
    return power_of_two_exponents(log2_norms), zero


PANEL = 16                 # pivots per block update of the Schur complement


def _eliminations(G, threshold, complete=True, skip=(), target=None):
    """Symmetric Gaussian elimination (LDL^T) on the midpoints of G, one pivot at a time:
    yields (column, pivot, Schur column) for each pivot above ``threshold``.

    ``complete``: the largest remaining diagonal next (complete pivoting), until none
    exceeds the threshold; else the columns in order, those at or below the threshold
    skipped (the leftmost basis), until ``target`` pivots. Blocked: a pivot's column is
    the panel-start matrix's minus the panel's earlier pivots (n x PANEL work in Python),
    the matrix itself is updated once per panel by one arb_mat product (in C); the
    diagonal is kept current. Every result is rounded to its midpoint (decisions only).
    """
    A = G.mid()
    n = A.nrows()
    entries = A.entries()
    diag = [entries[j * n + j] for j in range(n)]
    open_ = [j for j in range(n) if j not in set(skip)]
    cols, scaled = [], []
    count = 0
    while open_ and (target is None or count < target):
        if complete:
            j = max(open_, key=lambda k: (diag[k], -k))
        else:
            j = open_[0]
        p = diag[j]
        open_.remove(j)
        if not p > threshold:
            if complete:
                return
            continue
        col = entries[j::n]
        for c, sc in zip(cols, scaled):
            f = sc[j]
            col = [(x - y * f).mid() for x, y in zip(col, c)]
        inv = 1 / p
        sc = [(x * inv).mid() for x in col]
        for k in open_:
            diag[k] = (diag[k] - col[k] * sc[k]).mid()
        cols.append(col)
        scaled.append(sc)
        count += 1
        yield j, p, col
        if len(cols) == PANEL:
            A = (A - arb_mat(len(cols), n, [x for c in cols for x in c]).transpose()
                 * arb_mat(len(cols), n, [x for c in scaled for x in c])).mid()
            entries = A.entries()
            cols, scaled = [], []


def _approximate_pivots(G, threshold, skip=()):
    """Cholesky (LDL^T) with diagonal pivoting on midpoints while the pivot exceeds ``threshold``.

    Returns (order, pivots): the columns in pivot order and their pivots (midpoints).
    """
    order, pivots = [], []
    for j, p, _ in _eliminations(G, threshold, complete=True, skip=skip):
        order.append(j)
        pivots.append(p)
    return order, pivots


def _natural_basis(G, threshold, target, skip=()):
    """Leftmost columns (parameter order) whose midpoint Schur pivot exceeds ``threshold``."""
    return [j for j, _, _ in _eliminations(G, threshold, complete=False, skip=skip, target=target)]


def _select_rows(Wk, Gkk):
    """r rows of W_K making a well-conditioned square block (a choice only: what is claimed
    is verified in arb).

    W_K itself may be far too ill-conditioned for float64 (cond 1e20 when the kept
    columns are the parameter-order basis of a low-mobility mechanism), so it is first
    orthonormalised at the working precision, ``Q = W_K R^-1`` with ``R^T R = G_KK``
    (Cholesky on midpoints); QR with column pivoting on ``Q^T`` in float64 then picks
    rows whose block of Q, hence of W_K, is as well conditioned as a greedy choice can.
    """
    r = Wk.ncols()
    R = _cholesky_mid(Gkk)
    Q = Wk
    if R is not None:
        try:
            Q = _mid(Wk) * _mid(R.inv())
        except ZeroDivisionError:
            Q = Wk
    a = np.array([[float(Q[i, j].mid()) for i in range(Q.nrows())] for j in range(r)])
    return sorted(pivoted_qr_columns(a, r))


def _cholesky_mid(G):
    """Upper-triangular R with R^T R = G (midpoints), or None if a pivot is not positive."""
    n = G.nrows()
    R = arb_mat(n, n)
    done = 0
    for i, p, col in _eliminations(G, arb(0), complete=False):
        if i != done:                    # an earlier pivot was not positive
            return None
        root = p.sqrt().mid()
        for j in range(i, n):
            R[i, j] = (col[j] / root).mid()
        done += 1
    return R if done == n else None


# ----- matrices ------------------------------------------------------------------
def _columns(W, cols, exponents):
    """The scaled columns ``cols`` of W as an arb_mat (exact power-of-two scaling)."""
    two = arb(2)
    powers = [two ** (-exponents[j]) for j in cols]
    rows, n = W.nrows(), W.ncols()
    if not cols or not rows:
        return arb_mat(rows, len(cols))
    e = W.entries()
    return arb_mat(rows, len(cols), [e[i * n + j] * p for i in range(rows) for j, p in zip(cols, powers)])


def _pick(M, cols):
    """Columns ``cols`` of M (copied, not rounded)."""
    return _submatrix(M, list(range(M.nrows())), cols) if M.nrows() else arb_mat(0, len(cols))


def _rows(M, rows):
    n = M.ncols()
    if not rows or not n:
        return arb_mat(len(rows), n)
    e = M.entries()
    return arb_mat(len(rows), n, [x for i in rows for x in e[i * n:(i + 1) * n]])


def _submatrix(G, rows, cols):
    if not rows or not cols:
        return arb_mat(len(rows), len(cols))
    n = G.ncols()
    e = G.entries()
    return arb_mat(len(rows), len(cols), [e[i * n + j] for i in rows for j in cols])


def _mid(M):
    return M.mid()


def _frobenius_upper(M):
    """An upper bound of ||M||_F as an exact arb (no float underflow at hundreds of digits)."""
    total = arb(0)
    for x in M.entries():
        total += arb(abs(x).upper()) ** 2
    return arb(total.sqrt().upper())


def _verify(Ws, G, kept):
    """(rows, beta_s) with Ws_RK beta_s = Ws_RE solved in ball arithmetic, or None when
    Ws_RK is not proven nonsingular."""
    eliminated = [j for j in range(Ws.ncols()) if j not in set(kept)]
    Wk = _pick(Ws, kept)
    if not kept:
        return [], arb_mat(0, len(eliminated))
    rows = _select_rows(Wk, _submatrix(G, kept, kept))
    if len(rows) < len(kept):
        return None
    Wrk = _rows(Wk, rows)
    try:
        if eliminated:
            beta_s = Wrk.solve(_rows(_pick(Ws, eliminated), rows))
        else:
            Wrk.inv()
            beta_s = arb_mat(len(kept), 0)
    except ZeroDivisionError:
        return None
    return rows, beta_s


# ----- the analysis --------------------------------------------------------------
def analyse(W, digits, kept=None, pivoting="natural", approximate_spectrum=True):
    """Rank, permutation and beta of an ``arb_mat`` W, computed at ``digits`` (whatever
    precision the caller has set; it is restored on return).

    ``kept``: impose the kept columns (to compare two precisions, or another solver's
    permutation); ValueError if they are not proven independent.
    """
    with precision(digits):
        return _analyse(W, digits, kept, pivoting, approximate_spectrum)


def _analyse(W, digits, kept, pivoting, approximate_spectrum):
    n = W.ncols()
    exponents, zero = _column_exponents(W)
    everything = _columns(W, list(range(n)), exponents)
    G = everything.transpose() * everything
    gmax = max((float(abs(G[i, i].mid())) for i in range(n)), default=0.0)
    threshold = arb(NOISE_FACTOR * n * max(gmax, 1e-300)) * arb(10) ** (-digits)
    order, pivots = _approximate_pivots(G, threshold, skip=zero)
    notes = []
    candidates = []
    if kept is not None:
        candidates.append((sorted(kept), "imposed"))
    else:
        if pivoting == "natural":
            # a dependent column's pivot is noise amplified by cond(W_K), which can be huge
            # for this basis: demand 10^(-D/2), which noise cannot reach while cond < 10^(D/2)
            strict = max(threshold, arb(max(gmax, 1e-300)) * arb(10) ** (-(digits // 2)))
            natural = _natural_basis(G, strict, len(order), skip=zero)
            if len(natural) == len(order):
                candidates.append((natural, "natural"))
            else:
                notes.append(f"the parameter-order basis found {len(natural)} of {len(order)} columns "
                             f"at {digits} digits; the complete-pivoting columns are kept instead")
        candidates.append((sorted(order), "complete"))
    verified = None
    while verified is None:
        for cand, how in candidates:
            verified = _verify(everything, G, cand)
            if verified is not None:
                kept, used = cand, how
                break
            if how == "imposed":
                raise ValueError("the imposed kept columns are not proven independent at this precision")
            notes.append(f"the {how} choice of {len(cand)} columns is not proven independent "
                         f"at {digits} digits")
        if verified is None:            # a smaller rank that can be proven
            order, pivots = order[:-1], pivots[:-1]
            candidates = [(sorted(order), "complete")]
            notes.append(f"rank lowered to {len(order)}: the last pivot is not provable at {digits} digits")
    rows, beta_s = verified
    eliminated = [j for j in range(n) if j not in set(kept)]

    # s_{r+1} <= ||Ws_E - Ws_K B||_F for any exact B (Weyl: [Ws_K, Ws_K B] has rank r)
    Wk = _pick(everything, kept)
    if eliminated and kept:
        We = _pick(everything, eliminated)
        B = _mid(beta_s)
        try:                            # one least-squares refinement of B on all rows
            E = _mid(We - Wk * B)
            B = _mid(B + _mid(_submatrix(G, kept, kept)).solve(_mid(Wk.transpose() * E)))
        except ZeroDivisionError:
            pass
        tail = _frobenius_upper(We - Wk * B)
    elif eliminated:
        B = arb_mat(0, len(eliminated))
        tail = _frobenius_upper(_pick(everything, eliminated))
    else:
        B = arb_mat(len(kept), 0)
        tail = arb(0)

    # s_r >= s_min(Ws_K) >= s_min(Ws_RK) >= 1 / ||Ws_RK^-1||_F
    sigma_lower = arb(0)
    if kept:
        try:
            f = _frobenius_upper(_rows(Wk, rows).inv())
            sigma_lower = arb((1 / f).lower()) if f > 0 else arb(0)
        except ZeroDivisionError:
            pass

    two = arb(2)
    beta = arb_mat(len(kept), len(eliminated))
    for a, i in enumerate(kept):
        for b, j in enumerate(eliminated):
            beta[a, b] = beta_s[a, b] * two ** (exponents[j] - exponents[i])

    svals = _approximate_singular_values(G, everything) if approximate_spectrum else []
    return BallAnalysis(digits, len(kept), kept, eliminated, used, pivots, order, beta_s, beta,
                        exponents, zero, tail, sigma_lower, svals, B, notes)


def excitation_check(Wc, a):
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
    with precision(a.digits):
        return _excitation_check(Wc, a)


def _excitation_check(Wc, a):
    if not a.eliminated:
        return arb(0), 0, math.inf
    We = _columns(Wc, a.eliminated, a.exponents)
    if a.kept:
        Wk = _columns(Wc, a.kept, a.exponents)
        bound = _frobenius_upper(We - Wk * a.refined)
        E = We - Wk * a.beta_s
    else:
        bound, E = _frobenius_upper(We), We
    nonzero = sum(1 for i in range(E.nrows()) for j in range(E.ncols()) if not E[i, j].contains(0))
    combined = arb((a.tail_bound ** 2 + bound ** 2).sqrt().upper())
    if a.rank == 0 or not a.sigma_r_lower > 0:
        decades = math.inf if combined == 0 else -math.inf
    elif combined == 0:
        decades = math.inf
    else:
        decades = log10(a.sigma_r_lower) - log10(combined)
    return bound, nonzero, decades


def tail_singular_values(W, a):
    """Approximate singular values of the residual ``E = Ws_E - Ws_K B`` (B = ``a.refined``),
    largest first: by Weyl's inequality ``s_{r+i}(Ws) <= s_i(E)``, so they bound the
    singular values after the ridge one by one. Exactly zero columns of E give exact zeros.
    Computed at the analysis' digits."""
    with precision(a.digits):
        return _tail_singular_values(W, a)


def _tail_singular_values(W, a):
    if not a.eliminated:
        return []
    We = _columns(W, a.eliminated, a.exponents)
    E = _mid(We - _columns(W, a.kept, a.exponents) * a.refined) if a.kept else _mid(We)
    live = [j for j in range(E.ncols()) if any(E[i, j] != 0 for i in range(E.nrows()))]
    values = []
    if live and W.ncols() > SPECTRUM_IN_ARB_UP_TO:       # float64, as _approximate_singular_values
        Ml = _submatrix(E, list(range(E.nrows())), live)
        biggest = max(abs(x) for x in Ml.entries())
        exponent = int(math.floor(log10(biggest) / math.log10(2)))
        values = np.linalg.svd(_float_matrix(Ml, exponent), compute_uv=False)
        two = arb(2) ** exponent
        values = [arb(float(v)) * two for v in values] + [arb(0)] * (len(live) - len(values))
    elif live:
        Ml = arb_mat(E.nrows(), len(live), [E[i, j] for i in range(E.nrows()) for j in live])
        M = Ml.transpose() * Ml
        values = [abs(e.real.mid()).sqrt() for e in acb_mat(M).eig(algorithm="approx")]
        values.sort(key=lambda v: -log10(v))
    return [v.str(6, radius=False) for v in values] + ["0"] * (E.ncols() - len(live))


def _approximate_singular_values(G, Ws):
    """sqrt(|eigenvalues|) of the scaled Gram matrix, largest first, as decimal strings.

    ``acb_mat.eig(algorithm="approx")``: no error bounds (the cluster of zero eigenvalues
    defeats rigorous isolation); the values after the ridge are the working precision's
    noise, and ``BallAnalysis.tail_bound`` bounds them rigorously. Beyond
    ``SPECTRUM_IN_ARB_UP_TO`` parameters (an eig at D digits costs tens of seconds there)
    they are the float64 singular values of Ws's midpoints: the same values to float
    accuracy (absolute 1e-16 of the largest), nothing proven either way.
    """
    n = G.nrows()
    if n == 0:
        return []
    if n > SPECTRUM_IN_ARB_UP_TO:
        values = np.linalg.svd(_float_matrix(Ws), compute_uv=False) if Ws.nrows() else np.zeros(0)
        return [arb(float(v)).str(12, radius=False) for v in values] + ["0"] * (n - len(values))
    M = acb_mat(G)
    values = [abs(e.real.mid()).sqrt() for e in M.eig(algorithm="approx")]
    values.sort(key=lambda v: -log10(v))
    return [v.str(12, radius=False) for v in values]


def _float_matrix(M, exponent=0):
    """The midpoints of M times 2^-exponent (exact) as a float64 array."""
    scale = arb(2) ** (-exponent)
    return np.array([float((x.mid() * scale).mid()) for x in M.entries()]).reshape(M.nrows(), M.ncols())


# ----- digits, agreement, rationals ------------------------------------------------
def radius_digits(x):
    """Significant decimal digits a ball proves about its midpoint (inf when exact, 0 when
    it contains zero)."""
    if x.rad() == 0:
        return math.inf
    if x.contains(0):
        return 0
    return max(0, math.floor(log10(x.mid()) - log10(arb(x.rad()))))


def agreement_digits(a, b):
    """Leading decimal digits on which two balls' midpoints agree (relative to ``b``). The
    difference of the exact midpoints is rounded once, at FLOAT_BITS: enough for an integer."""
    da, db = a.mid(), b.mid()
    if da == db:
        return math.inf
    if db == 0:
        return 0
    with precision(bits=FLOAT_BITS):
        difference = da - db
    return max(0, math.floor(log10(db) - log10(difference)))


def decimal_string(x, digits):
    """The midpoint with ``digits`` significant digits, without the radius."""
    digits = max(1, min(int(digits), 100_000))
    return x.mid().str(digits, radius=False).replace("e+", "e")


def recover_rational(x, digits):
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


def contains_rational(x, q):
    """Does the ball ``x`` contain the rational ``q``? Decided exactly, from the ball's
    exact (binary) midpoint and radius: no precision, no rounding of ``q``."""
    if not x.is_finite():
        return not x.mid().is_nan()          # an infinite radius contains every real
    q = Fraction(q)
    return abs(q - _dyadic(x.mid())) <= _dyadic(x.rad())


def _dyadic(x):
    """An exact arb (a binary floating-point number) as a Fraction."""
    man, exp = x.man_exp()
    man, exp = int(man), int(exp)
    return Fraction(man * 2 ** exp) if exp >= 0 else Fraction(man, 2 ** -exp)
