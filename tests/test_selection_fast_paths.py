"""The diagnosis's shortcuts against the plain computations they replace: each must give
the same answer (to rounding) on every input, not only on the TX40 they were timed on."""

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt
from statsmodels.stats.sandwich_covariance import S_hac_simple

from baseparams.identify import longrun
from baseparams.diagnose import selection as S
from baseparams.diagnose import wald as W
from baseparams.recordings.data import zero_phase
from baseparams.identify.linear import WeightedLinearModel


def _ar(rng, n, f, rho):
    e = rng.standard_normal((n + 100, f))
    for t in range(1, len(e)):
        e[t] += rho * e[t - 1]
    return e[100:]


@pytest.mark.parametrize("seed", range(3))
def test_hac_window_from_direct_lags_is_the_fft_ones(seed, monkeypatch):
    """The first lags computed one by one give the window the FFT of every lag gives, over
    residuals from white to strongly correlated (windows 0 to N/4)."""
    rng = np.random.default_rng(seed)
    residuals = [_ar(rng, int(rng.integers(50, 900)), int(rng.integers(1, 7)), rho)
                 for rho in (0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.97, -0.5)]
    direct = [longrun.hac_lags(r) for r in residuals]
    monkeypatch.setattr(longrun, "DIRECT_LAGS", 1)            # the FFT for every lag beyond the first
    assert direct == [longrun.hac_lags(r) for r in residuals]
    assert len(set(direct)) >= 4


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9, 1.0, -0.99])
def test_prewhitened_long_run_of_one_score_is_the_matrix_formula(rho):
    """One score column: the scalar path equals Andrews and Monahan's matrix form (lstsq,
    singular values capped at PREWHITEN_LIMIT, (I - A)^-1 S (I - A)^-T), also where the cap
    acts (a unit root, a negative coefficient past it)."""
    rng = np.random.default_rng(int(abs(rho) * 100))
    s = _ar(rng, 600, 1, rho)
    before, after = s[:-1], s[1:]
    At, *_ = np.linalg.lstsq(before, after, rcond=None)
    u, sv, vt = np.linalg.svd(At.T)
    A = (u * np.minimum(sv, longrun.PREWHITEN_LIMIT)) @ vt
    e = after - before @ A.T
    B = np.linalg.inv(np.eye(1) - A)
    expected = B @ S_hac_simple(e, nlags=longrun.hac_lags(e)) @ B.T
    assert longrun.long_run(s, 7) == pytest.approx(expected, rel=1e-10)


def test_one_column_basis_and_support_are_the_svd_ones():
    """orthonormal_basis of one column (its direction, or nothing below the tolerance) and the
    support's participation ratio, against the SVD and the formula 1 / sum w^2."""
    rng = np.random.default_rng(4)
    for size in (1.0, 1e-6, 1e-8, 0.0):
        column = rng.standard_normal((300, 1)) * size
        reference = rng.standard_normal((300, 1))
        fast = W.orthonormal_basis(column, W.ABSORB_TOL, reference)
        u, s, _ = np.linalg.svd(column / np.linalg.norm(reference), full_matrices=False)
        slow = u[:, s > W.ABSORB_TOL]
        assert fast.shape == slow.shape and np.allclose(np.abs(fast), np.abs(slow))
    basis = np.linalg.qr(rng.standard_normal((300, 3)) * np.linspace(0.01, 1, 300)[:, None])[0]
    # over the subspace's own directions: the eigenvectors of sum_t G_t^2, G_t = b_t' b_t
    per_sample = basis.reshape(100, 3, 3)
    A = sum((b.T @ b) @ (b.T @ b) for b in per_sample)
    own = basis @ np.linalg.eigh(A)[1]
    w = (own ** 2).reshape(100, 3, 3).sum(axis=1)
    w = w / w.sum(axis=0)
    assert W.support(basis, (100, 3)) == pytest.approx(np.min(1 / np.sum(w ** 2, axis=0)))
    spike = np.zeros((300, 1))
    spike[7] = 1.0
    # a spike beside a spread direction: the subspace's sparsest own direction is (within 1 %) the spike
    assert W.support(np.hstack([spike, np.full((300, 1), 300 ** -0.5)]), (100, 3)) == pytest.approx(1.0, rel=0.01)


