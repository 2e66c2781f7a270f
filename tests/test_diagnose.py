"""diagnose: the statistics against independent computations, a small seeded campaign on
generated and built-in mechanisms, and the verb end to end (simulate -> CSV -> diagnose ->
--write -> load back). The full campaign is benchmarks/bench_diagnose.py."""

import json

import numpy as np
import pytest
import statsmodels.api as sm
from click.testing import CliRunner
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.stats.multitest import multipletests

from baseparams.cli import main
from baseparams.dynamics.effects import Effect
from baseparams.errors import InputError
from baseparams.hookspecs import hookimpl
from baseparams.identify import longrun
from baseparams.diagnose import wald as W
from baseparams.identify.linear import WeightedLinearModel
from baseparams.diagnose import whiteness
from baseparams.diagnose.fixed import decimal_text, write_fixed
from baseparams.diagnose.problem import prepare
from baseparams.diagnose.workflow import diagnose
from baseparams.dynamics.forces import evaluate
from baseparams.recordings.simulate import random_physical_inertia, trajectory_motion
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec


def _problem(mech, samples=240):
    motion = trajectory_motion(mech, samples)
    return prepare(mech, motion, evaluate(mech, motion))


def _data(problem, mech, rng, hidden=(), ratio=5.0, noise=0.02):
    """tau = K phi + hidden effects scaled to ``ratio`` x noise SD + noise."""
    clean = problem.inertial @ random_physical_inertia(mech, rng)
    sd = noise * np.sqrt(np.mean(clean ** 2, axis=0))
    tau = clean.copy()
    by_label = {c.label: c for c in problem.candidates}
    for label, theta in hidden:
        force = by_label[label].columns @ np.asarray(theta, float)
        tau += force * ratio / np.max(np.sqrt(np.mean(force ** 2, axis=0)) / sd)
    _data.last_sd = sd
    return tau + rng.standard_normal(tau.shape) * sd


def _named(d):
    return {(e["kind"], e["coordinate"]) for e in d.effects}


# ----- the statistics against statsmodels ----------------------------------------------------
def test_holm_matches_statsmodels():
    p = np.random.default_rng(0).uniform(size=30) ** 3
    np.testing.assert_allclose(W.holm(p), multipletests(p, method="holm")[1])


def test_wald_matches_statsmodels_hac_regression():
    """Our Wald statistic on the projected candidate equals statsmodels' HAC Wald test of the
    candidate's coefficient in the augmented regression (one coordinate: per-row scores)."""
    rng = np.random.default_rng(1)
    n = 300
    t = np.linspace(0, 10, n)
    X = np.column_stack([np.ones(n), np.sin(t), np.cos(2 * t)])
    z = np.sign(np.sin(1.3 * t))
    y = X @ [1.0, 2.0, -1.0] + 0.1 * z + rng.standard_normal(n) * 0.3
    lags = 5
    res = sm.OLS(y, np.column_stack([X, z])).fit(cov_type="HAC", cov_kwds={"maxlags": lags, "use_correction": False})
    expected = float(res.params[-1] ** 2 / res.cov_params()[-1, -1])
    Q = W.orthonormal_basis(X, 1e-12)
    e = y - Q @ (Q.T @ y)
    U = W.orthonormal_basis(W.project_out(z[:, None], Q), W.ABSORB_TOL, reference=z[:, None])
    rows = n
    test = W.wald(e, U, (n, 1), Q.shape[1], lags=lags, prewhiten=False)
    # our statistic carries the small-sample factor rows / (rows - dof - r)
    assert test.stat == pytest.approx(expected / (rows / (rows - 3 - 1)), rel=1e-9)


def test_wald_size_on_white_noise_is_near_alpha():
    """Nothing hidden: a candidate is rejected at 5 % in about 5 % of datasets."""
    mech = resolve("planar_2r")
    problem = _problem(mech, 200)
    rng = np.random.default_rng(7)
    n, f, _ = problem.inertial.shape
    clean = problem.inertial @ random_physical_inertia(mech, rng)
    sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
    testable = [c for c in problem.candidates if c.kind in ("viscous_friction", "coulomb_friction", "offset")]
    rejections = []
    for _ in range(150):
        fit = WeightedLinearModel(problem.inertial, clean + rng.standard_normal(clean.shape) * sd).fit()
        for cand in testable:
            rejections.append(W.wald(fit.residual, W.candidate_basis(cand, fit), (n, f), fit.rank).pvalue < 0.05)
    assert 0.02 <= np.mean(rejections) <= 0.085      # 900 tests: 5 % +- 2.5 SE


