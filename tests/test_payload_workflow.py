"""The payload run as a user does it: identify a run without the payload (its friction with
``KIND:*``), then diagnose the payload run against that result held as given (``--params``).
Each test is a fault that workflow hit on robots simulated by Pinocchio
(benchmarks/bench_diagnose_robots.py, scenario payload)."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.diagnose.fixed import effects_toml
from baseparams.io.loader import resolve
from baseparams.model.mechanism import EffectSpec


def test_effect_on_every_coordinate_leaves_out_one_held_still(tmp_path):
    """``--effect viscous_friction:*`` on a log where q6 is held still: the friction is
    identified on the five joints that move (within 3 % of the truth) and q6 is left out with
    a note. Before, the command failed (exit 2: fv_q6 has no effect on these data), and
    KIND:* gave the user no way to drop one (an SO-101 whose gripper does not move)."""
    from baseparams.api import identify
    from baseparams.dynamics.forces import standard_parameters
    from baseparams.recordings.simulate import trajectory_motion
    from baseparams.diagnose.problem import prepare
    from baseparams.dynamics.forces import evaluate
    mechanism = resolve("puma560")
    motion = trajectory_motion(mechanism, 1500)
    motion.q[:, 5], motion.qd[:, 5], motion.qdd[:, 5] = 0.2, 0.0, 0.0
    problem = prepare(mechanism, motion, evaluate(mechanism, motion))
    clean = problem.inertial @ standard_parameters(mechanism)
    truth = np.array([2.0, 3.0, 1.5, 0.4, 0.3, 0.0])
    rng = np.random.default_rng(3)
    tau = clean + motion.qd * truth + rng.standard_normal(clean.shape) * 0.01 * np.sqrt(np.mean(clean ** 2, axis=0))
    names = list(mechanism.independent)
    header = ["t"] + [f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in names]
    rows = np.column_stack([motion.t, motion.q, motion.qd, motion.qdd, tau])
    log = tmp_path / "log.csv"
    log.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    fit = identify("puma560", str(log), effects=["viscous_friction:*"])
    values = fit.to_json()
    found = {e["coordinate"]: e["coefficients"][0]["value"] for e in values["effects"]}
    assert sorted(found) == ["q1", "q2", "q3", "q4", "q5"]
    for k, c in enumerate(names[:5]):
        assert found[c] == pytest.approx(truth[k], rel=0.03)
    assert any("KIND:* left out q6" in n for n in values["notes"])


def test_an_identify_results_friction_replaces_the_models_own_when_held_as_given(tmp_path):
    """The model's file knows viscous friction 1 on q2 (a URDF's damping); identify with
    ``--effect viscous_friction:q2`` estimates the total (3, as in the data) in its place.
    Diagnosing the same robot's next run against that result (``--params``) subtracts 3, not
    1 + 3: nothing is named, and a note says the result's value replaced the model's. Before,
    both were subtracted and a correction of -1 was named (a Z1 arm: friction 'corrections'
    on every joint, gains of -0.45 and a body with a first moment of 7e13)."""
    mech = tmp_path / "puma_known.toml"
    mech.write_text(Path(resolve("puma560").path).read_text() + "\n"
                    + effects_toml([EffectSpec("viscous_friction", "q2", {"fv": 1})], "test"))
    runner = CliRunner()
    logs = []
    for seed in (2, 3):
        log = tmp_path / f"run{seed}.csv"
        assert runner.invoke(main, ["simulate", "puma560", "-o", str(log), "--samples", "1200", "--noise", "0.5",
                                    "--seed", str(seed), "--effect", "viscous_friction:q2=3", "--quiet"]).exit_code == 0
        logs.append(log)
    fitted = tmp_path / "fit.json"
    result = runner.invoke(main, ["identify", str(mech), str(logs[0]), "--effect", "viscous_friction:q2",
                                  "--format", "json", "-o", str(fitted), "--quiet"])
    assert result.exit_code == 0, result.output
    fv = json.loads(fitted.read_text())["effects"][0]["coefficients"][0]["value"]
    assert fv == pytest.approx(3.0, rel=0.05)
    result = runner.invoke(main, ["diagnose", str(mech), str(logs[1]), "--params", str(fitted), "--format", "json",
                                  "--quiet"])
    report = json.loads(result.stdout)
    assert [(e["kind"], e["coordinate"]) for e in report["effects"]] == [], report["effects"]
    assert any("replace the model's own viscous_friction:q2" in n for n in report["notes"])


def test_a_body_alone_with_nothing_else_to_fit_is_cross_validated(tmp_path):
    """``--candidates body:BODY`` with every effect known from an identify result: the model
    fitted beside the candidates has no column at all. Block cross-validation of an empty
    model once failed with an internal error (a reshape of 0 columns)."""
    runner = CliRunner()
    logs = []
    for seed in (4, 5):
        log = tmp_path / f"run{seed}.csv"
        args = ["simulate", "planar_2r", "-o", str(log), "--samples", "600", "--noise", "0.01", "--seed", str(seed),
                "--quiet"]
        assert runner.invoke(main, args).exit_code == 0
        logs.append(log)
    fitted = tmp_path / "fit.json"
    assert runner.invoke(main, ["identify", "planar_2r", str(logs[0]), "--format", "json", "-o", str(fitted),
                                "--quiet"]).exit_code == 0
    result = runner.invoke(main, ["diagnose", "planar_2r", str(logs[1]), "--params", str(fitted),
                                  "--candidates", "body:link2", "--format", "json", "--quiet"])
    assert result.exit_code in (0, 1), result.output + result.stderr
    report = json.loads(result.stdout)
    assert report["effects"] == [] and report["gap"]["cv_before"] == pytest.approx(report["gap"]["cv_after"])


def _planar_runs(tmp_path, payload: str) -> tuple[Path, Path]:
    """planar_2r identified on a short noisy run (its base parameters' std 0.003-0.03), and
    a long quiet run (noise 0.005) carrying ``payload`` kg more on link 2 (at its centre of
    mass, 0.15 m out): the identify JSON and the second log."""
    text = Path(resolve("planar_2r").path).read_text()
    assert text.count('mass = "1.2"') == 1
    loaded = tmp_path / "loaded.toml"
    loaded.write_text(text.replace('mass = "1.2"', f'mass = "{1.2 + float(payload):g}"'))
    runner = CliRunner()
    for args in (["planar_2r", "-o", str(tmp_path / "a.csv"), "--samples", "300", "--noise", "0.5", "--seed", "1"],
                 [str(loaded), "-o", str(tmp_path / "b.csv"), "--samples", "6000", "--noise", "0.005", "--seed", "2"]):
        assert runner.invoke(main, ["simulate", *args, "--quiet"]).exit_code == 0
    fitted = tmp_path / "a.json"
    assert runner.invoke(main, ["identify", "planar_2r", str(tmp_path / "a.csv"), "--format", "json", "-o",
                                str(fitted), "--quiet"]).exit_code == 0
    return fitted, tmp_path / "b.csv"


@pytest.mark.parametrize("payload", ["0.4", "0.03"])
def test_a_change_within_the_given_identifications_uncertainty_is_not_named(tmp_path, payload):
    """A payload on a planar arm's last link is also the first link's first moment and inertia
    (its mass acts at the elbow): the two bodies' candidates share it in any proportion. Held
    as given, an identification from a short noisy run is off by its own error, which the
    quiet second run makes significant: 0.4 kg was named as 0.21 kg on link2 plus 0.12 kg m
    on link1. What link1 adds to the base parameters the named bodies change together lies
    within the identification's covariance (the identify JSON's ``covariance``), so it is
    held back as the given model's own error, and link2 carries the payload (within 3 % for
    0.4 kg; 0.03 kg is 0.036, the rest of link2's change being the same error)."""
    fitted, log = _planar_runs(tmp_path, payload)
    covariance = json.loads(fitted.read_text())["covariance"]
    assert len(covariance["names"]) == len(covariance["matrix"]) == 6
    result = CliRunner().invoke(main, ["diagnose", "planar_2r", str(log), "--params", str(fitted), "--format",
                                       "json", "--quiet"])
    report = json.loads(result.stdout)
    assert [(e["kind"], e["coordinate"]) for e in report["effects"]] == [("body", "link2")]
    held = [u for u in report["unsupported"] if u["coordinate"] == "link1"]
    assert held and "within the uncertainty of the identification held as given" in held[0]["reason"]
    mass = report["effects"][0]["coefficients"]["m"]["value"]
    assert mass == pytest.approx(float(payload), rel=0.03 if payload == "0.4" else 0.25)


