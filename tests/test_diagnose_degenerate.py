"""diagnose on recordings a robot or a user really produces that carry less than they seem:
a torque channel that was not recorded (all zeros), data simulated without noise, a recording
too short to cross-validate. Each must give an answer that says so, never an internal error."""

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.identify import weighting


def _simulate(tmp_path, noise: str, samples: str = "1200", hidden: tuple = ("--effect", "viscous_friction:q2=3")
              ) -> tuple[list[str], np.ndarray]:
    log = tmp_path / "log.csv"
    result = CliRunner().invoke(main, ["simulate", "puma560", "-o", str(log), "--samples", samples, "--noise", noise,
                                       "--seed", "1", *hidden, "--quiet"])
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(open(log)))
    return rows[0], np.array(rows[1:], dtype=float)


def _diagnose(tmp_path, header, values) -> tuple[int, dict]:
    path = tmp_path / "edited.csv"
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(values.tolist())
    result = CliRunner().invoke(main, ["diagnose", "puma560", str(path), "--format", "json", "--quiet"])
    assert result.exit_code in (0, 1), result.output
    return result.exit_code, json.loads(result.stdout)


def test_a_torque_channel_of_zeros_is_said_and_does_not_break_the_weighting(tmp_path):
    """tau_q5 all zeros while q5 moves: before, the noise weighting sank q5's level by the
    same factor each pass until its weight overflowed (internal error, exit 3)."""
    header, values = _simulate(tmp_path, "0.5")
    values[:, header.index("tau_q5")] = 0.0
    _, report = _diagnose(tmp_path, header, values)
    assert any(n.startswith("tau_q5 is 0 in every row while q5 moves") for n in report["notes"])


def test_data_without_noise_is_nothing_missing_and_tests_nothing(tmp_path):
    """Simulated without noise, the model fits to rounding: before, candidates were tested on
    the rounding and an ambiguous group made the verdict 'unexplained'."""
    header, values = _simulate(tmp_path, "0", hidden=())
    code, report = _diagnose(tmp_path, header, values)
    assert (code, report["verdict"], report["effects"], report["unsupported"]) == (0, "nothing missing", [], [])
    assert any("reproduces the data to rounding" in n for n in report["notes"])


def test_levels_of_a_coordinate_fitted_exactly_stay_finite():
    """One coordinate's residual zero: its level is floored relative to the largest level
    (LEVEL_FLOOR), so its weight stays finite pass after pass."""
    levels = weighting.noise_levels(np.array([4.0, 0.0, 1e-250]), np.zeros(3), 100)
    assert levels[0] == pytest.approx(0.2)
    assert np.all(levels[1:] == 0.2 * weighting.LEVEL_FLOOR)


def test_a_recording_too_short_to_cross_validate_says_so(tmp_path):
    """The first 40 samples (0.5 s) of a PUMA run: each 8-sample block is predicted from the
    others hundreds of times worse than the fit, and the report says its verdict rests on
    the fit alone."""
    header, values = _simulate(tmp_path, "0.5", samples="1500")
    _, report = _diagnose(tmp_path, header, values[:40])
    assert report["gap"]["cv_before"] > 5 * report["gap"]["before"]
    assert any("too few samples or too little motion in each block" in n for n in report["notes"])



def test_a_named_effect_is_physical_in_the_final_model():
    """diagnose._turned, run on the final model's estimates after every check has taken its
    effects out: a named effect whose sign turned there is returned with its reason (on the
    SLA simulated without noise, at a version of this check's session, a rotor inertia judged
    positive beside effects held back later was -162 without them, and was named); an
    ambiguous group's member (not named) and a physical effect are left alone."""
    from baseparams.diagnose import gates
    from baseparams.diagnose.selection import Candidate
    n = 10
    cands = [Candidate("rotor_inertia", "q1", ("Ia",), np.zeros((n, 1, 1))),
             Candidate("viscous_friction", "q1", ("fv",), np.zeros((n, 1, 1))),
             Candidate("coulomb_friction", "q1", ("fc",), np.zeros((n, 1, 1)))]
    estimates = [(np.array([-162.0]), np.array([20.0])), (np.array([0.3]), np.array([0.01])),
                 (np.array([-1.0]), np.array([0.1]))]
    from types import SimpleNamespace
    problem = SimpleNamespace(mechanism=SimpleNamespace(effects=()), qd=None, given=None)    # no known effects
    turned = gates._turned(problem, cands, [0, 1, 2], [0, 1], estimates)
    assert [i for i, _ in turned] == [0]
    assert "must be positive" in turned[0][1] and "in the final model" in turned[0][1]