def test_ljung_box_matches_statsmodels():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((180, 3)).cumsum(axis=0) * 0.1 + rng.standard_normal((180, 3))
    ours = whiteness.ljung_box(x, 10)
    theirs = [float(acorr_ljungbox(x[:, j], lags=[10])["lb_stat"].iloc[0]) for j in range(3)]
    assert np.allclose(ours, theirs, rtol=1e-12)


def _smooth_model(n: int, p: int) -> np.ndarray:
    """p smooth columns (low-frequency cosines) on one coordinate: the shape of a regressor
    along a smooth trajectory."""
    t = np.linspace(0.0, 1.0, n)
    return np.stack([np.cos(np.pi * k * t) for k in range(p)], axis=1)[:, None, :]


def test_whiteness_size_after_a_smooth_fit_where_chi_square_fails():
    """Nothing but white noise, fitted by 24 smooth columns on 200 samples: the simulated
    null keeps the test's size (about 5 %), the chi-square reference rejects far more often
    (which is why the Monte Carlo null exists)."""
    rng = np.random.default_rng(9)
    model = _smooth_model(200, 24)
    monte_carlo, chi_square = [], []
    for _ in range(120):
        fit = WeightedLinearModel(model, rng.standard_normal((200, 1))).fit()
        residual = fit.residual.reshape(200, 1)
        _, p = whiteness.monte_carlo_pvalues(residual, fit.basis, 10, 0.05, seed=int(rng.integers(1 << 30)))
        monte_carlo.append(p[0] <= 0.05)
        chi_square.append(float(acorr_ljungbox(residual[:, 0], lags=[10])["lb_pvalue"].iloc[0]) <= 0.05)
    assert np.mean(monte_carlo) <= 0.1            # 120 datasets: 5 % + 2.5 SE
    assert np.mean(chi_square) >= 2 * max(np.mean(monte_carlo), 0.05)


def test_whiteness_detects_coloured_noise_after_the_same_fit():
    rng = np.random.default_rng(10)
    model = _smooth_model(200, 24)
    rejected = 0
    for _ in range(30):
        e = rng.standard_normal(200)
        coloured = e.copy()
        for k in range(1, 200):
            coloured[k] = 0.5 * coloured[k - 1] + e[k]
        fit = WeightedLinearModel(model, coloured[:, None]).fit()
        _, p = whiteness.monte_carlo_pvalues(fit.residual.reshape(200, 1), fit.basis, 10, 0.05)
        rejected += p[0] <= 0.05
    assert rejected >= 27


def test_hac_window_widens_for_correlated_residuals():
    rng = np.random.default_rng(2)
    white = rng.standard_normal((500, 2))
    coloured = np.zeros_like(white)
    for k in range(1, 500):
        coloured[k] = 0.9 * coloured[k - 1] + white[k]
    assert longrun.hac_lags(white) <= longrun.newey_west_lags(500)
    assert longrun.hac_lags(coloured) >= 2 * longrun.newey_west_lags(500)


def test_absorbed_and_sparse_candidates_are_not_tested():
    mech = resolve("pendulum")
    problem = _problem(mech)
    rng = np.random.default_rng(3)
    tau = _data(problem, mech, rng)
    d = diagnose(problem, tau)
    # rotor inertia on the only joint is Izz's column: absorbed
    assert any(u.startswith("rotor_inertia:") and "absorbed" in u for u in d.untestable)
    # the narrowest Stribeck bump of the shape grid is never sampled: not tested
    stribeck = next(c for c in problem.candidates if c.kind == "stribeck_friction")
    fit = WeightedLinearModel(problem.inertial, tau).fit()
    narrow = W.candidate_basis(stribeck.variants[0], fit)
    assert W.wald(fit.residual, narrow, tau.shape, fit.rank).reason == "support"