def test_an_identify_result_held_as_given_keeps_the_models_own_masses_where_the_data_cannot_see(tmp_path):
    """The standard parameters of an identify result: they reproduce its base parameters and,
    of all that do, are the nearest to the mechanism's own inertias (the least-norm ones put
    a Panda's last link at -1.1e7 kg, and a payload there was held back for a negative mass).
    Every mass stays positive."""
    from baseparams.diagnose.given import given_parameters
    from baseparams.dynamics.forces import standard_parameters
    fitted, _ = _planar_runs(tmp_path, "0.4")
    mechanism = resolve("planar_2r")
    given = given_parameters(mechanism, str(fitted))
    beta = np.array([b["value"] for b in json.loads(fitted.read_text())["base"]])
    assert given.base_map @ given.parameters == pytest.approx(beta, rel=1e-9, abs=1e-12)
    own = standard_parameters(mechanism)
    least_norm = np.linalg.lstsq(given.base_map, beta, rcond=None)[0]
    assert np.linalg.norm(given.parameters - own) <= np.linalg.norm(least_norm - own)
    assert given.masses and all(given.parameters[10 * k] > 0 for k in range(2))


def test_a_broken_covariance_in_an_identify_result_is_bad_input(tmp_path):
    """A hand-edited result whose covariance does not name its base parameters: exit 2, the
    file and the key named, before the run."""
    fitted, log = _planar_runs(tmp_path, "0.4")
    report = json.loads(fitted.read_text())
    report["covariance"]["names"] = ["x"] * len(report["covariance"]["names"])
    fitted.write_text(json.dumps(report))
    result = CliRunner().invoke(main, ["diagnose", "planar_2r", str(log), "--params", str(fitted), "--quiet"])
    assert result.exit_code == 2
    assert "covariance" in result.stderr and str(fitted) in result.stderr and "Traceback" not in result.stderr


