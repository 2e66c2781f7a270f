"""BaseModel.columns (K_b = K B^+) from B^+ computed once (issue 47), against the least-squares
solve per K it replaced and against the closed form B^+ = B^T (B B^T)^-1; residual_outside
with K_b given equals it computed, and measures a K outside B's row space."""

import numpy as np
import scipy.linalg

from baseparams.identify.base import BaseModel


def model(seed: int = 2) -> BaseModel:
    """A solver-like B: each row one kept parameter (1) plus a few eliminated ones, some of
    them large (coefficients of 1e3), 7 base parameters of 12 standard ones."""
    rng = np.random.default_rng(seed)
    B = np.zeros((7, 12))
    kept = [0, 1, 3, 4, 6, 8, 9]
    for row, k in enumerate(kept):
        B[row, k] = 1.0
    eliminated = [2, 5, 7, 10, 11]
    for row in range(7):
        for j in rng.choice(eliminated, size=2, replace=False):
            B[row, j] = rng.choice([-1, 1]) * 10.0 ** rng.integers(-3, 4)
    return BaseModel(tuple(f"phi_b{k}" for k in range(7)), tuple(f"p{j}" for j in range(12)), B)


def test_columns_equal_the_least_squares_solve_and_the_closed_form():
    base = model()
    rng = np.random.default_rng(5)
    K = rng.standard_normal((40, 3, 7)) @ base.B                      # rows in B's row space
    got = base.columns(K)
    assert got.shape == (40, 3, 7)
    flat = K.reshape(-1, 12)
    solved = scipy.linalg.lstsq(base.B.T, flat.T, lapack_driver="gelsy")[0].T.reshape(40, 3, 7)
    closed = (flat @ base.B.T @ np.linalg.inv(base.B @ base.B.T)).reshape(40, 3, 7)
    scale = np.abs(solved).max()
    assert np.abs(got - solved).max() <= 1e-12 * scale
    assert np.abs(got - closed).max() <= 1e-9 * scale
    # K phi = K_b (B phi) for every phi, as the base model promises
    phi = rng.standard_normal(12)
    assert np.allclose(K @ phi, got @ (base.B @ phi), rtol=0, atol=1e-10 * np.abs(K @ phi).max())


def test_residual_outside_with_the_columns_given_and_outside_the_row_space():
    base = model()
    rng = np.random.default_rng(6)
    K = rng.standard_normal((30, 7)) @ base.B
    assert base.residual_outside(K) < 1e-14
    assert base.residual_outside(K, base.columns(K)) == base.residual_outside(K)
    off = K.copy()
    null = scipy.linalg.null_space(base.B)[:, 0]                      # a direction B cannot see
    off[0] += 0.1 * np.linalg.norm(K) * null
    expected = np.linalg.norm(0.1 * np.linalg.norm(K) * null) / np.linalg.norm(off)
    assert abs(base.residual_outside(off) - expected) <= 1e-10 * expected


def test_no_base_parameter():
    base = BaseModel((), ("a", "b"), np.zeros((0, 2)))
    assert base.columns(np.ones((4, 2))).shape == (4, 0)
    assert base.residual_outside(np.ones((4, 2))) == 1.0
