"""Selection's backward passes (elimination of a named effect the later ones explain; an
ambiguous group compared again in the complete model), its rule for rivals that add over
each other, and the classical test of sparse directions: against constructions whose answer
is known, statsmodels, and the SLA case they were made for."""

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from scipy import stats
from scipy.signal import lfilter

from baseparams.identify import longrun
from baseparams.diagnose import selection as S
from baseparams.diagnose import wald as W
from baseparams.identify.linear import WeightedLinearModel
from baseparams.diagnose.problem import prepare
from baseparams.diagnose.workflow import diagnose
from baseparams.dynamics.forces import evaluate
from baseparams.recordings.simulate import random_physical_inertia, trajectory_motion
from baseparams.io.loader import resolve


def _smooth(n: int) -> np.ndarray:
    """A small 'inertial model': smooth functions of time, one coordinate (n, 1, 3)."""
    t = np.linspace(0.0, 10.0, n)
    return np.stack([np.ones(n), np.sin(t), np.cos(0.7 * t)], axis=1)[:, None, :]


def _candidate(label: str, column: np.ndarray) -> S.Candidate:
    kind, coordinate = label.split(":")
    return S.Candidate(kind, coordinate, ("c",), column[:, None, None])


def test_a_named_effect_the_later_ones_explain_is_taken_out():
    """C = A + B (plus a little of its own) explains the most at the first step, so forward
    selection names it first; A and B are hidden and enter after it, and then C adds
    nothing: backward elimination takes C out and the named set is exactly {A, B}."""
    rng = np.random.default_rng(5)
    n = 600
    t = np.linspace(0.0, 10.0, n)
    a = np.sign(np.sin(2.3 * t))              # Coulomb-like
    b = np.sin(5.1 * t) * np.cos(0.9 * t)     # a second, unrelated shape
    own = np.sin(13.0 * t)
    candidates = [_candidate("x:a", a), _candidate("x:b", b), _candidate("x:c", a + b + 0.5 * own),
                  _candidate("x:d", np.cos(3.7 * t) ** 3)]
    model = _smooth(n)
    y = ((model @ np.array([0.5, 1.0, -2.0]))[:, 0] + 1.0 * a + 1.0 * b + 0.1 * rng.standard_normal(n))[:, None]
    chosen = S.select(model, y, candidates, alpha=0.05)
    assert chosen.steps[0].chosen == 2                  # C named first ...
    assert [i for i, _, _ in chosen.removed] == [2]     # ... then taken out
    assert sorted(chosen.added) == [0, 1]
    assert not chosen.ambiguous
    # the last step tests the final model: its fit has exactly the final model's columns
    assert chosen.steps[-1].chosen is None
    assert chosen.steps[-1].fit.coefficients.shape == (3 + 2,)
    # what was taken out failed the bar it entered by, given the others
    index, test, bar = next(r for r in chosen.removed if r[0] == 2)
    assert not test.tested or test.pvalue > bar


def test_two_real_effects_stay_named():
    """Nothing to take out: two hidden effects with distinct shapes are both kept."""
    rng = np.random.default_rng(6)
    n = 500
    t = np.linspace(0.0, 10.0, n)
    a, b = np.sign(np.sin(2.3 * t)), np.sin(5.1 * t) * np.cos(0.9 * t)
    candidates = [_candidate("x:a", a), _candidate("x:b", b), _candidate("x:d", np.cos(3.7 * t) ** 3)]
    model = _smooth(n)
    y = ((model @ np.array([0.5, 1.0, -2.0]))[:, 0] + 0.3 * a + 0.3 * b + 0.1 * rng.standard_normal(n))[:, None]
    chosen = S.select(model, y, candidates)
    assert sorted(chosen.added) == [0, 1] and not chosen.removed


def _rival_pair(n: int, cosine: float, along_a: float, along_b: float):
    """Orthonormal bases A, B (n, 1) at the given cosine, and a residual whose components on
    the directions of A beyond B and of B beyond A are ``along_a`` and ``along_b`` (unit
    noise elsewhere, white): the encompassing statistics are then about along^2."""
    rng = np.random.default_rng(7)
    q, _ = np.linalg.qr(rng.standard_normal((n, 3)))
    u, w = q[:, 0], q[:, 1]
    A = u[:, None]
    B = (cosine * u + np.sqrt(1 - cosine ** 2) * w)[:, None]
    a_beyond_b = W.conditional(A, B)[:, 0]
    b_beyond_a = W.conditional(B, A)[:, 0]
    noise = rng.standard_normal(n)
    for v in (a_beyond_b, b_beyond_a, u, w):       # remove the noise's part on the plane
        noise -= v * (v @ noise) / (v @ v)
    noise *= np.sqrt(n / (noise @ noise))           # unit variance
    # solve for the residual's coefficients on (A beyond B, B beyond A): their inner
    # products with the two directions must be along_a and along_b
    G = np.array([[1.0, a_beyond_b @ b_beyond_a], [a_beyond_b @ b_beyond_a, 1.0]])
    c = np.linalg.solve(G, [along_a, along_b])
    residual = noise + c[0] * a_beyond_b + c[1] * b_beyond_a
    return A, B, residual


