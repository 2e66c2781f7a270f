"""diagnose on data as recordings are (issue 21): coloured noise, shaped and derived
candidates, the out-of-sample gates, a given simulation (--params), the verdict and the
report. Each against a known truth; the campaign with rates is
``benchmarks/bench_diagnose.py --outside`` (docs/diagnosis.md)."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.identify import longrun
from baseparams.diagnose import final as FN
from baseparams.diagnose import selection as S
from baseparams.diagnose import wald as W
from baseparams.identify.linear import WeightedLinearModel
from baseparams.diagnose.problem import prepare
from baseparams.diagnose.workflow import diagnose
from baseparams.dynamics.forces import evaluate
from baseparams.diagnose.outofsample import cross_validate, stability
from baseparams.identify.impossible import implausible
from baseparams.recordings.simulate import trajectory_motion
from baseparams.io.loader import resolve

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import diagnose_campaign as C  # noqa: E402


@pytest.fixture(scope="module")
def puma():
    return C.setting("puma560", 800)


@pytest.fixture(scope="module")
def puma_1200():
    return C.setting("puma560", 1200)


@pytest.fixture(scope="module")
def planar():
    return C.setting("planar_2r", 600)


def _named(d):
    return {(e["kind"], e["coordinate"]) for e in d.effects}


# ----- coloured noise ---------------------------------------------------------------------------
def test_whitening_recovers_the_ar1_coefficient_and_whitens():
    rng = np.random.default_rng(0)
    e = C.noise(rng, (4000, 2), np.array([1.0, 2.0]), rho=0.9)
    w = S.Whitening.of(e)
    assert w.rho == pytest.approx([0.9, 0.9], abs=0.02)
    white = w(e)
    assert longrun.hac_lags(white) <= longrun.newey_west_lags(4000)
    assert np.std(white[1:], axis=0) == pytest.approx(np.array([1.0, 2.0]) * np.sqrt(1 - 0.81), rel=0.05)
    assert S.Whitening.of(rng.standard_normal((4000, 2))) is None


def test_wald_size_after_whitening_with_ar1_noise(puma):
    """Nothing hidden, AR(1) noise at 0.9: after whitening a candidate is rejected at 5 % in
    about 5 % of datasets (16 % with HAC alone, measured when this was built)."""
    P = puma.problem
    n, f = P.inertial.shape[:2]
    rng = np.random.default_rng(1)
    cands = [c for c in P.candidates if c.kind in ("viscous_friction", "offset") and not c.variants]
    rejected = []
    for _ in range(25):
        data = C.nothing(puma, rng, rho=0.9)
        fit = WeightedLinearModel(P.inertial, data.tau).fit()
        w = S.Whitening.of(fit.residual.reshape(n, f) / fit.weights)
        fit = WeightedLinearModel(w(P.inertial), w(data.tau)).fit()
        for c in cands:
            t = W.wald(fit.residual, W.candidate_basis(w(c.columns), fit), (n, f), fit.rank)
            rejected.append(t.pvalue < 0.05)
    assert 0.02 <= np.mean(rejected) <= 0.09          # 300 tests: 5 % +- 3 SE


def test_prewhitened_long_run_variance_of_an_ar1_mean():
    """The long-run variance of AR(1) scores is sigma^2 (1 + rho) / (1 - rho): prewhitened
    Newey-West gets it, Bartlett alone at the same window underestimates it."""
    rng = np.random.default_rng(2)
    rho, n = 0.9, 20000
    s = C.noise(rng, (n, 1), np.ones(1), rho=rho)
    truth = (1 + rho) / (1 - rho) * n
    assert longrun.long_run(s, 40)[0, 0] == pytest.approx(truth, rel=0.15)
    assert longrun.long_run(s, 40, prewhiten=False)[0, 0] < 0.9 * truth


def test_nothing_hidden_with_coloured_noise_names_nothing(planar):
    rng = np.random.default_rng(3)
    false = sum(bool(diagnose(planar.problem, C.nothing(planar, rng, rho=0.9).tau).effects) for _ in range(12))
    assert false <= 2              # target 5 %; 12 datasets: P(> 2) < 2 % at 5 %


# ----- shapes and derived candidates -------------------------------------------------------------
def test_smooth_coulomb_is_named_with_its_transition_speed(planar):
    rng = np.random.default_rng(4)
    hits = 0
    for _ in range(5):
        data = C.smooth_coulomb(planar, rng, ratio=8)
        d = diagnose(planar.problem, data.tau)
        hits += _named(d) == data.truth
        for e in d.effects:
            if e["kind"] == "coulomb_friction":
                assert e["shape"]["vs"] > 0                 # a smooth law, not sign(qd)
                assert 0.2 < e["shape"]["vs"] / data.extra["vs"] < 5      # on the grid's resolution
    assert hits >= 4


def test_delay_is_named_with_its_value(puma):
    rng = np.random.default_rng(5)
    data = C.delay(puma, rng)
    d = diagnose(puma.problem, data.tau)
    assert _named(d) == {("delay", "all")}
    (e,) = d.effects
    assert abs(e["value"] - data.extra["d"]) < max(4 * e["std"], 0.1 * data.extra["d"])


def test_delay_is_named_under_ar1_noise(puma):
    """A delay of 0.5-3 samples at effect/noise 5 with AR(1) noise at 0.9 (the whitened tests
    see its sharp signature; the campaign gives 100 % of 20)."""
    rng = np.random.default_rng(15)
    hits = sum(_named(diagnose(puma.problem, data.tau)) == data.truth
               for data in (C.delay(puma, rng, rho=0.9) for _ in range(4)))
    assert hits >= 3


def _offset_cogging_spring(problem, place):
    kinds = ("cogging", "offset", "spring")
    cands = [next(c for c in problem.candidates if c.kind == k and c.coordinate == place) for k in kinds]
    return cands


def test_simpler_form_is_tried_in_place_of_a_held_back_general_one(puma):
    """Cogging held back (as when it failed the out-of-sample checks): the offset it
    generalises is proposed in its place when an offset is hidden, not the spring (the offset
    is nested in it and its slope adds nothing), and nothing is proposed when nothing is
    hidden (the bar is the one the cogging entered by)."""
    P = puma.problem
    place = puma.coordinates[3]            # q4: the spring's test is the stronger, the offset the truth
    cands = _offset_cogging_spring(P, place)
    rng = np.random.default_rng(16)
    proposed, false = [], 0
    for hidden in [True] * 4 + [False] * 10:
        phi, clean, sd = C.base(puma, rng)
        force = C.scaled(C.on(clean.shape[1], 3, np.ones(len(clean))), sd, 5.0) if hidden else 0.0
        tau = clean + force + C.noise(rng, clean.shape, sd, 0.9)
        chosen = S.select_whitened(P.inertial, tau, cands)
        held = S.Selection(chosen.steps, [0], {}, candidates=list(chosen.candidates), bars={0: 0.05 / 3})
        found = FN.simpler_in_place(P.inertial, tau, held, 0, [], 0.05)
        if hidden:
            proposed.append(None if found is None else cands[found[0].chosen].kind)
        else:
            false += found is not None
    assert proposed.count("offset") >= 3
    assert false <= 1


def test_diagnose_names_the_simpler_form_when_the_general_one_is_held_back():
    """The campaign's offset datasets 8 and 15 (PUMA, AR(1) 0.9, seed 2024): cogging won the
    selection and failed the stability check; the offset (the truth) is named in its place,
    and the report says so. Before, nothing was named on these two."""
    s = C.setting("puma560", 1200)
    rng = np.random.default_rng(2024)
    make = C.catalogue("offset")
    datasets = [make(s, rng, rho=0.9, ratio=5.0) for _ in range(16)]
    for k in (8, 15):
        d = diagnose(s.problem, datasets[k].tau)
        assert _named(d) == datasets[k].truth
        (place,) = {c for _, c in datasets[k].truth}
        assert any(n.startswith(f"cogging:{place} was held back") and f"offset:{place}" in n for n in d.notes)
        assert not any(u["kind"] == "cogging" for u in d.unsupported)


def test_one_drives_delay_is_a_candidate_only_when_named(puma, planar):
    """``delay`` alone is the recording's delay; ``delay:COORD`` one drive's own, on a
    mechanism with several coordinates."""
    from baseparams.errors import InputError
    from baseparams.diagnose.candidates import parse_selection
    assert parse_selection(puma.mechanism, ["delay"]) == [("delay", "all")]
    assert parse_selection(puma.mechanism, ["delay:q2"]) == [("delay", "q2")]
    one = C.generated_setting("four_bar2", 100)
    with pytest.raises(InputError, match="not a place of delay"):
        parse_selection(one.mechanism, ["delay:qa"])


def _with_joint_delays(s):
    selection = ["delay"] + [f"delay:{c}" for c in s.coordinates] + ["viscous_friction", "offset"]
    return prepare(s.mechanism, s.motion, evaluate(s.mechanism, s.motion), selection=selection)


def test_one_drives_delay_is_named_when_asked_for(puma):
    """q2's torque alone lags 2 samples: with every drive's delay asked for, q2's is named."""
    problem = _with_joint_delays(puma)
    t = puma.motion.t
    rng = np.random.default_rng(31)
    for _ in range(3):
        phi, clean, sd = C.base(puma, rng)
        lagged = clean.copy()
        lagged[:, 1] = np.interp(t - 2 * (t[1] - t[0]), t, clean[:, 1])
        d = diagnose(problem, lagged + C.noise(rng, clean.shape, sd))
        assert _named(d) == {("delay", "q2")}


