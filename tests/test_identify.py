"""Identification (baseparams.identify.base, .fit, .physical and the two verbs).

Independent checks: the base regressor against K itself for every solver; the pendulum's
estimates against its closed form and its standard deviations against statsmodels' OLS;
recovery of a simulation's truth (inertia and hidden effects) within a few standard
deviations on built-in and generated mechanisms; the standard deviations against the
spread of the estimates over seeds; the physically consistent parameters against the
pseudo-inertia condition and the base estimates.
"""

import functools
import importlib.util
import json

import numpy as np
import pytest
import statsmodels.api as sm
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.cli.identify import parse_effect
from baseparams.errors import InputError
from baseparams.identify import physical
from baseparams.identify.base import BaseModel
from baseparams.recordings.data import write_measured
from baseparams.identify.fit import identify, split_effects
from baseparams.dynamics.forces import design
from baseparams.identify.physical import physical_fit, pseudo_inertia
from baseparams.recordings.simulate import simulate
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec

MECHANISMS = {
    "pendulum": lambda: resolve("pendulum"),
    "planar_2r": lambda: resolve("planar_2r"),
    "puma560": lambda: resolve("puma560"),
    "sla_suspension": lambda: resolve("sla_suspension"),
    "chain": lambda: parse_mechanism(generate.serial_chain(7, bodies=4)),
    "loop": lambda: parse_mechanism(generate.four_bar(5)),
}


@functools.cache
def mechanism(name):
    return MECHANISMS[name]()


@functools.cache
def base_model(name, solver="dp"):
    mech = mechanism(name)
    return BaseModel.from_result(registry.solvers()[solver].item.solve(mech), mech)


def truth_values(base, truth):
    """Every unknown's true value: base parameters B phi and the effects' coefficients."""
    phi = np.array([truth["parameters"][p] for p in base.parameters])
    values = dict(zip(base.names, base.values(phi)))
    for effect in truth["effects"]:
        values.update({f"{k}_{effect['coordinate']}": v for k, v in effect["values"].items()})
    return values


# ----- the base model -----------------------------------------------------------------------
@pytest.mark.parametrize("name, solver", [
    ("pendulum", "exact"), ("pendulum", "symbolic"), ("planar_2r", "dp"), ("planar_2r", "vp"),
    ("planar_2r", "exact"), ("planar_2r", "symbolic"), ("chain", "dp"), ("chain", "exact"),
    ("chain", "symbolic"), ("loop", "dp"), ("loop", "vp"), ("loop", "symbolic"), ("puma560", "exact")])
def test_base_columns_reproduce_the_regressor(name, solver):
    """K phi == K_b (B phi) for random phi: K's rows lie in the row space of every solver's B."""
    mech = mechanism(name)
    base = base_model(name, solver)
    data, _ = simulate(mech, samples=60)
    K = design(mech, data.motion, (), data.sample)[0].matrix
    phi = np.random.default_rng(0).normal(size=(len(mech.parameters), 5))
    direct = K @ phi
    np.testing.assert_allclose(base.columns(K) @ base.values(phi), direct, atol=1e-9 * np.abs(direct).max())
    assert base.residual_outside(K) < 1e-10
    assert base.B.shape == (base.rank, len(mech.parameters)) and base.solver == solver


