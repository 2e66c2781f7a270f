"""The Gram route of thin_svd for rank-deficient tall matrices (core/numeric/linalg.py,
_gram_svd, inside gram_route()): exactly collinear columns factored from the Gram matrix's eigenvectors and a
Cholesky QR instead of Householder QR, checked against LAPACK's SVD; and the cases it must
leave to Householder QR (a singular value between the kept and the dropped groups, or a
``keep`` that counts otherwise)."""

import numpy as np
import pytest

import baseparams.numeric.linalg as linalg
from baseparams.numeric.linalg import _gram_svd, _householder_svd, gram_route, thin_svd


def collinear(rows: int, columns: int, rank: int, smallest: float, seed: int) -> np.ndarray:
    """rows x columns of the given rank (columns beyond it exact combinations of others), its
    nonzero singular values log-even from 1 to ``smallest``, columns of unit norm."""
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.standard_normal((rows, rank)))
    v, _ = np.linalg.qr(rng.standard_normal((columns, rank)))
    a = (u * np.logspace(0, np.log10(smallest), rank)) @ v.T
    return a / np.linalg.norm(a, axis=0)


@pytest.mark.parametrize("columns, rank, smallest", [(40, 25, 1e-3), (84, 61, 2e-3), (10, 7, 0.3), (12, 12, 1e-2)])
def test_the_gram_route_is_lapacks_svd(columns, rank, smallest, monkeypatch):
    a = collinear(4000, columns, rank, smallest, seed=columns)
    keep = lambda s: int(np.sum(s > 1e-9 * s[0]))                      # noqa: E731
    monkeypatch.setattr(linalg, "_householder_svd", None)              # the route must not be left
    with gram_route():
        u, s, vt = thin_svd(a, keep=keep, zero_column=rank == columns)  # a full-rank one sent here at once
    u0, s0, vt0 = np.linalg.svd(a, full_matrices=False)
    k = keep(s0)
    assert k == rank and u.shape == (4000, k) and vt.shape == vt0.shape
    assert np.allclose(s, s0, rtol=0, atol=1e-14 * s0[0])
    assert np.all(np.diff(s) <= 0)
    assert np.allclose(u.T @ u, np.eye(k), rtol=0, atol=1e-14)
    assert np.allclose(vt @ vt.T, np.eye(columns), rtol=0, atol=1e-14)
    x = np.random.default_rng(0).standard_normal(4000)
    assert np.allclose(u @ (u.T @ x), u0[:, :k] @ (u0[:, :k].T @ x), rtol=0, atol=1e-13 * s0[0] / s0[k - 1])
    assert np.allclose((u * s[:k]) @ vt[:k], a, rtol=0, atol=1e-13)
    null, null0 = vt[k:], vt0[k:]
    assert np.allclose(null.T @ (null @ null0.T), null0.T, rtol=0, atol=1e-12)
    assert np.allclose(s[k:], np.linalg.norm(a @ null.T, axis=0), rtol=1e-6)   # ||a w|| of each dropped w


def test_a_singular_value_between_the_groups_goes_to_householder():
    """1e-7 of the largest: below what the Gram matrix resolves (1e-5), above what the route
    drops (1e-10): Householder QR decides, and thin_svd's result is its own."""
    a = collinear(3000, 20, 15, 1e-3, seed=1)
    a = np.concatenate([a, a[:, :1] + 1e-7 * np.random.default_rng(2).standard_normal((3000, 1)) / np.sqrt(3000)], axis=1)
    keep = lambda s: int(np.sum(s > 1e-9 * s[0]))                      # noqa: E731
    assert _gram_svd(a, keep) is None
    with gram_route():
        for x, y in zip(thin_svd(a, keep=keep), _householder_svd(a, keep)):
            assert np.array_equal(x, y)
        assert keep(thin_svd(a, keep=keep)[1]) == 16


def test_a_keep_that_counts_otherwise_goes_to_householder():
    a = collinear(3000, 20, 15, 1e-3, seed=3)
    assert _gram_svd(a, lambda s: int(np.sum(s > 1e-9 * s[0]))) is not None
    fewer = lambda s: int(np.sum(s > 1e-2 * s[0]))                      # noqa: E731
    assert _gram_svd(a, fewer) is None
    with gram_route():
        u, s, _ = thin_svd(a, keep=fewer)
    assert u.shape[1] == fewer(s) < 15


def test_only_inside_the_context():
    """Outside gram_route() (identify, diagnose --params) the factors are Householder's, bit for
    bit; inside, the Gram route's; and the context is left as it was after an error."""
    a = collinear(3000, 20, 15, 1e-3, seed=4)
    keep = lambda s: int(np.sum(s > 1e-9 * s[0]))                      # noqa: E731
    for x, y in zip(thin_svd(a, keep=keep), _householder_svd(a, keep)):
        assert np.array_equal(x, y)
    with gram_route():
        inside = thin_svd(a, keep=keep)
    for x, y in zip(inside, _gram_svd(a, keep)):
        assert np.array_equal(x, y)
    with pytest.raises(ValueError), gram_route():
        raise ValueError
    for x, y in zip(thin_svd(a, keep=keep), _householder_svd(a, keep)):
        assert np.array_equal(x, y)