def test_an_elastic_joint_is_seldom_named_a_delay(puma):
    """One joint's torque through a second-order lag (an elastic joint), every drive's delay
    asked for: to first order a delay on that joint, but its second-order term has the
    elastic sign, and the delay is held back saying so (9 of 20 measured; a delay named in
    3 of 20, 7 of 20 without the check)."""
    problem = _with_joint_delays(puma)
    rng = np.random.default_rng(32)
    named = second_order = 0
    for _ in range(10):
        d = diagnose(problem, C.compliance(puma, rng).tau)
        named += any(e["kind"] == "delay" for e in d.effects)
        second_order += any(u["kind"] == "delay" and "resonant lag" in u["reason"] for u in d.unsupported)
    assert named <= 2 and second_order >= 3


# The campaign's datasets where q4's torque alone lags 4-6 samples (seed 2024, the white
# joint-delay row, datasets 1, 4, 5, 6, 7): the PCG64 state before each was drawn.
Q4_LAGS = [
    (311766082653223283809844186989636472564, 263843294879837360010514471918415607657, 1, 2856601604),
    (267387390845069555556787537282074402003, 263843294879837360010514471918415607657, 0, 1336749055),
    (334767923002793273886161685612014143826, 263843294879837360010514471918415607657, 1, 2216573180),
    (93191115261258054488259420029409838131, 263843294879837360010514471918415607657, 0, 2216573180),
    (258848044608796513178637532245714498583, 263843294879837360010514471918415607657, 1, 2288286783),
]


def test_what_stands_in_for_one_joints_lag_is_not_named():
    """q4's torque lags (one drive's own delay, not a default candidate): cogging and a spring
    or an offset on q4 imitated it, held steady and predicted held-out blocks, and were named
    in all five; a lag of the joints' torques (q4's among them) outdoes them, so nothing wrong is named and the report
    says what they may stand in for."""
    s = C.setting("puma560", 1200)
    said = 0
    for state in Q4_LAGS:
        data = C.joint_delay(s, _at(state))
        assert ("delay", "q4") in data.acceptable
        d = diagnose(s.problem, data.tau)
        assert _named(d) <= data.acceptable
        said += any("a lag of the joints' torques" in u["reason"] for u in d.unsupported)
    assert said >= 3


def test_a_filters_lag_is_named_a_delay(puma):
    """Torques through a first-order low-pass (time constant 1-3 samples: a current filter) lag
    the positions: named a delay, not held back as a resonant lag (the second-order check's
    coefficient is negative for a filter, as for a delay)."""
    from scipy.signal import lfilter
    t = puma.motion.t
    dt = t[1] - t[0]
    rng = np.random.default_rng(51)
    for _ in range(3):
        phi, clean, sd = C.base(puma, rng)
        a = np.exp(-1 / rng.uniform(1, 3))
        lagged = lfilter([1 - a], [1, -a], clean - clean[0], axis=0) + clean[0]
        d = diagnose(puma.problem, lagged + C.noise(rng, clean.shape, 0.3 * sd))
        assert _named(d) == {("delay", "all")}
        assert d.effects[0]["value"] > 0.5 * dt


def test_gear_loss_is_named_as_load_friction(puma):
    rng = np.random.default_rng(6)
    hits = sum(_named(d) == data.truth for data, d in
               ((data, diagnose(puma.problem, data.tau)) for data in (C.gear_loss(puma, rng) for _ in range(4))))
    assert hits >= 3


def test_payload_is_named_on_its_body_with_its_mass_given_the_model(puma):
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(4):
        tau, body, mass, phi = C.payload(puma, rng)
        d = diagnose(C.payload_problem(puma, phi), tau)
        named = [e for e in d.effects if e["coordinate"] == body and e["kind"] in ("mass", "body")]
        if named and len(d.effects) == 1:
            hits += abs(named[0]["coefficients"]["m"]["value"] - mass) < 0.1 * mass
    assert hits >= 3


def test_refit_mode_cannot_see_a_payload_the_given_mode_can(puma):
    """The point of --params: refitting every inertial parameter absorbs the payload."""
    rng = np.random.default_rng(8)
    tau, body, mass, phi = C.payload(puma, rng)
    assert not diagnose(puma.problem, tau).effects
    assert diagnose(C.payload_problem(puma, phi), tau).effects


# ----- the gates ----------------------------------------------------------------------------------
def test_implausible_signs():
    assert implausible("viscous_friction", {"fv": -0.1})
    assert implausible("rotor_inertia", {"Ia": -1e-3})
    assert implausible("load_friction", {"mu": 1.5})
    assert implausible("delay", {"d": 0.5})
    assert not implausible("offset", {"off": -3.0})
    assert not implausible("coulomb_friction", {"fc": 0.3})


def test_negative_friction_in_the_data_is_not_named(planar):
    """A force like viscous friction with the wrong sign (energy in, not out) is significant
    but not physical: reported unsupported, never named."""
    rng = np.random.default_rng(9)
    phi, clean, sd = C.base(planar, rng)
    cand = next(c for c in planar.problem.candidates if c.label == "viscous_friction:q1")
    tau = clean - C.scaled(cand.columns @ [1.0], sd, 8) + C.noise(rng, clean.shape, sd)
    d = diagnose(planar.problem, tau)
    assert ("viscous_friction", "q1") not in _named(d)
    assert any(u["kind"] == "viscous_friction" and "positive" in u["reason"] for u in d.unsupported)
    assert d.verdict in ("unexplained", "partly explained") and not d.closed


