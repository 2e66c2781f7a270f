"""The diagnosis' tests of a set of directions depend on the subspace, not on the orthonormal
basis an SVD happened to return for it (issue 42: on a PUMA step four bases of one subspace
gave Wald statistics from 51,700 to 99,000 and supports from 18 to 96 samples)."""

import numpy as np
import pytest

from baseparams.diagnose.wald import support, wald


def _subspace(rng, n: int, f: int, r: int, sparse: bool) -> np.ndarray:
    """An orthonormal basis (n f, r) of directions; ``sparse``: concentrated on a few samples."""
    raw = rng.standard_normal((n * f, r))
    if sparse:
        raw *= (rng.random((n * f, 1)) < 0.02) * 5 + 0.01
    return np.linalg.qr(raw)[0]


def _rotations(rng, r: int, count: int = 4):
    return [np.eye(r)] + [np.linalg.qr(rng.standard_normal((r, r)))[0] for _ in range(count - 1)]


@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("coloured", [False, True])
def test_wald_and_support_do_not_depend_on_the_basis(sparse, coloured):
    rng = np.random.default_rng(4)
    n, f, r = 600, 3, 5
    basis = _subspace(rng, n, f, r, sparse)
    noise = rng.standard_normal((n, f))
    if coloured:                                          # AR(1) 0.9 along time
        for t in range(1, n):
            noise[t] += 0.9 * noise[t - 1]
    residual = noise.reshape(-1) + basis @ rng.standard_normal(r) * 0.3
    residual -= basis @ (basis.T @ residual) * 0.5        # some of it along the directions
    stats, supports = [], []
    for Q in _rotations(rng, r):
        test = wald(residual, basis @ Q, (n, f), dof=10, sparse_if_white=True, sparse_if_coloured=True)
        stats.append(test.stat)
        supports.append(support(basis @ Q, (n, f)))
    assert np.allclose(stats, stats[0], rtol=1e-8), stats
    assert np.allclose(supports, supports[0], rtol=1e-8), supports


def test_the_support_finds_a_concentrated_direction_hidden_among_spread_ones():
    """A direction on 5 samples mixed with four spread over all: every basis of the subspace
    has each direction spread (a random rotation mixes them), yet the subspace holds one that
    acts on 5 samples."""
    rng = np.random.default_rng(1)
    n, f = 1000, 1
    spike = np.zeros((n, 1))
    spike[100:105] = 1.0
    basis = np.linalg.qr(np.hstack([spike, rng.standard_normal((n, 4))]))[0]
    mixed = basis @ np.linalg.qr(rng.standard_normal((5, 5)))[0]
    assert support(mixed, (n, f)) == pytest.approx(5.0, rel=0.05)
