"""The SVD that does not stop where LAPACK's divide and conquer fails to converge
(baseparams.numeric.linalg.svd): numpy's result, bit for bit, when gesdd converges; the QR
iteration's (gesvd) when it does not, and the weighted fits built on it give the same
numbers to rounding either way.

Why: a real recording (Kinova Gen3, the joint-torque-sensor channels) stopped diagnose with
numpy's "SVD did not converge" in the cross-validation's fit: a finite 2541 x 119 regressor
with 7 zero columns and singular values down to 1e-20 of the largest, on which gesdd fails
for those exact bits (a relative change of 1e-16 lets it converge) and gesvd does not. Such
a matrix cannot be kept small and portable (which bits fail depends on the LAPACK build), so
the failure is forced here by making numpy's SVD raise."""

import numpy as np
import pytest

from baseparams.diagnose.workflow import reduced_model
from baseparams.identify.linear import WeightedLinearModel
from baseparams.identify.longrun import long_run_each
from baseparams.diagnose.wald import orthonormal_basis
from baseparams.numeric.linalg import svd

NUMPY_SVD = np.linalg.svd


class Failing:
    """np.linalg.svd that raises LinAlgError on the calls ``fail`` selects (all when None),
    counting how often it did: the failure path taken on demand."""

    def __init__(self, fail=None):
        self.fail, self.calls, self.failed = fail, 0, 0

    def __call__(self, a, *args, **kwargs):
        self.calls += 1
        if self.fail is None or self.calls in self.fail:
            self.failed += 1
            raise np.linalg.LinAlgError("SVD did not converge")
        return NUMPY_SVD(a, *args, **kwargs)


def rank_deficient_problem(seed=0, n=300, f=3):
    """A regressor like a robot's: columns on scales from 1e-3 to 1e3, an exactly zero
    column, two columns that are combinations of others (structural rank deficiency), and
    noise of a different level on each coordinate."""
    rng = np.random.default_rng(seed)
    p = 9
    model = rng.standard_normal((n, f, p)) * (10.0 ** np.linspace(-3, 3, p))
    model[:, :, 4] = 0.0
    model[:, :, 7] = 2.0 * model[:, :, 1] - 0.5 * model[:, :, 2]
    model[:, :, 8] = model[:, :, 0] + model[:, :, 3]
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f)) * np.array([0.3, 1.0, 3.0])[:f]
    return model, y


def same_fit(a, b, rtol=1e-9):
    """Two fits agree to rounding on everything that does not depend on the singular
    vectors' signs (the factorisation differs, the least-squares answer does not)."""
    assert a.rank == b.rank
    np.testing.assert_allclose(a.weights, b.weights, rtol=rtol)
    np.testing.assert_allclose(a.singular_values[:a.rank], b.singular_values[:b.rank], rtol=rtol)
    scale = np.max(np.abs(a.coefficients))
    np.testing.assert_allclose(a.coefficients, b.coefficients, rtol=rtol, atol=rtol * scale)
    np.testing.assert_allclose(a.residual, b.residual, rtol=rtol, atol=rtol * np.max(np.abs(a.residual)))
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-7, atol=1e-7 * np.max(np.abs(a.covariance)))


def test_the_helper_is_numpys_svd_bit_for_bit_when_gesdd_converges():
    rng = np.random.default_rng(1)
    for a in (rng.standard_normal((40, 7)), rng.standard_normal((7, 40)), rng.standard_normal((5, 6, 4))):
        for full in (True, False):
            for got, want in zip(svd(a, full_matrices=full), NUMPY_SVD(a, full_matrices=full)):
                assert np.array_equal(got, want)
        assert np.array_equal(svd(a, compute_uv=False), NUMPY_SVD(a, compute_uv=False))


@pytest.mark.parametrize("shape", [(40, 7), (7, 40), (5, 6, 4), (2, 3, 4, 3)])
@pytest.mark.parametrize("full", [True, False])
def test_after_a_gesdd_failure_the_helper_returns_an_svd_of_the_same_matrix(monkeypatch, shape, full):
    """The gesvd answer: the same shapes as numpy's, the same singular values to rounding,
    orthonormal factors that rebuild the matrix (stacked matrices one by one)."""
    a = np.random.default_rng(2).standard_normal(shape)
    want_u, want_s, want_vt = NUMPY_SVD(a, full_matrices=full)
    failing = Failing()
    monkeypatch.setattr(np.linalg, "svd", failing)
    u, s, vt = svd(a, full_matrices=full)
    assert failing.failed == 1
    assert (u.shape, s.shape, vt.shape) == (want_u.shape, want_s.shape, want_vt.shape)
    np.testing.assert_allclose(s, want_s, rtol=1e-12)
    k = s.shape[-1]
    rebuilt = (u[..., :k] * s[..., None, :]) @ vt[..., :k, :]
    np.testing.assert_allclose(rebuilt, a, atol=1e-12)
    np.testing.assert_allclose(np.swapaxes(u, -1, -2) @ u, np.broadcast_to(np.eye(u.shape[-1]), u.shape[:-2] + (u.shape[-1],) * 2), atol=1e-12)
    np.testing.assert_allclose(svd(a, compute_uv=False), want_s, rtol=1e-12)