# ----- seeded campaign subset ------------------------------------------------------------------
@pytest.mark.parametrize("text", [generate.serial_chain(3), generate.four_bar(2)], ids=["chain3", "four_bar"])
def test_nothing_hidden_names_nothing_on_generated_mechanisms(text):
    mech = parse_mechanism(text)
    problem = _problem(mech, 200)
    rng = np.random.default_rng(11)
    false = sum(bool(diagnose(problem, _data(problem, mech, rng)).effects) for _ in range(12))
    assert false <= 2          # target 5 %; 12 datasets: <= 2 allows for chance (P(>2) < 2 % at 5 %)


@pytest.mark.parametrize("text", [generate.serial_chain(4), generate.tree(1)], ids=["chain4", "tree1"])
def test_nothing_hidden_closes_the_gap_on_generated_mechanisms(text):
    """With nothing hidden the whiteness test (its null simulated through the fit) says
    'closed' (exit 0) in about 95 % of datasets: 30 of 30 and 29 of 30 measured here; the
    chi-square null said 'structure remains' in 20-25 % on the PUMA and Stewart platform."""
    mech = parse_mechanism(text)
    problem = _problem(mech, 300)
    rng = np.random.default_rng(11)
    closed = sum(diagnose(problem, _data(problem, mech, rng)).closed for _ in range(12))
    assert closed >= 10        # 12 datasets at a 5 % rejection rate: P(< 10) < 2 %


@pytest.mark.parametrize("name, hidden", [
    ("planar_2r", [("viscous_friction:q2", [0.8])]),
    ("planar_2r", [("coulomb_friction:q1", [1.0]), ("viscous_friction:q2", [0.5])]),
    ("pendulum", [("offset:theta", [1.0])]),
    ("slider_crank", [("viscous_friction:q1", [1.0])]),
])
def test_hidden_effects_are_named_and_the_gap_shrinks(name, hidden):
    mech = resolve(name)
    problem = _problem(mech)
    rng = np.random.default_rng(5)
    tau = _data(problem, mech, rng, hidden)
    d = diagnose(problem, tau)
    truth = {tuple(label.split(":")) for label, _ in hidden}
    assert _named(d) == truth
    # the gap closes to the noise floor (the noise SD / RMS tau, known here), on the holdout too
    sd = _data.last_sd
    train = d.training

    def floor(rows):
        return np.sqrt(np.mean((sd / np.sqrt(np.mean(tau[rows] ** 2, axis=0))) ** 2))
    # block cross-validated: every block predicted from the others
    assert d.gap["after"] < d.gap["before"] and d.gap["cv_after"] < d.gap["cv_before"]
    assert d.gap["after"] < 1.1 * floor(slice(0, train))
    assert d.gap["cv_after"] < 1.25 * floor(slice(0, train))
    assert d.closed and d.verdict == "explained"
    # and on a last block kept out of everything
    d = diagnose(problem, tau, holdout=0.3)
    assert _named(d) == truth
    assert d.gap["holdout_after"] < d.gap["holdout_before"]
    assert d.gap["holdout_after"] < 1.25 * floor(slice(d.training, None))


def test_named_coefficient_matches_the_truth_within_its_std():
    mech = resolve("planar_2r")
    problem = _problem(mech, 400)
    rng = np.random.default_rng(8)
    clean = problem.inertial @ random_physical_inertia(mech, rng)
    sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
    by_label = {c.label: c for c in problem.candidates}
    tau = clean + by_label["viscous_friction:q1"].columns @ [0.7] + rng.standard_normal(clean.shape) * sd
    d = diagnose(problem, tau)
    (effect,) = d.effects
    assert (effect["kind"], effect["coordinate"]) == ("viscous_friction", "q1")
    assert abs(effect["value"] - 0.7) < 4 * effect["std"]
    assert 0 < effect["std"] < 0.05


def test_spring_on_an_independent_coordinate_is_not_reported_as_an_offset():
    mech = resolve("planar_2r")
    problem = _problem(mech, 300)
    rng = np.random.default_rng(9)
    q2 = trajectory_motion(mech, 300).q[:, 1]
    tau = _data(problem, mech, rng, [("spring:q2", [2.0, 2.0 * np.mean(q2)])], ratio=8)
    assert _named(diagnose(problem, tau)) == {("spring", "q2")}
    tau = _data(problem, mech, rng, [("offset:q2", [1.0])], ratio=8)
    assert _named(diagnose(problem, tau)) == {("offset", "q2")}