@pytest.mark.parametrize("along, expect", [(2.5, "confusable"), (5.0, "distinct")])
def test_rivals_that_add_over_each_other_must_clear_the_further_effect_bar(along, expect):
    """Both add over each other at alpha (p about 0.012 each way) but not at the bar of a
    further effect (alpha / 20 = 0.0025): neither is shown to be a second effect, so the
    two are confusable, not 'two distinct effects' (which named the stronger and dropped the
    other at the next step: the slider-crank's crank offset named for the coupler's).
    Far beyond the bar both ways (p about 1e-6): two distinct effects, neither beaten."""
    n = 800
    A, B, residual = _rival_pair(n, 0.99, along, along)
    fit = WeightedLinearModel(np.zeros((n, 1, 0)), residual[:, None]).fit(np.ones(1))   # an empty model
    t_ab = W.wald(residual - B @ (B.T @ residual), W.conditional(A, B), (n, 1), 1, lags=0)
    # White's (HC0) statistic on unit white noise: about along^2, chi-square's tail
    assert t_ab.stat == pytest.approx(along ** 2, rel=0.5)
    assert t_ab.pvalue == pytest.approx(stats.f.sf(t_ab.stat, 1, n - 2), rel=1e-9)
    winner, confusable, beaten = S.resolve(0, [1], {0: A, 1: B}, fit, (n, 1), 0, 0.05,
                                           nested_level=0.05 / 20)
    if expect == "confusable":
        assert 0.0025 < t_ab.pvalue <= 0.05
        assert [r.index for r in confusable] == [1] and not beaten
    else:
        assert t_ab.pvalue < 1e-4
        assert winner == 0 and not confusable and not beaten


def test_sparse_direction_on_a_white_residual_gets_the_classical_test():
    """A direction acting on 8 samples: White's covariance would rest on 8 scores, so it is
    not tested; on a white residual the classical variance is exact, and the statistic then
    equals statsmodels' non-robust F test of the column in the augmented regression; where
    the residual around those samples is larger than its average (noise 3 times larger
    there), that statistic divided by the local power (a centred 25-sample mean of the
    augmented regression's squared residual over its mean, the end samples repeated,
    pandas, weighted by the direction's energy)."""
    rng = np.random.default_rng(8)
    n = 400
    X = _smooth(n)[:, 0, :]
    z = np.zeros(n)
    z[200:208] = [1.0, 3.0, 5.0, 6.0, 5.0, 3.0, 1.0, 0.5]
    Q = W.orthonormal_basis(X, 1e-12)
    U = W.orthonormal_basis(W.project_out(z[:, None], Q), W.ABSORB_TOL, reference=z[:, None])
    white = rng.standard_normal(n)
    louder = white * np.where((np.arange(n) >= 190) & (np.arange(n) < 220), 3.0, 1.0)
    for noise, local in ((white, False), (louder, True)):
        y = X @ [1.0, 2.0, -1.0] + 0.4 * z + noise
        e = y - Q @ (Q.T @ y)
        assert W.wald(e, U, (n, 1), 3).reason == "support"
        test = W.wald(e, U, (n, 1), 3, lags=0, sparse_if_white=True)       # the white branch
        ols = sm.OLS(y, np.column_stack([X, z])).fit()
        squares = ols.resid ** 2
        padded = pd.Series(np.pad(squares, 12, mode="edge"))       # the end samples repeated
        power = padded.rolling(25, center=True).mean().to_numpy()[12:-12] / squares.mean()
        factor = float(power @ U[:, 0] ** 2)
        assert test.tested and test.lags == 0 and (factor > 1.5) == local
        expected = float(ols.tvalues[-1] ** 2) / max(factor, 1.0)
        assert test.stat == pytest.approx(expected, rel=1e-9)
        assert test.pvalue == pytest.approx(stats.f.sf(expected, 1, n - 4), rel=1e-6)
        if not local:
            assert test.pvalue == pytest.approx(float(ols.pvalues[-1]), rel=1e-6)