def test_bases_projected_together_are_each_ones(monkeypatch):
    """candidate_bases (all forms projected off the model at once, in batches) gives each
    form's candidate_basis: one-column, two-column and shaped candidates, a form inside the
    model's range (no direction left), and batches of one column."""
    rng = np.random.default_rng(5)
    n, f = 80, 2
    model = rng.standard_normal((n, f, 4))
    fit = WeightedLinearModel(model, rng.standard_normal((n, f))).fit(np.array([1.0, 3.0]))
    inside = model[:, :, :1] * 2.0
    cands = [S.Candidate("offset", "q1", ("a",), rng.standard_normal((n, f, 1))),
             S.Candidate("spring", "q1", ("k", "kq0"), rng.standard_normal((n, f, 2))),
             S.Candidate("smooth", "q2", ("fc",), inside, (inside, rng.standard_normal((n, f, 1))),
                       ({"v": 1.0}, {"v": 2.0}), {"v": 1.0})]
    for batch in (W.BATCH_BYTES, 8 * n * f):
        monkeypatch.setattr(W, "BATCH_BYTES", batch)
        together = S.candidate_bases(cands, fit)
        each = [[W.candidate_basis(c, fit)] if not c.variants else [W.candidate_basis(v, fit) for v in c.variants]
                for c in cands]
        assert [[b.shape for b in forms] for forms in together] == [[(n * f, 1)], [(n * f, 2)], [(n * f, 0), (n * f, 1)]]
        for forms, expected in zip(together, each):
            for b, e in zip(forms, expected):
                assert b.shape == e.shape and np.allclose(b @ b.T, e @ e.T, atol=1e-12)


def test_zero_phase_skips_zero_columns_and_equals_sosfiltfilt():
    sos = butter(4, 0.05, output="sos")
    rng = np.random.default_rng(6)
    x = rng.standard_normal((3000, 4, 3))
    x[:, 1, :] = 0.0
    x[:, :, 2] = 0.0
    assert np.array_equal(zero_phase(sos, x), sosfiltfilt(sos, x, axis=0))
    assert np.array_equal(zero_phase(sos, np.zeros((100, 2))), np.zeros((100, 2)))
    # only the kept rows (a segment's decimation), by slice or by index; many columns
    rows = slice(40, 3000 - 40, 7)
    assert np.array_equal(zero_phase(sos, x, rows), sosfiltfilt(sos, x, axis=0)[rows])
    index = np.arange(3000)[rows]
    assert np.array_equal(zero_phase(sos, x, index), sosfiltfilt(sos, x, axis=0)[index])
    wide = rng.standard_normal((500, 40))
    wide[:, ::3] = 0.0
    assert np.array_equal(zero_phase(sos, wide, rows), sosfiltfilt(sos, wide, axis=0)[rows])


def test_zero_phase_in_batches_of_columns_is_the_same_filter(monkeypatch):
    """The filter takes the columns a few at a time (bounded memory on long recordings):
    runs of live columns, scattered ones and all of them give sosfiltfilt's numbers exactly."""
    from baseparams.recordings import data as data_module
    sos = butter(4, 0.05, output="sos")
    rng = np.random.default_rng(7)
    x = rng.standard_normal((2000, 3, 7))
    x[:, 0, 1:4] = 0.0                                    # live columns in runs and scattered
    rows = slice(30, 2000 - 30, 9)
    whole = sosfiltfilt(sos, x, axis=0)[rows]
    for width in (1, 2, 5, 21):
        monkeypatch.setattr(data_module, "FILTER_BATCH_BYTES", 8 * 2000 * width)
        assert np.array_equal(zero_phase(sos, x, rows), whole)
        dense = rng.standard_normal((2000, 4))
        assert np.array_equal(zero_phase(sos, dense, rows), sosfiltfilt(sos, dense, axis=0)[rows])


def test_complete_fit_grown_from_a_known_one_is_the_direct_fit():
    """_complete from a known fit whose effects were partly taken out, replaced (a new shape)
    and reordered, with new ones added, equals the direct fit: coefficients in the asked
    order, residual, and what leaving an effect out gives (the shape search's use)."""
    rng = np.random.default_rng(8)
    n, f = 120, 2
    model = rng.standard_normal((n, f, 5))
    y = rng.standard_normal((n, f))
    weights = np.array([0.7, 1.6])
    blocks = [rng.standard_normal((n, f, k)) for k in (1, 2, 1, 1, 2)]
    cands = [S.Candidate("offset", f"q{i}", tuple("abc"[:b.shape[-1]]), b) for i, b in enumerate(blocks)]
    rho = S.Whitening(np.array([0.5, 0.2]))
    for whiten in (S._same, rho):
        first = [0, 1, 2]
        known_fit, _ = S.complete_fit(model, y, cands, first, whiten, weights)
        known = (known_fit, [cands[i].columns for i in first])
        changed = list(cands)
        changed[2] = S.Candidate("offset", "q2", ("a",), rng.standard_normal((n, f, 1)))   # a new shape
        wanted = [2, 0, 4, 3]                                     # 1 taken out, 3 and 4 new, reordered
        grown, offsets = S.complete_fit(model, y, changed, wanted, whiten, weights, known)
        direct, same = S.complete_fit(model, y, changed, wanted, whiten, weights)
        assert S._extended(known, [changed[i].columns for i in wanted], 5, whiten, weights) is not None
        assert np.array_equal(offsets, same)
        assert np.allclose(grown.coefficients, direct.coefficients, rtol=1e-9)
        assert np.allclose(grown.residual, direct.residual, atol=1e-12)
        assert np.allclose(grown.without([6, 7]).residual, direct.without([6, 7]).residual, atol=1e-12)
    assert S._extended(known, [changed[i].columns for i in wanted], 5, rho, weights * 1.1) is None   # other weights