class TwinFriction:
    """A third party's effect identical to viscous friction up to scale: indistinguishable."""
    @hookimpl
    def baseparams_effects(self):
        return [Effect("twin_friction", "tau = ft * 2 qd", ("ft",), lambda q, qd, qdd: [2 * qd])]


def test_confusable_candidates_are_reported_ambiguous_not_named(registered):
    """A third party's effect is a candidate too; two candidates with proportional columns
    cannot be told apart: both under ambiguous, neither named."""
    registered(TwinFriction())
    mech = resolve("planar_2r")
    assert any(c.label == "twin_friction:q2" for c in _problem(mech).candidates)
    # the friction candidates only: the point is the twin, not the rest of the catalogue
    motion = trajectory_motion(mech, 240)
    problem = prepare(mech, motion, evaluate(mech, motion),
                      ["viscous_friction", "twin_friction", "coulomb_friction", "offset"])
    rng = np.random.default_rng(4)
    d = diagnose(problem, _data(problem, mech, rng, [("viscous_friction:q2", [1.0])]))
    assert not any(e["coordinate"] == "q2" for e in d.effects)
    (group,) = d.ambiguous
    assert {(c["kind"], c["coordinate"]) for c in group["candidates"]} == {("viscous_friction", "q2"),
                                                                           ("twin_friction", "q2")}
    assert abs(group["evidence"][0]["correlation"]) == pytest.approx(1.0, abs=1e-9)
    assert "speed" in group["separate_by"] or "range" in group["separate_by"] or group["separate_by"]


def test_effect_on_a_dependent_coordinate_of_a_loop():
    mech = resolve("four_bar")
    problem = _problem(mech, 300)
    dependent = [c for c in mech.coordinates if c not in mech.independent]
    rng = np.random.default_rng(6)
    label = f"viscous_friction:{dependent[0]}"
    d = diagnose(problem, _data(problem, mech, rng, [(label, [1.0])], ratio=8))
    named = _named(d) | {(c["kind"], c["coordinate"]) for a in d.ambiguous for c in a["candidates"]}
    assert ("viscous_friction", dependent[0]) in named
    assert not (_named(d) - {("viscous_friction", dependent[0])})


# ----- writing and the verb ------------------------------------------------------------------
def test_decimal_text_is_exact_and_plain():
    for value in (1e-7, -2.5e12, 0.1, 1234.5678):
        text = decimal_text(value)
        assert "e" not in text.lower() and float(text) == value


def test_write_fixed_appends_and_loads_back(tmp_path):
    mech = resolve("planar_2r")
    out = tmp_path / "fixed.toml"
    back = write_fixed(mech, [EffectSpec("spring", "q2", {"k": 2.5, "kq0": -1e-7})], out, origin="test")
    original = open(mech.path, encoding="utf-8").read()
    assert out.read_text(encoding="utf-8").startswith(original.rstrip("\n"))
    (spec,) = back.effects
    assert (spec.kind, spec.coordinate) == ("spring", "q2") and float(spec.values["kq0"]) == -1e-7