def test_cross_validation_against_a_direct_leave_block_out_fit():
    rng = np.random.default_rng(10)
    n, f = 200, 2
    X = rng.standard_normal((n, f, 3))
    y = X @ [1.0, -2.0, 0.5] + rng.standard_normal((n, f)) * 0.1
    w = np.array([1.0, 3.0])
    cv, without = cross_validate(X, y, w, folds=4, margin=0, leave_out=[[1]])
    block = np.arange(50, 100)
    train = np.r_[0:50, 100:200]
    A = (X[train] * w[None, :, None]).reshape(-1, 3)
    beta = np.linalg.lstsq(A, (y[train] * w).reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(cv.residual[block], y[block] - X[block] @ beta, rtol=1e-9, atol=1e-12)
    beta = np.linalg.lstsq(A[:, [0, 2]], (y[train] * w).reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(without.residual[block], y[block] - X[block][:, :, [0, 2]] @ beta, rtol=1e-9,
                               atol=1e-12)


def test_stability_flags_a_coefficient_that_changes_and_not_one_that_does_not():
    rng = np.random.default_rng(11)
    n = 1000
    z = rng.standard_normal((n, 1, 1))
    steady = z[:, :, 0] * 2.0 + rng.standard_normal((n, 1)) * 0.1
    drifting = z[:, :, 0] * np.linspace(0.5, 3.5, n)[:, None] + rng.standard_normal((n, 1)) * 0.1
    w = np.ones(1)
    assert not stability(steady, z, w).unstable(0.01)
    assert stability(drifting, z, w).unstable(0.01)


def test_stability_test_has_its_size_under_the_null_and_power_against_a_step():
    """The blocks' chi-square is calibrated: with one coefficient and white noise it rejects
    at 5 % in about 5 % of datasets, and a 20 % step in the coefficient halfway is found in
    nearly all. (Its block covariances were once multiplied by the block length: p was 1
    always and the test was inert.)"""
    rng = np.random.default_rng(12)
    n, w = 1000, np.ones(1)
    null, step = [], []
    for _ in range(200):
        z = rng.standard_normal((n, 1, 1))
        null.append(stability(z[:, :, 0] * 2.0 + rng.standard_normal((n, 1)), z, w).pvalue)
        jump = np.where(np.arange(n) < n // 2, 2.0, 2.4)[:, None]
        step.append(stability(z[:, :, 0] * jump + rng.standard_normal((n, 1)), z, w).pvalue)
    assert 0.02 <= np.mean(np.array(null) < 0.05) <= 0.10
    assert np.mean(np.array(step) < 0.05) >= 0.9


# ----- the verb -----------------------------------------------------------------------------------
def test_verb_params_payload_and_verdict_first(tmp_path):
    """simulate with a payload the model lacks, then diagnose --params with the model's own file:
    the body is named, the text leads with the verdict."""
    runner = CliRunner()
    mech = resolve("planar_2r")
    phi_file = Path(mech.path)                 # the model's own file and inertias
    motion = trajectory_motion(mech, 400)
    sample = evaluate(mech, motion)
    problem = prepare(mech, motion, sample)
    from baseparams.dynamics.forces import standard_parameters
    phi = standard_parameters(resolve(str(phi_file)))
    true = phi.copy()
    true[10 * (len(mech.bodies) - 1)] += 0.5   # half a kilogram at the last link's frame origin
    rng = np.random.default_rng(12)
    clean = problem.inertial @ true
    tau = clean + rng.standard_normal(clean.shape) * 0.01 * np.sqrt(np.mean(clean ** 2, axis=0))
    data = tmp_path / "d.csv"
    header = ["t"] + [f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in ("q1", "q2")]
    rows = np.column_stack([motion.t, motion.q, motion.qd, motion.qdd, tau])
    data.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    result = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--params", str(phi_file), "--format", "json"])
    assert result.exit_code in (0, 1), result.output + result.stderr
    report = json.loads(result.stdout)
    named = [(e["kind"], e["coordinate"]) for e in report["effects"]]
    assert len(named) == 1 and named[0][0] in ("mass", "body")
    assert report["effects"][0]["coefficients"]["m"]["value"] == pytest.approx(0.5, rel=0.1)
    text = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--params", str(phi_file)])
    assert text.stdout.startswith("verdict: ")


def test_write_is_refused_before_the_run_for_a_urdf(tmp_path):
    urdf = tmp_path / "r.urdf"
    assert CliRunner().invoke(main, ["convert", "planar_2r", "-o", str(urdf)]).exit_code == 0
    result = CliRunner().invoke(main, ["diagnose", str(urdf), str(tmp_path / "missing.csv"),
                                       "--write", str(tmp_path / "out.toml")])
    assert result.exit_code == 2
    assert "--write needs a TOML mechanism file" in result.stderr      # not the missing data file


def test_max_steps_when_hit_is_reported(puma):
    rng = np.random.default_rng(13)
    phi, clean, sd = C.base(puma, rng)
    by = {c.label: c for c in puma.problem.candidates}
    tau = clean + sum(C.scaled(by[f"viscous_friction:{q}"].columns @ [1.0], sd, 8) for q in ("q1", "q2", "q3"))
    tau = tau + C.noise(rng, clean.shape, sd)
    d = diagnose(puma.problem, tau, max_steps=1)
    assert d.unexplained["significant_candidates_left"] and d.unexplained["max_steps"] == 1
    assert "--max-steps 1" in d.notes[0]
    assert not d.closed


@pytest.mark.parametrize("text", ["chain4", "tree1"])
def test_smooth_coulomb_and_delay_on_generated_mechanisms(text):
    """Not only the built-ins: a generated chain and tree, a smooth Coulomb law on the first
    coordinate and a 1.5-sample delay, each named (the four-bar: the next test)."""
    from baseparams.recordings.simulate import random_physical_inertia
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    m = parse_mechanism(generate.serial_chain(4) if text == "chain4" else generate.tree(1))
    motion = trajectory_motion(m, 600)
    problem = prepare(m, motion, evaluate(m, motion))
    rng = np.random.default_rng(3)
    clean = problem.inertial @ random_physical_inertia(m, rng)
    sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
    qd = motion.qd[:, 0]
    force = np.zeros_like(clean)
    force[:, 0] = np.tanh(qd / (0.05 * np.sqrt(np.mean(qd ** 2))))
    force *= 6 * sd[0] / np.sqrt(np.mean(force[:, 0] ** 2))
    d = diagnose(problem, clean + force + rng.standard_normal(clean.shape) * sd)
    assert _named(d) == {("coulomb_friction", problem.coordinates[0])}
    t = motion.t
    lagged = np.stack([np.interp(t - 1.5 * (t[1] - t[0]), t, clean[:, k]) for k in range(clean.shape[1])], axis=1)
    d = diagnose(problem, lagged + rng.standard_normal(clean.shape) * sd)
    assert _named(d) == {("delay", "all")}


def test_delay_on_a_generated_four_bar_is_not_taken_for_friction():
    """A generated four-bar (one coordinate, 21 identifiable parameters), a 0.5-3 sample delay:
    at effect/noise 3 named (4 of 5 here: one is held back because the second-order term fits
    beyond it), below it (the 2 % noise: effect/noise 0.2-1.5) never a wrong name (ambiguous
    or none). Before the delay's column was fitted with the model and low-passed, viscous
    friction on a dependent joint was named for it in half the datasets at effect/noise 5 and
    in 8 of 30 below."""
    from baseparams.recordings.simulate import random_physical_inertia
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    m = parse_mechanism(generate.four_bar(2))
    motion = trajectory_motion(m, 1200)
    problem = prepare(m, motion, evaluate(m, motion))
    t = motion.t
    rng = np.random.default_rng(21)
    named, wrong = 0, 0
    for ratio in [3.0] * 5 + [None] * 5:
        clean = problem.inertial @ random_physical_inertia(m, rng)
        sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        lag = rng.uniform(0.5, 3.0) * (t[1] - t[0])
        lagged = np.stack([np.interp(t - lag, t, clean[:, k]) for k in range(clean.shape[1])], axis=1)
        if ratio is not None:
            sd = sd * np.max(np.sqrt(np.mean((lagged - clean) ** 2, axis=0)) / sd) / ratio
        found = _named(diagnose(problem, lagged + rng.standard_normal(clean.shape) * sd))
        named += ratio is not None and found == {("delay", "all")}
        wrong += bool(found - {("delay", "all")})
    assert named >= 4 and wrong == 0


def test_delay_column_is_the_true_torque_rate():
    """The delay's column against -dtau/dt of the clean torque (a generated four-bar, a
    2-sample delay, 2 % noise): within 10 % (3-8 % measured; 12-43 % without the low-pass),
    where the model fitted alone and differentiated as it is gives 24-51 % (its fitted noise
    in fast directions of the model's span)."""
    from baseparams.diagnose import derived
    from baseparams.recordings.data import bandwidth
    from baseparams.diagnose.workflow import reduced_model
    from baseparams.recordings.simulate import random_physical_inertia
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    m = parse_mechanism(generate.four_bar(2))
    motion = trajectory_motion(m, 600)
    problem = prepare(m, motion, evaluate(m, motion))
    t, rows = motion.t, slice(0, 600)
    model = reduced_model(problem.inertial, 600)
    rng = np.random.default_rng(22)
    for _ in range(3):
        clean = problem.inertial @ random_physical_inertia(m, rng)
        sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        lagged = np.stack([np.interp(t - 2 * (t[1] - t[0]), t, clean[:, k]) for k in range(clean.shape[1])], axis=1)
        y = lagged + rng.standard_normal(clean.shape) * sd
        alone = model @ WeightedLinearModel(model, y).fit().coefficients
        fit = lambda extra: WeightedLinearModel(np.concatenate([model, extra], axis=-1), y).fit().coefficients  # noqa: E731
        cutoff = derived.DELAY_CUTOFF_PER_BANDWIDTH * bandwidth(problem.qd, t[1] - t[0])
        column = derived.delay_column(model, y, rows, np.zeros_like(y), t, alone, fit, cutoff)[0][:, :, 0]
        truth = -np.gradient(clean, t, axis=0)
        assert np.linalg.norm(column - truth) < 0.1 * np.linalg.norm(truth)
        assert np.linalg.norm(-np.gradient(alone, t, axis=0) - truth) > 0.2 * np.linalg.norm(truth)


def test_load_friction_on_a_generated_four_bar_is_named_as_such():
    """Load friction on a four-bar's one coordinate: its column is built from the model's
    torque fitted together with it (the model fitted alone bent towards it, and Coulomb or
    position friction was named instead in 11 of 20; 16 of 20 right and 1 wrong measured)."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(41)
    outcomes = [C.run(s, C.gear_loss, rng)[2] for _ in range(6)]
    assert outcomes.count("right") >= 4 and outcomes.count("wrong") <= 1


def test_a_held_back_effect_is_tried_in_the_place_of_a_simpler_form_named_later():
    """Load friction on a four-bar's one coordinate under AR(1) 0.9 noise at effect/noise 20:
    it entered beside position friction and failed out of sample there; position friction
    failed too, and Coulomb friction, its simpler form, was named in its place, never judged
    against load friction (4 of the first 19 datasets of this stream). In Coulomb friction's
    place load friction predicts a typical held-out block 49-600 % better: it is named
    instead. True Coulomb friction on the same data is not replaced
    (``test_coulomb_friction_is_not_replaced_by_load_friction``)."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(2024)
    datasets = [C.gear_loss(s, rng, rho=0.9, ratio=20.0) for _ in range(19)]
    for k in (2, 5, 13, 18):
        d = diagnose(s.problem, datasets[k].tau)
        assert _named(d) == datasets[k].truth == {("load_friction", "qa")}
        assert any("it is named instead of coulomb_friction:qa" in note for note in d.notes)
        assert any(u["kind"] == "coulomb_friction" and "in its place predicts held-out blocks" in u["reason"]
                   for u in d.unsupported)


def test_coulomb_friction_is_not_replaced_by_load_friction():
    """The other way round: Coulomb friction hidden on the same four-bar (AR(1) 0.9 noise,
    effect/noise 20), where load friction is its closest rival: named as Coulomb friction in
    all 8, load friction never swapped in."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(2024)
    for _ in range(8):
        data = C.INSIDE["coulomb"](s, rng, rho=0.9, ratio=20.0)
        d = diagnose(s.problem, data.tau)
        assert _named(d) == data.truth
        assert not any("is named instead of" in note for note in d.notes)


def test_params_from_a_wrong_source_is_refused(tmp_path):
    data = tmp_path / "d.csv"
    assert CliRunner().invoke(main, ["simulate", "planar_2r", "-o", str(data), "--samples", "200"]).exit_code == 0
    result = CliRunner().invoke(main, ["diagnose", "planar_2r", str(data), "--params", "pendulum"])
    assert result.exit_code == 2 and "bodies do not match" in result.stderr
    bad = tmp_path / "bad.json"
    bad.write_text('{"x": 1}')
    result = CliRunner().invoke(main, ["diagnose", "planar_2r", str(data), "--params", str(bad)])
    assert result.exit_code == 2 and "no 'base' list" in result.stderr


def test_an_elastic_four_bar_is_not_named_a_delay():
    """A generated four-bar (one coordinate) whose torque passes through an elastic joint's
    resonance (1.5-3 times the motion's band, zeta 0.2): to first order a delay, and the
    second-order term could not tell (its inertial model absorbs most of it), so all 8 were
    named a delay. Over a grid of resonant lags the best one explains what the delay does:
    held back as one the data cannot tell from an elastic lag, in all 8."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(7)
    held = 0
    for _ in range(8):
        data = C.compliance(s, rng)
        d = diagnose(s.problem, data.tau)
        assert ("delay", "all") not in _named(d)
        held += any(u["kind"] == "delay" and "resonant lag (zeta" in u["reason"] for u in d.unsupported)
    assert held >= 6


def test_a_resonant_lag_does_not_hold_back_a_true_delay():
    """The same four-bar with its torques delayed 0.5-3 samples (effect/noise 5): the delay adds
    over every resonant lag of the grid (p below 1e-5 over the best) and is named in all 6."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(7)
    for _ in range(6):
        data = C.delay(s, rng)
        d = diagnose(s.problem, data.tau)
        assert _named(d) == {("delay", "all")}
        pvalue = d.effects[0]["checks"].get("over_resonant_lag_pvalue")
        assert pvalue is None or pvalue < 1e-4


# The campaign's generated chain (seed 2024), compliance with white noise, datasets 0 and 1:
# the PCG64 state before each was drawn.
CHAIN_ELASTIC = [
    (173417237837080309220082487578382986486, 263843294879837360010514471918415607657, 0, 983023243),
    (12041916908307643616041735451293306251, 263843294879837360010514471918415607657, 1, 2065839138),
]


def test_what_stands_in_for_another_joints_elastic_lag_is_not_named(monkeypatch):
    """q2 of a generated chain is elastic: an offset on q1 (cv gain 78 %, steady over the
    blocks) and on q4 were named, the inertial fit's compromise having moved q2's lag there;
    the lag of every joint's torque outdoes them, so nothing is named. (Judged on the typical
    held-out block, the offset on q4 is already too small to name: 5.7 %. With that size gate
    off, the lag's check still holds back the first dataset's offset.)"""
    from baseparams.diagnose import gates as diagnose_module
    s = C.generated_setting("chain4", 1200)
    outdone = 0
    for state in CHAIN_ELASTIC:
        d = diagnose(s.problem, C.compliance(s, _at(state)).tau)
        assert _named(d) == set()
        assert any(u["kind"] == "offset" for u in d.unsupported)
        outdone += any(u["kind"] == "offset" and "a lag of the joints' torques" in u["reason"] for u in d.unsupported)
    assert outdone >= 1
    monkeypatch.setattr(diagnose_module, "MIN_EFFECT_TO_NOISE", 0.0)
    d = diagnose(s.problem, C.compliance(s, _at(CHAIN_ELASTIC[0])).tau)
    assert _named(d) == set()
    assert any(u["kind"] == "offset" and "a lag of the joints' torques" in u["reason"] for u in d.unsupported)


# The campaign's generated four-bar (seed 2024), AR(1) 0.9 noise: Coulomb friction datasets
# 1 and 3, gear-loss datasets 1, 9 and 13: the PCG64 state before each was drawn.
FOUR_BAR_AR_COULOMB = [
    (261401354450567631690289128750557609539, 263843294879837360010514471918415607657, 1, 2884581700),
    (20495703654986603908264128494036303758, 263843294879837360010514471918415607657, 1, 2722545595),
]
FOUR_BAR_AR_GEAR_LOSS = [
    (36095531927994080082987842165207944243, 263843294879837360010514471918415607657, 0, 1742214268),
    (207848935721002361087758675688186144380, 263843294879837360010514471918415607657, 0, 1742214268),
    (211033253619964635905623831165282113944, 263843294879837360010514471918415607657, 0, 1742214268),
]


def _at(state: tuple) -> np.random.Generator:
    """A generator at a recorded PCG64 state (state, increment, has_uint32, uinteger)."""
    rng = np.random.default_rng()
    rng.bit_generator.state = {"bit_generator": "PCG64", "state": {"state": state[0], "inc": state[1]},
                               "has_uint32": state[2], "uinteger": state[3]}
    return rng


def test_a_sparse_truth_under_coloured_noise_is_tested_not_stood_in_for():
    """Whitened (AR(1) 0.9), a four-bar's Coulomb step and gear loss act on a few samples.
    Their tests were refused ('support'): the gear loss never entered and Coulomb friction on
    the other joint was named in all three; Coulomb friction, its comparison with viscous
    friction on the other joint refused (counted as nesting), ended ambiguous with it in both.
    Tested with the stationary variance: Coulomb named in both, the gear loss never wrongly."""
    s = C.generated_setting("four_bar2", 1200)
    for state in FOUR_BAR_AR_COULOMB:
        data = C.INSIDE["coulomb"](s, _at(state), rho=0.9)
        assert C.score(diagnose(s.problem, data.tau), data) == "right"
    outcomes = []
    for state in FOUR_BAR_AR_GEAR_LOSS:
        data = C.gear_loss(s, _at(state), rho=0.9)
        outcomes.append(C.score(diagnose(s.problem, data.tau), data))
    assert "wrong" not in outcomes and "right" in outcomes


# The campaign's generated chain (seed 2024), compliance with white noise, datasets 9 and 15.
CHAIN_ELASTIC_DELAY = [
    (115648710090958604810908194795775250070, 263843294879837360010514471918415607657, 1, 2700309412),
    (284687528343174702474450827150337079028, 263843294879837360010514471918415607657, 1, 2291169574),
]


def test_one_elastic_joints_lag_is_not_named_the_recordings_delay(monkeypatch):
    """q3 of a generated chain is elastic, and a delay of the whole recording was named (cv
    gain 7-9 %). Each joint's own delay: q3's 6.4-6.9 ms, the others' under 1.6 ms, each
    significantly below half of q3's: one joint's lag, held back. True delays on the same
    chain agree on every joint and stay named. (In the first dataset, once two ambiguous
    groups that predicted no held-out block left the model, the delay is too small to name
    before that check; with that size gate off, the per-joint check holds it back on both.)"""
    from baseparams.diagnose import gates as diagnose_module
    s = C.generated_setting("chain4", 1200)
    for state in CHAIN_ELASTIC_DELAY:
        d = diagnose(s.problem, C.compliance(s, _at(state)).tau)
        assert _named(d) == set()
        assert any(u["kind"] == "delay" for u in d.unsupported)
    assert next(u for u in d.unsupported if u["kind"] == "delay")["reason"].startswith("only q3 lags")
    monkeypatch.setattr(diagnose_module, "MIN_EFFECT_TO_NOISE", 0.0)
    reasons = []
    for state in CHAIN_ELASTIC_DELAY:
        d = diagnose(s.problem, C.compliance(s, _at(state)).tau)
        assert _named(d) == set()
        reasons.append(next(u for u in d.unsupported if u["kind"] == "delay"))
    assert all(r["reason"].startswith("only q3 lags") for r in reasons)
    held = reasons[1]
    assert held["per_joint_delay"]["q3"] > 4 * max(abs(v) for c, v in held["per_joint_delay"].items() if c != "q3")
    rng = np.random.default_rng(5)
    for _ in range(3):
        data = C.delay(s, rng)
        d = diagnose(s.problem, data.tau)
        assert _named(d) == {("delay", "all")}
        per_joint = np.array(list(d.effects[0]["checks"]["per_joint_delay"].values()))
        assert np.all(np.abs(per_joint - data.extra["d"]) < 0.2 * data.extra["d"])


def test_an_ambiguous_group_that_predicts_no_held_out_block_leaves_the_model():
    """The gate on ambiguous groups, all members left out together: two near-copies of a
    column the data do not contain are held back with the reason; two near-copies of the
    hidden effect's column are kept. (On the TX40, a group of position and Stribeck friction
    on joint 2 improved the held-out blocks by 0.15 %; beside it Coulomb friction on that
    joint was too small to name, and both left.)"""
    from baseparams.diagnose.gates import _gate
    rng = np.random.default_rng(3)
    n = 600
    t = np.linspace(0.0, 10.0, n)
    model = np.stack([np.ones(n), np.sin(t), np.cos(0.7 * t)], axis=1)[:, None, :]
    effect, unrelated = np.sign(np.sin(2.3 * t)), np.sin(5.1 * t) * np.cos(0.3 * t)
    candidates = [S.Candidate(kind, "a", ("c",), (column + 0.01 * rng.standard_normal(n))[:, None, None])
                  for kind, column in [("x", effect), ("y", effect), ("z", unrelated), ("w", unrelated)]]
    y = (model @ np.array([0.5, 1.0, -2.0]) + 0.5 * effect[:, None] + 0.1 * rng.standard_normal((n, 1)))
    kept, out = _gate(None, model, candidates, [0, 1, 2, 3], [], y, np.ones(1), 0.05, 5, {},
                      groups={0: [0, 1], 2: [2, 3]})
    assert kept == [] and [u["index"] for u in out] == [2]
    assert out[0]["members"] == [2, 3] and out[0]["reason"].startswith("ambiguous (z:a | w:a); all together: ")


# The campaign's generated four-bar (seed 77), a delay under AR(1) 0.9 noise: dataset 9.
FOUR_BAR_AR_DELAY = (219946614607361241879459152652146026049, 336983293413220778415499640756163231851, 0, 795133399)


def test_the_delays_low_pass_is_chosen_by_the_data(monkeypatch):
    """A 0.75-sample delay on a four-bar's one coordinate, AR(1) 0.9 noise. With the delay's
    column low-passed at 10 times the speeds' bandwidth, viscous friction on a dependent
    joint was named instead (the fast part of the derivative, which tells them apart after
    whitening, filtered away); with the low-pass a shape chosen from 10, 20 and 40 times, the
    delay is named, at a wider low-pass, and within 5 % of the truth."""
    from baseparams.diagnose import derived
    from baseparams.recordings.data import bandwidth
    s = C.generated_setting("four_bar2", 1200)
    data = C.delay(s, _at(FOUR_BAR_AR_DELAY), rho=0.9)
    d = diagnose(s.problem, data.tau)
    assert C.score(d, data) == "right"
    delay = next(e for e in d.effects if e["kind"] == "delay")
    band = bandwidth(s.problem.qd, s.motion.t[1] - s.motion.t[0])
    assert delay["shape"]["low_pass_hz"] > 1.5 * derived.DELAY_CUTOFF_PER_BANDWIDTH * band
    assert abs(delay["value"] / data.extra["d"] - 1) < 0.05
    monkeypatch.setattr(derived, "DELAY_CUTOFFS_PER_BANDWIDTH", (derived.DELAY_CUTOFF_PER_BANDWIDTH,))
    narrow = diagnose(s.problem, data.tau)
    assert _named(narrow) == {("viscous_friction", "qd")}


def test_held_out_gain_is_the_typical_blocks_improvement():
    """The geometric mean over blocks of SSE without / SSE with, minus 1: a block both models
    extrapolate badly (its SSE scaled by the same factor in both) does not move it, where it
    decided the ratio of the totals; a block both predict exactly counts as no change."""
    from baseparams.diagnose.outofsample import CrossValidation, held_out_gain
    residual = np.zeros((5, 1))
    whole = CrossValidation(residual, np.array([1.0, 2.0, 1.0, 4.0, 2.0]))
    ratios = np.array([4.0, 9.0, 2.0, 1.0, 0.5])
    without = CrossValidation(residual, whole.sse * ratios)
    assert held_out_gain(without, whole) == pytest.approx(np.prod(ratios) ** 0.2 - 1, rel=1e-12)
    bad = np.array([1.0, 1.0, 1.0, 1.0, 300.0])
    assert held_out_gain(CrossValidation(residual, without.sse * bad), CrossValidation(residual, whole.sse * bad)) \
        == pytest.approx(held_out_gain(without, whole), rel=1e-12)
    totals = (np.sum(without.sse * bad) - np.sum(whole.sse * bad)) / np.sum(whole.sse * bad)
    assert abs(totals - held_out_gain(without, whole)) > 0.5
    exact = CrossValidation(residual, np.array([0.0, 1.0]))
    assert held_out_gain(CrossValidation(residual, np.array([0.0, 4.0])), exact) == pytest.approx(1.0)


def test_a_block_that_cannot_determine_an_effect_does_not_count_against_it():
    """A column nearly a copy of the model's except in one block: fitted without that block it
    cannot be told from the model's, so its prediction there carries a variance (s^2 tr(X^T X
    (H_whole - H_smaller))) far above the block's noise, checked against the prediction
    variances computed directly. Such a block does not count against the effect (it counts
    for it when the effect predicts it better anyway), unless fewer than half the blocks
    determine it."""
    from baseparams.diagnose.outofsample import CrossValidation, blocks, held_out_gain
    rng = np.random.default_rng(4)
    n = 500
    t = np.linspace(0, 10, n)
    a = np.sin(t)
    e = 1.001 * a + 0.001 * np.cos(3 * t)
    odd = blocks(n)[2]
    e[odd] = a[odd] + np.cos(3 * t[odd])
    X = np.stack([a, e], axis=-1)[:, None, :]
    y = X @ [1.0, 0.5] + rng.standard_normal((n, 1)) * 0.1
    w = np.array([10.0])
    whole, without = cross_validate(X, y, w, margin=0, leave_out=[[1]])
    for k, block in enumerate(blocks(n)):
        train = np.setdiff1d(np.arange(n), block)
        A, B = X[train, 0] * 10, X[block, 0] * 10
        added = (np.einsum("ip,pq,iq->i", B, np.linalg.inv(A.T @ A), B)
                 - B[:, 0] ** 2 / (A[:, 0] @ A[:, 0]))
        assert without.determined[k] == (added.sum() <= len(block))
    assert list(without.determined) == [True, True, False, True, True]
    ratios = without.sse / whole.sse
    counted = [0, 1, 3, 4] if ratios[2] < 1 else [0, 1, 2, 3, 4]
    assert held_out_gain(without, whole) == pytest.approx(np.exp(np.mean(np.log(ratios[counted]))) - 1)
    residual = np.zeros((5, 1))
    sse = np.array([1.0, 2.0, 1.0, 4.0, 2.0])
    whole = CrossValidation(residual, sse)
    undetermined_worse = CrossValidation(residual, sse * [4.0, 9.0, 0.1, 1.0, 0.5], np.array([1, 1, 0, 1, 1], bool))
    assert held_out_gain(undetermined_worse, whole) == pytest.approx((4 * 9 * 0.5) ** 0.25 - 1)
    undetermined_better = CrossValidation(residual, sse * [4.0, 9.0, 30.0, 1.0, 0.5], np.array([1, 1, 0, 1, 1], bool))
    assert held_out_gain(undetermined_better, whole) == pytest.approx((4 * 9 * 30 * 0.5) ** 0.2 - 1)
    few = CrossValidation(residual, sse * [4.0, 9.0, 0.1, 1.0, 0.5], np.array([True, False, False, True, False]))
    assert held_out_gain(few, whole) == pytest.approx((4 * 9 * 0.1 * 0.5) ** 0.2 - 1)


def test_a_block_that_cannot_determine_an_effect_does_not_hold_it_back():
    """A pendulum's spring at effect/noise 12, fitted on the first 70 %: beyond gravity it is
    nearly the cubic q - sin q, and the one block holding the motion's large negative angles
    is where the others' fit cannot pin it down (3-30 times the SSE without it there, though
    it predicts the other four blocks better). With that block counted, the spring is named
    in 1 of these 8 datasets ('does not predict held-out blocks better' or too small); where
    that block does not count against it, in 7, and in the eighth cogging (harmonics of q,
    correlation 0.995 with the spring beyond the model, adding over it at p 0.014) is named
    with the spring as its rival."""
    from baseparams.diagnose import gates as diagnose_module
    from baseparams.diagnose import outofsample
    from baseparams.recordings.simulate import random_physical_inertia
    s = C.setting("pendulum", 1000)
    spring = next(c for c in s.problem.candidates if c.kind == "spring")
    q = np.asarray(s.motion.q, float).reshape(s.motion.count, -1)[:, 0]

    def named(seed):
        rng = np.random.default_rng(seed)
        clean = s.problem.inertial @ random_physical_inertia(s.mechanism, rng)
        sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        k = rng.uniform(0.5, 1.5)
        force = spring.columns @ np.array([k, k * (q.mean() + 0.1 * q.std())])
        d = diagnose(s.problem, clean + C.scaled(force, sd, 12) + C.noise(rng, clean.shape, sd), holdout=0.3)
        stand_ins = [e for e in d.effects if e["kind"] != "spring"]
        return _named(d), all(any(r["candidate"] == "spring:theta" and r["correlation"] > 0.99
                                  for r in e["rivals"]) for e in stand_ins)

    scored = [named(seed) for seed in range(8)]
    assert sum(("spring", "theta") in n for n, _ in scored) >= 7
    assert all(len(n) <= 1 and rival_is_the_spring for n, rival_is_the_spring in scored)
    plain = outofsample.held_out_gain
    every_block = (lambda without, whole: plain(outofsample.CrossValidation(without.residual, without.sse),
                                                outofsample.CrossValidation(whole.residual, whole.sse)))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(diagnose_module, "held_out_gain", every_block)
        assert sum(("spring", "theta") in named(seed)[0] for seed in range(8)) <= 2


# The PUMA campaign's (seed 2024) torque ripple in time under AR(1) 0.9 noise, dataset 1.
PUMA_RIPPLE_AR = (322375931215529888877736177227543293363, 263843294879837360010514471918415607657, 1, 1541058982)


def test_effects_that_cancel_each_other_are_not_named(puma_1200, monkeypatch):
    """A torque ripple periodic in time on one PUMA joint (outside the catalogue): a spring and
    cogging on q3 fitted it together with forces ~240 times the joint's torque, cancelling to a
    few N m, each significant and steady over the blocks. No such force acts in a mechanism:
    both are held back (without the check, both are named)."""
    from baseparams.diagnose import gates as diagnose_module
    data = C.OUTSIDE["ripple"](puma_1200, _at(PUMA_RIPPLE_AR), rho=0.9)
    d = diagnose(puma_1200.problem, data.tau)
    assert _named(d) == set()
    cancelled = {u["kind"] for u in d.unsupported if "other columns cancel it" in u["reason"]}
    assert cancelled == {"spring", "cogging"}
    monkeypatch.setattr(diagnose_module, "CANCELS", np.inf)
    assert _named(diagnose(puma_1200.problem, data.tau)) == {("spring", "q3"), ("cogging", "q3")}


def test_an_effect_that_dominates_the_torque_is_not_taken_for_cancelling():
    """The cancelling check compares a force with the measured torque, which holds a real
    effect: a spring on a generated chain's q2 with 20 times the inertial torque's RMS is
    named, with its stiffness, and not held back."""
    from baseparams.recordings.simulate import random_physical_inertia
    s = C.generated_setting("chain4", 1200)
    spring = next(c for c in s.problem.candidates if c.kind == "spring" and c.coordinate == "q2")
    q2 = np.asarray(s.motion.q, float).reshape(s.motion.count, -1)[:, 1]
    for seed in range(2):
        rng = np.random.default_rng(seed)
        clean = s.problem.inertial @ random_physical_inertia(s.mechanism, rng)
        unit = spring.columns @ np.array([1.0, np.mean(q2)])
        k = 20 * np.sqrt(np.mean(clean[:, 1] ** 2) / np.mean(unit[:, 1] ** 2))
        sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        d = diagnose(s.problem, clean + k * unit + C.noise(rng, clean.shape, sd))
        assert _named(d) == {("spring", "q2")}
        assert d.effects[0]["value"]["k"] == pytest.approx(k, rel=0.02)
        assert not d.unsupported


FOUR_BAR_AR_VISCOUS = (333427002749827781086311162658377319386, 263843294879837360010514471918415607657, 0,
                       1729936829)


def test_one_badly_extrapolated_block_does_not_hold_back_a_true_effect(monkeypatch):
    """Viscous friction on a four-bar's one coordinate under AR(1) 0.9 noise (z 29, one
    coefficient over the blocks). With 21 inertial parameters on few effective samples, the
    last held-out block is extrapolated badly with or without it; judged on the totals it
    'did not predict held-out blocks better' (-4 %) while the other four blocks improved 6 to
    33 times. Judged on the typical block (:func:`held_out_gain`) it is named."""
    from baseparams.diagnose import gates as diagnose_module
    s = C.generated_setting("four_bar2", 1200)
    data = C.INSIDE["viscous"](s, _at(FOUR_BAR_AR_VISCOUS), rho=0.9)
    d = diagnose(s.problem, data.tau)
    assert C.score(d, data) == "right"
    monkeypatch.setattr(diagnose_module, "held_out_gain",
                        lambda without, whole: (without.total - whole.total) / whole.total)
    totals = diagnose(s.problem, data.tau)
    assert not totals.effects
    assert any(u["kind"] == "viscous_friction" and "does not predict held-out blocks better" in u["reason"]
               for u in totals.unsupported)


FOUR_BAR_AR_ELASTIC = (314967344717288324771473941610976038462, 336983293413220778415499640756163231851, 0,
                       795133399)


def test_viscous_friction_standing_in_for_an_elastic_lag_is_held_back(monkeypatch):
    """A four-bar whose one coordinate's torque passes through an elastic joint's resonance,
    AR(1) 0.9 noise: a resonant lag of a torque that is mostly gravity is to first order a
    viscous force, and viscous friction was named (it predicts four of five held-out blocks
    better). It must add over every resonant lag of the grid, as the delay must: it does not,
    and is held back with that reason; without the check it is named."""
    from baseparams.diagnose import gates as diagnose_module
    s = C.generated_setting("four_bar2", 1200)
    data = C.compliance(s, _at(FOUR_BAR_AR_ELASTIC), rho=0.9)
    d = diagnose(s.problem, data.tau)
    assert C.score(d, data) != "wrong"
    assert any(u["kind"] == "viscous_friction" and "cannot tell viscous friction from an elastic lag" in u["reason"]
               for u in d.unsupported)
    monkeypatch.setattr(diagnose_module, "LAG_STAND_INS", ())
    assert ("viscous_friction", "qa") in _named(diagnose(s.problem, data.tau))


def test_campaign_counts_a_simpler_form_apart_from_a_wrong_name():
    """bench_diagnose's scoring: Coulomb friction named where position friction (which
    generalises it) was hidden on that joint is a simpler form, not a wrong name; on another
    joint, or a kind the truth does not generalise, it is wrong."""
    from types import SimpleNamespace
    import bench_diagnose as BD

    def named(*pairs):
        return SimpleNamespace(effects=[{"kind": k, "coordinate": c} for k, c in pairs], ambiguous=[])
    truth = [("position_friction", "s2")]
    assert BD.outcome(named(("coulomb_friction", "s2")), truth) == "simpler"
    assert BD.outcome(named(("coulomb_friction", "s3")), truth) == "wrong"
    assert BD.outcome(named(("viscous_friction", "s2")), truth) == "wrong"
    assert BD.outcome(named(("position_friction", "s2")), truth) == "right"
    assert BD.outcome(named(("position_friction", "s2"), ("coulomb_friction", "s2")), truth) == "right+extra"
    assert BD.outcome(named(("viscous_friction", "all")), [("delay", "all")]) == "wrong"   # a derived kind's truth


def test_harmonics_of_q_are_default_candidates_on_angles_only():
    """Position friction and cogging (harmonics of q) on a prismatic leg, q in metres, were a
    Coulomb friction plus a slope: the Stewart platform's legs had Coulomb friction named for
    position friction and the reverse in 9 of 40 pairs. By default they are tried on angles
    only; named explicitly (KIND:COORD) they are still tried on a length."""
    from baseparams.diagnose.candidates import all_pairs, parse_selection
    m = resolve("stewart_platform")
    angles = [c for c in m.coordinates if m.is_angle(c)]
    lengths = [c for c in m.coordinates if not m.is_angle(c)]
    assert angles and lengths
    pairs = all_pairs(m)
    for kind in ("position_friction", "cogging"):
        assert {c for k, c in pairs if k == kind} == set(angles)
        assert {c for k, c in parse_selection(m, [kind]) if k == kind} == set(angles)
        assert parse_selection(m, [f"{kind}:{lengths[0]}"]) == [(kind, lengths[0])]
    assert {c for k, c in pairs if k == "coulomb_friction"} >= set(lengths)


def test_friction_the_model_has_but_the_data_lack_is_corrected_not_stood_in_for(tmp_path):
    """The mechanism says Coulomb friction fc 3 on q2 and q3 (known, subtracted); the data (a
    PUMA 560 simulated without it) have none. Named: a correction of -3 on each (total within
    ABSENT of zero: the model's own is not in the data). Before, Coulomb friction was no
    candidate where the model had it, and position friction was named on both joints with
    fcc -3.2 about q = 0: a negative Coulomb friction that drives the motion everywhere."""
    mech = _puma_with(tmp_path, [("coulomb_friction", "q2", {"fc": 3.0}), ("coulomb_friction", "q3", {"fc": 3.0})])
    runner = CliRunner()
    log = tmp_path / "plain.csv"
    assert runner.invoke(main, ["simulate", "puma560", "-o", str(log), "--samples", "1200", "--noise", "0.5",
                                "--seed", "1", "--quiet"]).exit_code == 0
    report = json.loads(runner.invoke(main, ["diagnose", str(mech), str(log), "--format", "json", "--quiet"]).stdout)
    named = {(e["kind"], e["coordinate"]): e for e in report["effects"]}
    assert set(named) == {("coulomb_friction", "q2"), ("coulomb_friction", "q3")}
    for e in named.values():
        assert e["known"] == {"fc": 3.0} and abs(e["value"] + 3.0) < 0.05 * 3.0


def test_position_friction_that_drives_the_motion_is_not_friction():
    """Position friction fcc -3 about the PUMA's q2 travel resists nowhere (a negative
    Coulomb friction in its clothes): held back with the reason; +3 resists and passes."""
    from baseparams.diagnose.gates import _unphysical
    from baseparams.recordings.simulate import trajectory_motion as motion_of
    m = resolve("puma560")
    problem = prepare(m, motion_of(m, 300))
    cand = next(c for c in problem.candidates if (c.kind, c.coordinate) == ("position_friction", "q2"))
    assert "drives the motion instead of resisting it" in _unphysical(problem, cand, {"fcc": -3.0, "fcs": 0.0})
    assert _unphysical(problem, cand, {"fcc": 3.0, "fcs": 0.0}) == ""


def _puma_with(tmp_path, effects) -> Path:
    from baseparams.diagnose.fixed import effects_toml
    from baseparams.model.mechanism import EffectSpec
    mech = tmp_path / "puma_known.toml"
    mech.write_text(Path(resolve("puma560").path).read_text() + "\n"
                    + effects_toml([EffectSpec(k, c, v) for k, c, v in effects], "test"))
    return mech


@pytest.mark.parametrize("known, truth", [(0.5, 3.0), (4.0, 3.0)])
def test_an_effect_the_model_knows_is_corrected_to_the_datas_value(tmp_path, known, truth):
    """The model's own viscous friction on q2 (known: a URDF's damping) is 0.5 or 4 where the
    data have 3: the candidate of its kind there estimates the correction (2.5, or -1: less
    friction than the model says, still physical in total), reported with ``known`` and the
    total, and --write leaves the file to the user with the value to set. Before, a known
    effect barred its kind's candidate: a Panda's URDF damping of 0.003 kept its viscous
    friction (0.07-1.4 N m s/rad in the data) from being named on every joint."""
    mech = _puma_with(tmp_path, [("viscous_friction", "q2", {"fv": known})])
    runner = CliRunner()
    log = tmp_path / "data.csv"
    assert runner.invoke(main, ["simulate", "puma560", "-o", str(log), "--samples", "1200", "--noise", "0.5",
                                "--seed", "2", "--effect", f"viscous_friction:q2={truth}", "--quiet"]).exit_code == 0
    out = tmp_path / "written.toml"
    result = runner.invoke(main, ["diagnose", str(mech), str(log), "--format", "json", "--quiet", "--write", str(out)])
    report = json.loads(result.stdout)
    named = {(e["kind"], e["coordinate"]): e for e in report["effects"]}
    assert set(named) == {("viscous_friction", "q2")}, named
    entry = named["viscous_friction", "q2"]
    assert entry["known"] == {"fv": known}
    assert entry["value"] + known == pytest.approx(truth, rel=0.03)
    assert any(n.startswith("--write: viscous_friction:q2 corrects the model's own fv = ") for n in report["notes"])
    assert not out.exists()
    text = runner.invoke(main, ["diagnose", str(mech), str(log), "--quiet"]).stdout
    assert f"correcting the model's own fv = {known:.4g} (total fv = " in text


def test_a_correction_whose_total_is_not_physical_is_held_back():
    """A correction is judged on the total: -1.5 beside a known fv = 1 is a negative viscous
    friction (not named), -0.5 is fine; without a known value -0.5 is not."""
    from baseparams.diagnose.fixed import effects_toml
    from baseparams.diagnose.gates import _unphysical
    from baseparams.io.loader import parse_mechanism
    from baseparams.recordings.simulate import trajectory_motion as motion_of
    from baseparams.model.mechanism import EffectSpec
    text = Path(resolve("puma560").path).read_text()
    for known, correction, physical in ((1.0, -1.5, False), (1.0, -0.5, True), (None, -0.5, False)):
        extra = "" if known is None else effects_toml([EffectSpec("viscous_friction", "q2", {"fv": known})], "test")
        m = parse_mechanism(text + "\n" + extra)
        problem = prepare(m, motion_of(m, 200))
        cand = next(c for c in problem.candidates if (c.kind, c.coordinate) == ("viscous_friction", "q2"))
        reason = _unphysical(problem, cand, {"fv": correction})
        assert (reason == "") == physical, reason
        if known is not None and not physical:
            assert reason.startswith("with the model's own fv = 1 the total is not physical")


def test_an_effects_test_added_to_a_model_is_the_selections_own(puma):
    """``final.added_test`` (an unsupported effect judged beside the final model) makes the
    selection's own test: added to the model of the first step, with that step's filter and
    weights, it gives the chosen candidate's statistic and p value there."""
    P = puma.problem
    place = puma.coordinates[3]
    cands = _offset_cogging_spring(P, place)
    rng = np.random.default_rng(16)
    phi, clean, sd = C.base(puma, rng)
    tau = clean + C.scaled(C.on(clean.shape[1], 3, np.ones(len(clean))), sd, 5.0) + C.noise(rng, clean.shape, sd, 0.9)
    chosen = S.select_whitened(P.inertial, tau, cands)
    first = chosen.steps[0]
    i = first.chosen
    test = FN.added_test(P.inertial, tau, chosen.candidates, [], i, first.whiten, first.fit.weights)
    assert test is not None and test.tested
    np.testing.assert_allclose(test.stat, first.tests[i].stat, rtol=1e-6)
    assert abs(test.pvalue - first.tests[i].pvalue) <= 1e-6 + 1e-6 * first.tests[i].pvalue