def _window_by_acf(residual: np.ndarray) -> int:
    """hac_lags' rule from statsmodels' acf of each live coordinate (the reference)."""
    from statsmodels.tsa.stattools import acf
    n = len(residual)
    base = longrun.newey_west_lags(n)
    limit = max(base, n // 4)
    if n < 8:
        return base
    live = [c for c in residual.T if np.any(c != np.mean(c))]
    if not live:
        return base
    mean = np.mean([acf(c, nlags=min(limit, n - 1), fft=False) for c in live], axis=0)
    inside = np.nonzero(np.abs(mean[1:]) < 1.96 / np.sqrt(n))[0]
    leading = int(inside[0]) if inside.size else min(limit, n - 1)
    return 0 if leading == 0 else min(limit, max(base, 2 * leading))


@pytest.mark.parametrize("seed", range(3))
def test_windows_of_many_residuals_at_once_are_each_ones(seed):
    """hac_lags_each over m residuals (N, f, m) gives each one's window by the rule computed
    from statsmodels' acf: white to strongly correlated, a dead coordinate, an all-zero
    residual, fewer than 8 samples."""
    rng = np.random.default_rng(10 + seed)
    for n in (5, 60, 700):
        f = int(rng.integers(1, 5))
        stack = np.stack([_ar(rng, n, f, rho) for rho in (0.0, 0.3, 0.7, 0.95, -0.6, 0.0)], axis=2)
        stack[:, 0, 1] = 0.0                      # a coordinate that does not move
        stack[:, :, 5] = 0.0                      # nothing at all
        expected = [_window_by_acf(stack[:, :, j]) for j in range(stack.shape[2])]
        assert list(longrun.hac_lags_each(stack)) == expected
        assert [longrun.hac_lags(stack[:, :, j]) for j in range(stack.shape[2])] == expected


def _long_run_reference(s: np.ndarray, lags: int) -> np.ndarray:
    """Andrews and Monahan's prewhitened Newey-West by lstsq and statsmodels (the reference)."""
    if lags == 0 or len(s) < 20:
        return S_hac_simple(s, nlags=lags)
    before, after = s[:-1], s[1:]
    At, *_ = np.linalg.lstsq(before, after, rcond=None)
    u, sv, vt = np.linalg.svd(At.T)
    A = (u * np.minimum(sv, longrun.PREWHITEN_LIMIT)) @ vt
    e = after - before @ A.T
    B = np.linalg.inv(np.eye(s.shape[1]) - A)
    return B @ S_hac_simple(e, nlags=_window_by_acf(e)) @ B.T


@pytest.mark.parametrize("r", [1, 2, 4])
def test_long_runs_of_many_score_series_at_once_are_each_ones(r):
    """long_run_each over m series (m, n, r) with their own lags equals the reference for
    each: prewhitened (white to a unit root), lags 0, too few samples, not prewhitened."""
    rng = np.random.default_rng(r)
    for n in (15, 400):
        scores = np.stack([_ar(rng, n, r, rho) for rho in (0.0, 0.5, 0.9, 1.0, -0.99, 0.3)])
        lags = np.array([0, 3, 7, 5, 2, 0])
        got = longrun.long_run_each(scores, lags)
        for j in range(len(scores)):
            assert got[j] == pytest.approx(_long_run_reference(scores[j], int(lags[j])), rel=1e-9, abs=1e-12)
        plain = longrun.long_run_each(scores, lags, prewhiten=False)
        for j in range(len(scores)):
            assert plain[j] == pytest.approx(S_hac_simple(scores[j], nlags=int(lags[j])), rel=1e-12)


def _dense_reference(residual, basis, shape, dof, lags, extra_df=0):
    """The HAC Wald statistic and p value written out (the reference for wald's dense path)."""
    from scipy import stats
    n, f = shape
    r = basis.shape[1]
    gamma = basis.T @ residual
    augmented = residual - basis @ gamma
    lags = _window_by_acf(augmented.reshape(n, f)) if lags is None else lags
    scores = (basis * augmented[:, None]).reshape(n, f, r).sum(axis=1)
    rows = n * f
    V = _long_run_reference(scores, lags) * rows / (rows - dof - r)
    if lags == 0:
        values, vectors = np.linalg.eigh(V)
        V = (vectors * np.maximum(values, augmented @ augmented / (rows - dof - r))) @ vectors.T
    stat = float(gamma @ np.linalg.solve(V, gamma))
    k = r + extra_df
    return stat, float(stats.f.sf(stat / k, k, n - int(np.ceil(dof / f)) - r)), lags


@pytest.mark.parametrize("rho", [0.0, 0.8])
def test_wald_tests_of_many_forms_at_once_are_each_ones(rho):
    """wald_each on forms of 0, 1, 2 and 3 directions, some acting on few samples, each with
    its own residual and null model: each test equals wald alone, and the dense ones the
    statistic written out (HAC with its window, White's never below the classical variance)."""
    rng = np.random.default_rng(int(rho * 10))
    n, f, dof = 300, 2, 7
    shape, rows = (n, f), n * f
    Q, _ = np.linalg.qr(rng.standard_normal((rows, dof)))
    bases, residuals = [], []
    for width in (1, 2, 1, 3, 0, 1, 2):
        X = rng.standard_normal((rows, width))
        if len(bases) in (2, 6):                  # a step: acts on a few samples only
            X[30:] = 0.0
        X -= Q @ (Q.T @ X)
        bases.append(W.orthonormal_basis(X, W.ABSORB_TOL) if width else np.zeros((rows, 0)))
        e = _ar(rng, n, f, rho).reshape(rows) + (X @ rng.standard_normal(width) * 0.1 if width else 0.0)
        residuals.append(e - Q @ (Q.T @ e))
    dofs = [dof + j for j in range(len(bases))]
    extra = [j % 2 for j in range(len(bases))]
    for sparse in (False, True):
        tests = W.wald_each(residuals, bases, shape, dofs, None, extra, sparse_if_white=sparse,
                            sparse_if_coloured=sparse)
        alone = [W.wald(e, b, shape, d, extra_df=x, sparse_if_white=sparse, sparse_if_coloured=sparse)
                 for e, b, d, x in zip(residuals, bases, dofs, extra)]
        assert [(t.df, t.reason, t.lags) for t in tests] == [(t.df, t.reason, t.lags) for t in alone]
        for t, a in zip(tests, alone):
            assert t.stat == pytest.approx(a.stat, rel=1e-9) and t.pvalue == pytest.approx(a.pvalue, rel=1e-8, abs=1e-300)
    tests = W.wald_each(residuals, bases, shape, dofs, None, extra)
    assert [t.reason for t in tests] == ["", "", "support", "", "absorbed", "", "support"]
    for j in (0, 1, 3, 5):
        stat, p, lags = _dense_reference(residuals[j], bases[j], shape, dofs[j], None, extra[j])
        assert tests[j].lags == lags
        assert tests[j].stat == pytest.approx(stat, rel=1e-9) and tests[j].pvalue == pytest.approx(p, rel=1e-7)
    # one residual for all, a given window
    shared = W.wald_each([residuals[0]], bases, shape, [dof], 4, [0])
    for j in (0, 1, 3, 5):
        stat, p, _ = _dense_reference(residuals[0], bases[j], shape, dof, 4)
        assert shared[j].stat == pytest.approx(stat, rel=1e-9) and shared[j].lags == 4


def test_encompassing_with_many_rivals_at_once_is_each_pairs():
    """encompassing_each of one winner with several rivals equals encompassing pair by pair."""
    rng = np.random.default_rng(12)
    n, f = 250, 3
    rows = n * f
    residual = _ar(rng, n, f, 0.5).reshape(rows)
    a = W.orthonormal_basis(rng.standard_normal((rows, 1)), W.ABSORB_TOL)
    rivals = [W.orthonormal_basis(a + 0.3 * rng.standard_normal((rows, 1)), W.ABSORB_TOL),
              W.orthonormal_basis(rng.standard_normal((rows, 2)), W.ABSORB_TOL), a.copy()]
    together = W.encompassing_each(a, rivals, residual, (n, f), 5, sparse_if_coloured=True)
    for (t_ab, t_ba), b in zip(together, rivals):
        o_ab, o_ba = W.encompassing(a, b, residual, (n, f), 5, sparse_if_coloured=True)
        for t, o in ((t_ab, o_ab), (t_ba, o_ba)):
            assert (t.df, t.reason, t.lags) == (o.df, o.reason, o.lags)
            assert t.stat == pytest.approx(o.stat, rel=1e-9)
    assert together[2][0].reason == "absorbed" and together[2][1].reason == "absorbed"
