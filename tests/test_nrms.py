"""NRMS relative to the torque's standard deviation beside its RMS (issue 48): a
gravity-loaded joint's mean torque sits in its RMS and made a fit look 2.6 times better.
And the verbose report's residual lines."""

import numpy as np

import baseparams as bp
from baseparams.identify.fit import Prediction


def test_prediction_nrms_of_the_sd_is_the_closed_form():
    t = np.linspace(0.0, 10.0, 10001)[:-1]
    mean, amplitude, error = 20.0, 2.0, 0.1
    measured = np.column_stack([mean + amplitude * np.sin(2 * np.pi * t), amplitude * np.sin(2 * np.pi * t)])
    predicted = measured + error * np.sign(np.sin(2 * np.pi * 7 * t + 0.1))[:, None]
    p = Prediction("x", ("a", "b"), t, measured, predicted)
    sd = amplitude / np.sqrt(2)
    assert np.allclose(p.rms, error, rtol=1e-3)
    assert np.allclose(p.nrms_sd, error / sd, rtol=1e-3)
    assert np.isclose(p.nrms[0], error / np.sqrt(mean ** 2 + sd ** 2), rtol=1e-3)     # the RMS holds the mean
    assert p.to_json()["nrms_sd"]["a"] == float(p.nrms_sd[0])


def test_identify_reports_both(tmp_path):
    bp.simulate("planar_2r", output=tmp_path / "run.csv", noise=0.01, samples=300)
    fit = bp.identify("planar_2r", str(tmp_path / "run.csv"), solver="dp").to_json()
    assert set(fit["nrms_sd"]) == set(fit["nrms"])
    assert all(fit["nrms_sd"][c] >= fit["nrms"][c] for c in fit["nrms"])      # SD <= RMS


def test_verbose_report_of_a_coordinate_without_a_predictability_test(tmp_path):
    """A coordinate whose predictability was not tested (None in the JSON, here the SLA's
    theta2 on 200 noise-free samples) is left out of the verbose line: --verbose exited 3."""
    from click.testing import CliRunner
    from baseparams.cli import main
    data = tmp_path / "sla.csv"
    assert CliRunner().invoke(main, ["simulate", "sla_suspension", "--effect", "viscous_friction:theta1=0.5",
                                     "--seed", "3", "-o", str(data), "--quiet"]).exit_code == 0
    result = CliRunner().invoke(main, ["diagnose", "sla_suspension", str(data), "--verbose"])
    assert result.exit_code in (0, 1), result.stderr
    assert "predictable from the motion (the verdict's test, Holm p): theta1" in result.stdout


def test_a_constant_force_has_no_nrms_of_its_sd_and_the_json_stays_json(tmp_path):
    """A force without spread (constant) has no NRMS of its SD: null, never Infinity (which
    is not JSON)."""
    import json
    t = np.linspace(0.0, 1.0, 101)
    p = Prediction("x", ("a",), t, np.full((101, 1), 3.0), np.full((101, 1), 3.1))
    text = json.dumps(p.to_json(), allow_nan=False)
    assert json.loads(text)["nrms_sd"] == {"a": None}