def _six_samples(n: int, start: int) -> tuple[np.ndarray, np.ndarray]:
    """The small model's orthonormal basis, and a direction beyond it acting on 6 samples."""
    Q = W.orthonormal_basis(_smooth(n)[:, 0, :], 1e-12)
    z = np.zeros(n)
    z[start:start + 6] = 1.0
    return Q, W.orthonormal_basis(W.project_out(z[:, None], Q), W.ABSORB_TOL, reference=z[:, None])


def test_sparse_direction_test_has_its_size_on_white_noise():
    rng = np.random.default_rng(9)
    n = 300
    Q, U = _six_samples(n, 100)
    rejections = []
    for _ in range(400):
        y = rng.standard_normal(n)
        t = W.wald(y - Q @ (Q.T @ y), U, (n, 1), 3, sparse_if_white=True)
        if t.tested:
            rejections.append(t.pvalue <= 0.05)
    assert len(rejections) > 300 and 0.02 <= np.mean(rejections) <= 0.09


def test_group_refused_for_support_is_resolved_once_the_model_is_complete():
    """A and B differ only on 8 samples (A = B + a spike). Hidden: A and a smooth effect C.
    At the first step C is still in the residual (not white), the comparison of A with B
    is refused ('support') and they form an ambiguous group; once C is in, the residual is
    white, the comparison is made and A is named, B is not."""
    rng = np.random.default_rng(10)
    n = 600
    t = np.linspace(0.0, 10.0, n)
    b = np.sign(np.sin(2.3 * t))
    spike = np.zeros(n)
    spike[300:308] = [2.0, 5.0, 9.0, 12.0, 9.0, 5.0, 2.0, 1.0]
    c = np.sin(1.1 * t) * np.cos(0.4 * t) ** 2
    candidates = [_candidate("x:a", b + spike), _candidate("x:b", b), _candidate("x:c", c),
                  _candidate("x:d", np.cos(3.7 * t) ** 3)]
    model = _smooth(n)
    y = ((model @ np.array([0.5, 1.0, -2.0]))[:, 0] + 1.0 * (b + spike) + 0.3 * c
         + 0.1 * rng.standard_normal(n))[:, None]
    chosen = S.select(model, y, candidates)
    first = chosen.steps[0]
    assert chosen.regrouped and chosen.regrouped[0][1] == 0       # a group at first; A named later
    assert first.chosen == 0 and 1 in [r.index for r in first.beaten]    # the record: A beat B
    assert sorted(chosen.added) == [0, 2] and not chosen.ambiguous and not chosen.companions


def test_sla_upper_arm_friction_is_named_not_left_ambiguous():
    """The case the regrouping is for: on the SLA, viscous friction on the upper arm differs
    from viscous friction on the lower arm only near the arms' toggle position. Hidden with
    an offset on theta2 (still in the residual when the two frictions compete), it used to
    end 'ambiguous' with the lower arm's; compared again in the complete model it is named,
    with its coefficient within 4 standard deviations of the truth."""
    mech = resolve("sla_suspension")
    motion = trajectory_motion(mech, 1000)
    problem = prepare(mech, motion, evaluate(mech, motion))
    by_label = {c.label: c for c in problem.candidates}
    rng = np.random.default_rng(100)
    clean = problem.inertial @ random_physical_inertia(mech, rng)
    sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
    tau = clean.copy()
    truth = {}
    for label in ("viscous_friction:theta_upper", "offset:theta2"):
        column = by_label[label].columns[..., 0]
        scale = 5.0 / np.max(np.sqrt(np.mean(column ** 2, axis=0)) / sd)     # ratio 5
        truth[label] = scale
        tau += column * scale
    d = diagnose(problem, tau + rng.standard_normal(tau.shape) * sd)
    named = {f"{e['kind']}:{e['coordinate']}": e for e in d.effects}
    assert set(named) == set(truth) and not d.ambiguous
    assert any("compared again in the complete model" in note for note in d.notes)
    e = named["viscous_friction:theta_upper"]
    assert abs(e["value"] - truth["viscous_friction:theta_upper"]) < 4 * e["std"]