def test_a_matrix_with_nan_still_raises_and_so_does_one_gesvd_cannot_factor(monkeypatch):
    """The fallback is for LAPACK's convergence, not for bad input: NaN raises numpy's error
    as before; and if the QR iteration fails too, numpy's error is what the caller sees."""
    bad = np.ones((5, 3))
    bad[2, 1] = np.nan
    with pytest.raises(np.linalg.LinAlgError):
        svd(bad)
    import scipy.linalg

    def also_failing(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(np.linalg, "svd", Failing())
    monkeypatch.setattr(scipy.linalg, "svd", also_failing)
    with pytest.raises(np.linalg.LinAlgError, match="did not converge"):
        svd(np.eye(3))


@pytest.mark.parametrize("fail", [{1}, None], ids=["first call fails", "every call fails"])
@pytest.mark.parametrize("weights", [np.array([1.0, 0.4, 2.5]), None], ids=["given weights", "Gautier's weights"])
def test_a_fit_whose_svd_fails_to_converge_is_the_normal_fit(monkeypatch, fail, weights):
    """The weighted fit (and at Gautier's fixed point, whose passes refit from the last
    fit's factors: reweighted's SVD of the core) gives the same rank, coefficients,
    residual and covariance to rounding when numpy's SVD raises."""
    model, y = rank_deficient_problem()
    normal = WeightedLinearModel(model, y).fit(weights)
    assert normal.rank == 6                 # 9 columns: one zero, two combinations
    failing = Failing(fail)
    monkeypatch.setattr(np.linalg, "svd", failing)
    fallback = WeightedLinearModel(model, y).fit(weights)
    assert failing.failed >= 1
    same_fit(fallback, normal)


def test_the_fits_from_factors_are_the_normal_ones_when_their_svd_fails(monkeypatch):
    """extended, subset and reweighted factor a small core again: the same with gesvd."""
    model, y = rank_deficient_problem(seed=3)
    keep = [0, 1, 2, 3, 5, 6]                       # full rank, so the updates apply
    small, extra = model[:, :, keep], model[:, :, [4, 7]]
    weights = np.array([1.0, 0.5, 2.0])
    base = WeightedLinearModel(small, y).fit(weights)
    n, f, _ = extra.shape
    columns = (extra * weights[None, :, None]).reshape(n * f, -1)
    normal = (base.extended(columns), base.subset([0, 2, 4]), base.reweighted(weights * 1.01))
    assert all(fit is not None for fit in normal)
    monkeypatch.setattr(np.linalg, "svd", Failing())
    fallback = (base.extended(columns), base.subset([0, 2, 4]), base.reweighted(weights * 1.01))
    for a, b in zip(fallback, normal):
        same_fit(a, b)


def test_the_other_data_svds_take_the_fallback(monkeypatch):
    """diagnose's reduced model, selection's orthonormal basis and the prewhitened long-run
    covariance (stacked 2 x 2 SVDs) span and give the same with gesvd."""
    model, y = rank_deficient_problem(seed=5)
    rng = np.random.default_rng(6)
    scores = rng.standard_normal((4, 200, 2))
    scores[:, 1:] += 0.6 * scores[:, :-1]
    matrix = model.reshape(-1, model.shape[2])
    normal_reduced = reduced_model(model, 200)
    normal_basis = orthonormal_basis(matrix, 1e-10)
    normal_long = long_run_each(scores, np.array([3, 3, 3, 3]))
    failing = Failing()
    monkeypatch.setattr(np.linalg, "svd", failing)
    reduced, basis, long = reduced_model(model, 200), orthonormal_basis(matrix, 1e-10), long_run_each(scores, np.array([3, 3, 3, 3]))
    assert failing.failed >= 3
    assert reduced.shape == normal_reduced.shape and basis.shape == normal_basis.shape

    def projector(q):
        q = q.reshape(-1, q.shape[-1])
        q = np.linalg.qr(q)[0]
        return q @ q.T

    np.testing.assert_allclose(projector(reduced), projector(normal_reduced), atol=1e-9)
    np.testing.assert_allclose(basis @ basis.T, normal_basis @ normal_basis.T, atol=1e-9)
    np.testing.assert_allclose(long, normal_long, rtol=1e-9)

