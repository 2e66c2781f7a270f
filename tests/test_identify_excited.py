"""identify's excitation check of the base columns (issue 47): when the fit has no effect
columns, the weighted fit's singular values prove it (:func:`baseparams.identify.fit._excited`)
and the pivoted QR of the unweighted columns is not formed; when they do not, the QR decides
and refuses with the message it always gave."""

import numpy as np
import pytest
import scipy.linalg

import baseparams as bp
from baseparams.errors import InputError
from baseparams.identify import fit as fitting
from baseparams.identify.linear import WeightedLinearModel


@pytest.mark.parametrize("seed", range(6))
def test_the_bound_is_below_every_pivot_of_the_unweighted_qr(seed):
    """s_min(A) >= s_min(X) min w / max w for the unit-norm unweighted columns A and the fit's
    weighted unit-norm X, and every pivot of A's QR is at least s_min(A): checked with
    LAPACK's SVD and QR on columns of very different sizes and weights, some nearly dependent."""
    rng = np.random.default_rng(seed)
    n, f, p = 60, 4, 9
    model = rng.standard_normal((n, f, p)) * 10.0 ** rng.uniform(-3, 3, p)
    model[:, :, -1] = model[:, :, 0] + 10.0 ** -rng.uniform(2, 8) * rng.standard_normal((n, f))
    weights = 10.0 ** rng.uniform(-2, 2, f)
    y = model @ rng.standard_normal(p) + rng.standard_normal((n, f))
    fit = WeightedLinearModel(model, y).fit(weights)
    A = model.reshape(n * f, p)
    A = A / np.linalg.norm(A, axis=0)
    smallest = np.linalg.svd(A, compute_uv=False)[-1]
    bound = fit.singular_values[-1] * weights.min() / weights.max()
    assert smallest >= bound * (1 - 1e-12)
    pivots = np.abs(np.diag(scipy.linalg.qr(A, mode="r", pivoting=True)[0]))
    assert pivots.min() >= smallest * (1 - 1e-9)
    assert fitting._excited(fit) is bool(bound > fitting.PROVEN_EXCITED)


def test_proven_fit_skips_the_qr_and_gives_the_same_result(tmp_path, monkeypatch):
    data = tmp_path / "data.csv"
    bp.simulate("planar_2r", output=str(data), noise=0.01)
    before = bp.identify("planar_2r", str(data)).to_json()
    calls = []
    original = fitting._independent
    monkeypatch.setattr(fitting, "_independent", lambda *a: calls.append(1) or original(*a))
    assert bp.identify("planar_2r", str(data)).to_json() == before and not calls
    bp.identify("planar_2r", str(data), effects=["viscous_friction:*"])         # effect columns: the QR
    assert calls


def _still(path):
    """A pendulum held at one angle with a constant acceleration on record: each base column is
    constant, so every column is a multiple of every other."""
    t = np.arange(0, 4, 0.01)
    tau = np.random.default_rng(1).normal(0, 0.01, len(t))
    one = np.ones_like(t)
    np.savetxt(path, np.column_stack([t, 0.3 * one, 0 * one, one, tau]), delimiter=",",
               header="t,q_theta,qd_theta,qdd_theta,tau_theta", comments="")


def test_dependent_base_columns_are_refused_as_before(tmp_path, monkeypatch):
    data = tmp_path / "still.csv"
    _still(data)
    calls = []
    original = fitting._independent
    monkeypatch.setattr(fitting, "_independent", lambda *a: calls.append(1) or original(*a))
    with pytest.raises(InputError, match=r"these data do not excite the base parameters phi_b0\d(, phi_b0\d)* \(the columns are "
                                         r"dependent on this trajectory\)"):
        bp.identify("pendulum", str(data))
    assert calls