def test_stationary_variance_is_the_double_sum_and_classical_without_lags():
    """sum over t, s of b_t^T G(s - t) b_s with G the Bartlett-tapered cross-autocovariance
    (two coordinates, two directions), computed term by term; with no lags, sigma^2 I on
    orthonormal directions of one coordinate."""
    rng = np.random.default_rng(3)
    n, f, r, lags = 40, 2, 2, 3
    e, b = rng.standard_normal((n, f)), rng.standard_normal((n, f, r))
    expected = np.zeros((r, r))
    for t in range(n):
        for s in range(max(0, t - lags), min(n, t + lags + 1)):
            h = s - t
            g = sum(np.outer(e[u], e[u + h]) for u in range(max(0, -h), min(n, n - h)))
            expected += (1 - abs(h) / (lags + 1)) * b[t].T @ g @ b[s]
    assert np.allclose(longrun.stationary_variance(e, b, lags, 1.0), expected, rtol=1e-10)
    flat = np.zeros((r, r))               # the truncated kernel: weight 1 up to the lags
    for t in range(n):
        for s in range(max(0, t - lags), min(n, t + lags + 1)):
            h = s - t
            g = sum(np.outer(e[u], e[u + h]) for u in range(max(0, -h), min(n, n - h)))
            flat += b[t].T @ g @ b[s]
    truncated = longrun.stationary_variance(e, b, lags, 1.0, truncated=True)
    for floor in (flat, expected):        # at least both, in the matrix order
        assert np.linalg.eigvalsh(truncated - floor).min() > -1e-9 * np.abs(truncated).max()
    for a in range(r):                    # one direction: the larger of the two
        one = longrun.stationary_variance(e, b[:, :, a:a + 1], lags, 1.0, truncated=True)[0, 0]
        assert one == pytest.approx(max(flat[a, a], expected[a, a]), rel=1e-10)
    Q = np.linalg.qr(rng.standard_normal((n, r)))[0]
    one = e[:, :1]
    assert np.allclose(longrun.stationary_variance(one, Q[:, None, :], 0, 7.0), float(one[:, 0] @ one[:, 0]) / 7.0 * np.eye(r))


def test_sparse_direction_on_coloured_noise_has_its_size_with_the_stationary_variance():
    """A direction on 6 samples, AR(1) 0.6 noise: refused without ``sparse_if_coloured``
    (HAC would rest on 6 scores); with it, the test rejects at about its level."""
    rng = np.random.default_rng(11)
    n = 400
    Q, U = _six_samples(n, 200)
    rejections, refused = [], 0
    for _ in range(400):
        y = lfilter([0.8], [1.0, -0.6], rng.standard_normal(n))
        e = y - Q @ (Q.T @ y)
        refused += W.wald(e, U, (n, 1), 3, sparse_if_white=True).reason == "support"
        t = W.wald(e, U, (n, 1), 3, sparse_if_white=True, sparse_if_coloured=True)
        if t.tested and t.lags > 0:
            rejections.append(t.pvalue <= 0.05)
    assert refused > 300 and len(rejections) > 300
    assert 0.02 <= np.mean(rejections) <= 0.09


@pytest.mark.parametrize("rho, highest", [(0.0, 0.09), (0.6, 0.12)])
def test_sparse_direction_where_the_noise_is_larger_keeps_its_size(rho, highest):
    """A direction on 6 samples inside a stretch of 60 where the noise is 3 times its level
    elsewhere (as at a velocity reversal), white and AR(1) noise. With the residual's average
    level alone the test rejects in about a third of the draws at 5 % (checked); with the
    local power, near its level (6.5 % white, 9.5 % AR: the local power is estimated from
    25 samples, a tail the F test does not widen for)."""
    rng = np.random.default_rng(12)
    n = 400
    Q, U = _six_samples(n, 200)
    level = np.ones(n)
    level[170:230] = 3.0
    rejections, average_only = [], []
    for _ in range(400):
        y = lfilter([np.sqrt(1 - rho ** 2)], [1.0, -rho], rng.standard_normal(n)) * level
        e = y - Q @ (Q.T @ y)
        t = W.wald(e, U, (n, 1), 3, sparse_if_white=True, sparse_if_coloured=True)
        assert t.tested
        rejections.append(t.pvalue <= 0.05)
        gamma = float(U[:, 0] @ e)
        rest = e - U[:, 0] * gamma
        variance = (longrun.stationary_variance(rest[:, None], U[:, None, :], t.lags, n - 4.0, truncated=True)[0, 0]
                    if t.lags else float(rest @ rest) / (n - 4))
        average_only.append(stats.f.sf(gamma ** 2 / variance, 1, n - 4) <= 0.05)
    assert np.mean(average_only) > 0.2
    assert 0.02 <= np.mean(rejections) <= highest