def test_the_real_tx40_against_its_own_first_run_names_no_changed_body(tmp_path):
    """Real data, nothing added: the TX40's first 6 s identified (friction on every joint and
    the coupled motor), its last 3 s diagnosed against that result held as given. No body
    changed, so none may be named; every named coefficient is a number of the effect's own
    scale. Before, the second link's mz, whose column is rounding (norm 5e-16 against 1e2),
    was named in a changed body at mz = 1.2e15."""
    data = Path(__file__).parent / "data" / "tx40"
    urdf, description = str(data / "tx40_mdh_modified.urdf"), str(data / "recording.toml")
    effects = [a for kind in ("viscous_friction", "coulomb_friction") for a in ("--effect", f"{kind}:*")]
    effects += [a for kind in ("viscous_friction", "coulomb_friction") for a in ("--effect", f"{kind}:motor_6")]
    fitted = tmp_path / "first.json"
    runner = CliRunner()
    result = runner.invoke(main, ["identify", urdf, description + "#first", *effects, "--effect", "offset:*",
                                  "--format", "json", "-o", str(fitted), "--quiet"])
    assert result.exit_code == 0, result.output + result.stderr
    result = runner.invoke(main, ["diagnose", urdf, description + "#last", "--params", str(fitted), "--format",
                                  "json", "--quiet"])
    assert result.exit_code in (0, 1), result.output + result.stderr
    report = json.loads(result.stdout)
    assert not [e for e in report["effects"] if e["kind"] in ("body", "mass")], report["effects"]
    values = [c["value"] for e in report["effects"] for c in e["coefficients"].values()]
    assert all(np.isfinite(v) and abs(v) < 1e3 for v in values), values