# ----- closed form and statsmodels ----------------------------------------------------------
def test_pendulum_closed_form_and_statsmodels():
    """tau = Izz1 qdd + g (mx1 sin(theta) + my1 cos(theta)): the truth of a uniform rod (m L / 2,
    0, m L^2 / 3) within 4 std, and estimates and std equal to statsmodels' OLS on those columns."""
    mech = mechanism("pendulum")
    data, truth = simulate(mech, samples=400, noise_sd=0.02, seed=3)
    fit = identify(mech, data, base=base_model("pendulum", "exact"))
    assert fit.names == ("phi_b01", "phi_b02", "phi_b03")                  # mx1, my1, Izz1
    closed = np.array([1.2 * 0.5 / 2, 0.0, 1.2 * 0.5 ** 2 / 3])
    assert np.all(np.abs(fit.estimates - closed) < 4 * fit.std)
    theta, acc = data.motion.q[:, 0], data.motion.qdd[:, 0]
    X = np.column_stack([9.81 * np.sin(theta), 9.81 * np.cos(theta), acc])
    ols = sm.OLS(data.tau[:, 0], X).fit()
    # the sign of the my1 column depends on the body axes: compare magnitudes of that one
    np.testing.assert_allclose(np.abs(fit.estimates), np.abs(ols.params), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(fit.std, ols.bse, rtol=1e-6)
    assert abs(fit.noise_sd[0] - 0.02) < 0.003 and fit.nrms[0] < 0.05


# ----- recovery of the truth ----------------------------------------------------------------
@pytest.mark.parametrize("name, noise, samples", [("puma560", 0.02, 600), ("chain", 0.01, 500),
                                                  ("loop", 0.01, 500), ("planar_2r", 0.01, 300)])
def test_truth_recovered_within_a_few_std(name, noise, samples):
    mech = mechanism(name)
    data, truth = simulate(mech, samples=samples, noise_sd=noise, seed=7, random_inertia=True)
    base = base_model(name)
    fit = identify(mech, data, base=base)
    z = (fit.estimates - fit.stands_for(truth_values(base, truth))) / fit.std
    assert np.abs(z).max() < 4.5, (fit.names[int(np.argmax(np.abs(z)))], np.abs(z).max())
    np.testing.assert_allclose(fit.noise_sd, noise, rtol=0.25)
    assert 0.8 < fit.residual_variance < 1.25


def test_hidden_effects_on_a_generated_chain_recovered_when_named():
    mech = mechanism("chain")
    c = mech.coordinates
    hidden = [EffectSpec("coulomb_friction", c[0], {"fc": 0.5}), EffectSpec("viscous_friction", c[2], {"fv": 0.8}),
              EffectSpec("offset", c[1], {"off": -0.3})]
    data, truth = simulate(mech, samples=500, noise_sd=0.02, seed=2, effects=hidden)
    base = base_model("chain")
    fit = identify(mech, data, base=base, effects=[EffectSpec(s.kind, s.coordinate) for s in hidden])
    z = (fit.estimates - fit.stands_for(truth_values(base, truth))) / fit.std
    assert np.abs(z).max() < 4.5
    unnamed = identify(mech, data, base=base)
    # weighted least squares lowers the weighted sum, not every coordinate's residual: a
    # coordinate the effects do not touch may move by a fraction of a percent either way
    assert np.all(fit.nrms <= unnamed.nrms * 1.01) and unnamed.nrms.max() > 2 * fit.nrms.max()


@pytest.mark.parametrize("solver", ["dp", pytest.param("vp", marks=pytest.mark.slow)])
def test_sla_strut_spring_and_damper(solver):
    """A hidden spring and damper on the SLA's strut (a dependent coordinate). Named, the damper
    is recovered; the spring's rest force cannot be told from gravity (a spring between the
    chassis and the lower arm turning about a fixed axis: |C - H|^2 is affine in cos and sin of
    the arm angle), so kq0 is absorbed and k stands for k + kq0 / LD, recovered within a few std."""
    mech = mechanism("sla_suspension")
    base = base_model("sla_suspension", solver)
    hidden = [EffectSpec("spring", "damper_s", {"k": 3000, "kq0": 20}),
              EffectSpec("viscous_friction", "damper_s", {"fv": 400})]
    data, truth = simulate(mech, samples=600, noise_sd=0.05, seed=1, effects=hidden)
    fit = identify(mech, data, base=base, effects=[EffectSpec(s.kind, s.coordinate) for s in hidden])
    assert set(fit.absorbed) == {"kq0_damper_s"}
    assert fit.absorbed["kq0_damper_s"]["k_damper_s"] == pytest.approx(1 / 0.35, rel=1e-6)   # 1 / LD
    z = (fit.estimates - fit.stands_for(truth_values(base, truth))) / fit.std
    assert np.abs(z).max() < 4.5
    assert abs(fit.value("fv_damper_s") - 400) < 4 * fit.std[fit.names.index("fv_damper_s")]
    # dp's coefficients reproduce K only to about 5e-4 here (noted), vp's exactly
    assert fit.base_model_error < (1e-10 if solver == "vp" else 1e-2)
    assert any("kq0_damper_s cannot be identified" in n for n in fit.notes)
    unnamed = identify(mech, data, base=base)
    assert unnamed.nrms[0] > 20 * fit.nrms[0]
    entry = fit.to_json()["effects"][0]["coefficients"][1]
    assert entry["value"] is None and "k_damper_s" in entry["absorbed_into"]


def test_std_is_calibrated_over_seeds():
    """The reported std matches the spread of the estimates over 40 noise draws (within
    sampling error: the ratio of 40 draws is within +-25 % at well over 99 %)."""
    mech = mechanism("planar_2r")
    base = base_model("planar_2r")
    runs = [identify(mech, simulate(mech, samples=200, noise_sd=[0.3, 0.05], seed=s)[0], base=base)
            for s in range(40)]
    estimates = np.array([r.estimates for r in runs])
    reported = np.mean([r.std for r in runs], axis=0)
    ratio = estimates.std(axis=0, ddof=1) / reported
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio
    # weighting: the quiet coordinate's SD is found, and weighted std beats unweighted OLS
    assert np.allclose(np.mean([r.noise_sd for r in runs], axis=0), [0.3, 0.05], rtol=0.05)


def test_too_few_samples_is_an_input_error():
    mech = mechanism("puma560")
    data, _ = simulate(mech, samples=12)
    with pytest.raises(InputError, match="equations for"):
        identify(mech, data.take(slice(0, 5)), base=base_model("puma560"))


def test_rotor_inertia_on_the_first_axis_is_absorbed_into_its_base_parameter():
    """A rotor's inertia on the PUMA's first (vertical) axis only adds to the base parameter
    that holds Izz1 (its column is qdd1 on q1 alone): absorbed with coefficient exactly 1."""
    mech = mechanism("puma560")
    base = base_model("puma560", "exact")
    column = base.B[:, list(base.parameters).index("Izz1")]
    holder = [base.names[k] for k in np.nonzero(column)[0]]
    assert len(holder) == 1 and column[base.names.index(holder[0])] == 1
    data, _ = simulate(mech, samples=100, noise_sd=0.01)
    fit = identify(mech, data, base=base, effects=[EffectSpec("rotor_inertia", "q1"),
                                                   EffectSpec("viscous_friction", "q1")])
    assert fit.absorbed == {"Ia_q1": {holder[0]: pytest.approx(1.0, rel=1e-9)}}
    assert "fv_q1" in fit.names and "Ia_q1" not in fit.names


# ----- physically consistent parameters -----------------------------------------------------
@pytest.mark.parametrize("name", ["puma560", "chain"])
def test_physical_parameters_are_consistent_and_reproduce_the_base(name):
    pytest.importorskip("cvxpy", reason="physically consistent parameters need cvxpy (the 'physical' extra)")
    mech = mechanism(name)
    base = base_model(name)
    data, truth = simulate(mech, samples=500, noise_sd=0.01, seed=4, random_inertia=True)
    fit = identify(mech, data, base=base)
    found = physical_fit(fit.base_estimates, base, std=fit.std[:base.rank])
    for b in range(len(mech.bodies)):
        J = pseudo_inertia(found.parameters[10 * b: 10 * b + 10])
        assert np.linalg.eigvalsh(J)[0] >= -1e-7 * max(1.0, np.abs(J).max())
    # the truth is feasible and within a few std: the consistent fit may move the estimates
    # by no more than that
    assert found.max_deviation < 3
    np.testing.assert_allclose(base.values(found.parameters), fit.base_estimates,
                               atol=3 * fit.std[:base.rank].max() + 1e-9)


def test_physical_without_cvxpy_is_exit_2(monkeypatch, tmp_path):
    path = tmp_path / "d.csv"
    write_measured(path, simulate(mechanism("pendulum"), samples=40, noise_sd=0.01)[0])
    monkeypatch.setattr(physical, "cp", None)
    result = CliRunner().invoke(main, ["identify", "pendulum", str(path), "--solver", "dp", "--physical"])
    assert result.exit_code == 2 and "cvxpy" in result.stderr and "baseparams[physical]" in result.stderr


# ----- the verbs ---------------------------------------------------------------------------
def test_simulate_then_identify_json(tmp_path):
    # with cvxpy (the 'physical' extra) the fit adds the physically consistent parameters
    with_physical = importlib.util.find_spec("cvxpy") is not None
    runner = CliRunner()
    data, truth_path = tmp_path / "d.csv", tmp_path / "truth.json"
    result = runner.invoke(main, ["simulate", "planar_2r", "-o", str(data), "--truth", str(truth_path),
                                  "--effect", "viscous_friction:q2=0.7", "--noise", "0.02", "--seed", "3",
                                  "--samples", "300", "--random-inertia"])
    assert result.exit_code == 0, result.output
    out = tmp_path / "identified.json"
    result = runner.invoke(main, ["identify", "planar_2r", str(data), "--effect", "viscous_friction:q2",
                                  "--solver", "dp", "--format", "json", "-o", str(out)]
                           + ["--physical"] * with_physical)
    assert result.exit_code == 0, result.output
    # -o FILE is where the output goes (docs/cli.md, "One grammar"): nothing on stdout
    assert result.stdout == "" and f"wrote {out}" in result.stderr
    report = json.loads(out.read_text())
    assert set(report) >= {"base", "effects", "condition_number", "nrms", "noise_sd"}
    fv = report["effects"][0]["coefficients"][0]
    assert fv["name"] == "fv_q2" and abs(fv["value"] - 0.7) < 4 * fv["std"]
    assert fv["relative_std_percent"] == pytest.approx(100 * fv["std"] / abs(fv["value"]))
    if with_physical:
        assert {"physical", "physical_fit"} <= set(report)
        assert list(report["physical"]) == list(mechanism("planar_2r").parameters)
        assert all(isinstance(v, str) and np.isfinite(float(v)) for v in report["physical"].values())
    text = runner.invoke(main, ["identify", "planar_2r", str(data), "--solver", "dp"])
    assert text.exit_code == 0 and "condition number" in text.stdout and "NRMS" in text.stdout


def test_mechanism_effects_without_values_are_identified_with_values_subtracted(tmp_path):
    text = open(resolve("pendulum").path, encoding="utf-8").read()
    mech = parse_mechanism(text + '\n[[effects]]\nkind = "viscous_friction"\ncoordinate = "theta"\n'
                                  '\n[[effects]]\nkind = "offset"\ncoordinate = "theta"\nvalues = { off = "0.25" }\n')
    identified, known = split_effects(mech, [])
    assert [(s.kind, s.coordinate) for s in identified] == [("viscous_friction", "theta")]
    assert [(s.kind, s.coordinate) for s in known] == [("offset", "theta")]
    data, truth = simulate(mech, samples=300, noise_sd=0.01, seed=1,
                           effects=[EffectSpec("viscous_friction", "theta", {"fv": 0.4}), known[0]])
    fit = identify(mech, data, base=base_model("pendulum"), effects=identified, known=known)
    assert abs(fit.value("fv_theta") - 0.4) < 4 * fit.std[fit.names.index("fv_theta")]
    again, _ = split_effects(mech, [EffectSpec("offset", "theta")])       # named: identified, not known
    assert ("offset", "theta") in [(s.kind, s.coordinate) for s in again]


@pytest.mark.parametrize("text, values, reason", [
    ("spring:q1", True, "give 2 values"), ("spring:q1=1", True, "give 2 values"),
    ("spring:q1:k=1", True, "no value for kq0"), ("spring:q1:x=1,k=2", True, "NAME=VALUE"),
    ("viscous:q1", False, "unknown effect"), ("offset:nope", False, "not a joint coordinate"),
    ("offset:q1=2", False, "not a joint coordinate"), ("offset:q1=abc", True, "not a number"),
    ("offset", False, "expected KIND:COORD")])
def test_effect_option_errors(text, values, reason):
    with pytest.raises(InputError) as info:
        parse_effect(text, mechanism("planar_2r"), values=values)
    assert reason in str(info.value) and "--effect" in str(info.value)


def test_effect_option_forms():
    mech = mechanism("planar_2r")
    a = parse_effect("spring:q2=3,0.5", mech, values=True)
    b = parse_effect("spring:q2:kq0=0.5,k=3", mech, values=True)
    assert a.values == b.values == {"k": 3, "kq0": 0.5} and (a.kind, a.coordinate) == ("spring", "q2")
