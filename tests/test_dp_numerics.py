"""dp's SVD degrades gracefully: economy SVD for tall W (memory rows x n, not rows x rows),
full V for wide W, extreme column scales, and KinematicsError (never numpy's LinAlgError)
for a non-finite W or an SVD that does not converge. Results are checked against the
defining relation W2 = W1 beta (independent of the SVD)."""

import numpy as np
import pytest

from baseparams.errors import KinematicsError
from baseparams.plugins.solvers.dp import gautier
from baseparams.plugins.solvers.dp.gautier import dp_gautier


def dependent_matrix(rows, rank, n, seed=0):
    """rows x n, exact rank ``rank``: the last n - rank columns combine the first ones."""
    rng = np.random.default_rng(seed)
    first = rng.standard_normal((rows, rank))
    return np.hstack([first, first @ rng.standard_normal((rank, n - rank))])


def assert_base_relation(W, res):
    """Gautier's base parameters: W phi = W1 (phi_1 + beta phi_2), i.e. W2 = W1 beta."""
    W1, W2 = W[:, res.kept], W[:, res.eliminated]
    assert np.allclose(W2, W1 @ res.beta, rtol=1e-9, atol=1e-9 * np.abs(W).max())


def test_tall_matrix_uses_the_economy_svd():
    """100,000 x 10: a full SVD would allocate U of 74.5 GiB and fail."""
    W = dependent_matrix(100_000, 4, 10)
    res = dp_gautier(W)
    assert res.rank == 4 and len(res.eliminated) == 6
    assert len(res.singular_values) == 10
    assert_base_relation(W, res)


def test_wide_matrix_still_gets_the_whole_null_space():
    W = dependent_matrix(3, 3, 10)
    res = dp_gautier(W)
    assert res.rank == 3 and len(res.eliminated) == 7
    assert_base_relation(W, res)


def test_singular_values_agree_with_numpy():
    W = dependent_matrix(50, 5, 8, seed=3)
    res = dp_gautier(W, scale=False)
    assert np.allclose(res.singular_values, np.linalg.svd(W, compute_uv=False), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("size", [1e200, 1e-200])
def test_extreme_magnitudes_do_not_overflow(size):
    """Entries near 1e+-200: sums of squares would overflow to inf or underflow to 0."""
    W = dependent_matrix(40, 3, 5, seed=1) * size
    assert not np.isfinite(np.linalg.norm(W, axis=0)).all() or np.linalg.norm(W, axis=0).min() == 0
    res = dp_gautier(W)
    assert res.rank == 3
    assert not res.zero_columns
    assert np.allclose(W[:, res.eliminated] / size, W[:, res.kept] / size @ res.beta)


def test_non_finite_matrix_is_a_kinematics_error_naming_columns():
    W = dependent_matrix(20, 2, 4)
    W[5, 1] = np.nan
    W[7, 3] = np.inf
    with pytest.raises(KinematicsError) as info:
        dp_gautier(W, columns=["m1", "mx1", "my1", "mz1"])
    message = str(info.value)
    assert "2 non-finite entries" in message and "2 of 20 rows" in message
    assert "mx1, mz1" in message and "degenerate axis" in message


def test_svd_non_convergence_is_a_kinematics_error(monkeypatch):
    import scipy.linalg

    def fails(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")
    monkeypatch.setattr(gautier.np.linalg, "svd", fails)
    monkeypatch.setattr(scipy.linalg, "svd", fails)
    with pytest.raises(KinematicsError, match="did not converge"):
        dp_gautier(dependent_matrix(10, 2, 4))


def test_divide_and_conquer_failure_falls_back_to_qr_iteration(monkeypatch):
    """numpy's gesdd can fail to converge where gesvd does not (so100's stacked W):
    the result is then the same as with a working gesdd."""
    W = dependent_matrix(30, 3, 6, seed=2)
    expected = dp_gautier(W)

    def fails(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")
    monkeypatch.setattr(gautier.np.linalg, "svd", fails)
    res = dp_gautier(W)
    assert res.rank == expected.rank == 3
    assert np.allclose(res.singular_values, expected.singular_values, rtol=1e-12)
    assert_base_relation(W, res)


def test_small_equal_columns_are_not_lifted_into_the_rank():
    """Two columns of norm 1e-5 of W's equal up to W's rounding (so100's mx1 and mx2): scaled to
    norm 1 their difference would count as a direction; in the parameters' units it is below
    W's rounding level, so the rank is that of the unscaled W. A small column that is not
    a copy (independent, same norm) still counts."""
    rng = np.random.default_rng(4)
    W = dependent_matrix(200, 5, 8, seed=5)
    small = 1e-5 * rng.standard_normal(200)
    twin = small + 1e-14 * np.abs(W).max() * rng.standard_normal(200) / np.sqrt(200)
    lifted = np.column_stack([W, small, twin])
    res = dp_gautier(lifted)
    unscaled = np.linalg.matrix_rank(lifted)
    assert res.rank == unscaled == 6 and res.lifted == 1
    assert set(res.lifted_columns) == {"8", "9"}
    assert dp_gautier(lifted, scale=False).rank == 6
    independent = np.column_stack([W, small, 1e-5 * rng.standard_normal(200)])
    res = dp_gautier(independent)
    assert res.rank == 7 and res.lifted == 0