def test_verb_end_to_end(tmp_path):
    runner = CliRunner()
    data, truth = tmp_path / "d.csv", tmp_path / "truth.json"
    result = runner.invoke(main, ["simulate", "planar_2r", "-o", str(data), "--effect", "viscous_friction:q1=0.9",
                                  "--noise", "0.02", "--seed", "3", "--samples", "300", "--truth", str(truth)])
    assert result.exit_code == 0, result.output
    fixed, plot = tmp_path / "fixed.toml", tmp_path / "diag.png"
    result = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--format", "json", "--plot", str(plot),
                                  "--write", str(fixed)])
    assert result.exit_code == 0, result.output + result.stderr
    report = json.loads(result.stdout)
    assert set(report) >= {"effects", "ambiguous", "gap", "unexplained"}
    assert set(report["gap"]) >= {"before", "after", "cv_before", "cv_after", "cv_blocks", "holdout_before",
                                  "holdout_after", "holdout_floor", "holdout_noise_floor"}
    assert report["verdict"] == "explained"
    assert report["gap"]["cv_after"] < report["gap"]["cv_before"]
    (effect,) = report["effects"]
    assert set(effect) >= {"kind", "coordinate", "value", "std"}
    assert (effect["kind"], effect["coordinate"]) == ("viscous_friction", "q1")
    assert abs(effect["value"] - 0.9) < 4 * effect["std"]
    assert plot.stat().st_size > 10_000
    assert [(e.kind, e.coordinate) for e in resolve(str(fixed)).effects] == [("viscous_friction", "q1")]
    # the fixed mechanism explains the data: nothing left to name (its viscous friction is known)
    result = runner.invoke(main, ["diagnose", str(fixed), str(data), "--format", "json"])
    assert json.loads(result.stdout)["effects"] == [] and result.exit_code == 0


def test_data_without_noise_are_explained_to_rounding(tmp_path):
    """Data simulated without noise fit to rounding (NRMS near 1e-11), which is not white: once
    said "UNEXPLAINED: structure remains" with exit 1. A residual below ROUNDING of the torque
    is rounding: nothing missing on clean data, the hidden friction exact on clean data with
    it."""
    runner = CliRunner()
    clean, hidden = tmp_path / "clean.csv", tmp_path / "hidden.csv"
    assert runner.invoke(main, ["simulate", "puma560", "-o", str(clean)]).exit_code == 0
    result = runner.invoke(main, ["diagnose", "puma560", str(clean), "--format", "json"])
    report = json.loads(result.stdout)
    assert result.exit_code == 0 and report["verdict"] == "nothing missing" and report["effects"] == []
    assert report["gap"]["after"] < 1e-9
    runner.invoke(main, ["simulate", "planar_2r", "-o", str(hidden), "--effect", "viscous_friction:q1=0.5"])
    result = runner.invoke(main, ["diagnose", "planar_2r", str(hidden), "--format", "json"])
    report = json.loads(result.stdout)
    assert result.exit_code == 0 and report["verdict"] == "explained"
    assert [(e["kind"], e["coordinate"]) for e in report["effects"]] == [("viscous_friction", "q1")]
    assert abs(report["effects"][0]["value"] - 0.5) < 1e-9


def test_verb_bad_candidates_exit_2(tmp_path):
    runner = CliRunner()
    data = tmp_path / "d.csv"
    runner.invoke(main, ["simulate", "pendulum", "-o", str(data), "--noise", "0.01", "--samples", "100"])
    result = runner.invoke(main, ["diagnose", "pendulum", str(data), "--candidates", "viscous:theta"])
    assert result.exit_code == 2 and "unknown effect 'viscous'" in result.stderr
    result = runner.invoke(main, ["diagnose", "pendulum", str(data), "--candidates", "offset:nope"])
    assert result.exit_code == 2 and "'nope'" in result.stderr
    with pytest.raises(InputError, match="holdout"):
        mech = resolve("pendulum")
        diagnose(_problem(mech, 50), np.zeros((50, 1)), holdout=1.5)


def test_diagnose_says_when_it_stops_at_max_steps(tmp_path):
    """No silent cap: a search stopped by --max-steps with candidates still significant says
    so in the text and the JSON (three hidden effects, one step allowed)."""
    runner = CliRunner()
    data = tmp_path / "d.csv"
    result = runner.invoke(main, ["simulate", "planar_2r", "-o", str(data), "--samples", "600", "--noise", "0.01",
                                  "--effect", "viscous_friction:q1=0.5", "--effect", "coulomb_friction:q2=0.3",
                                  "--effect", "offset:q1=0.4"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--max-steps", "1", "--format", "json"])
    assert result.exit_code == 1, result.output + result.stderr
    out = json.loads(result.stdout)
    assert out["unexplained"]["significant_candidates_left"] is True and out["unexplained"]["max_steps"] == 1
    assert "--max-steps 1" in out["notes"][0]
    text = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--max-steps", "1"]).output
    assert "stopped at --max-steps 1" in text
