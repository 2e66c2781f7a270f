"""What changed between recordings (``diagnose CHANGED --baseline BASE``): on simulated pairs
of runs with a known change, coloured noise and model errors common to both sides
(core/recordings/simulate.py, simulate_change), the change is named on the right body or
coordinate with its value, and nothing is named when nothing changed."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.diagnose.change import diagnose_change, pair
from baseparams.diagnose.changesearch import ar_whitening, rest_test
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import coloured_noise, simulate_change
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate

PUMA = "puma560"


@pytest.fixture(scope="module")
def puma():
    return resolve(PUMA)


def _names(result):
    return [f"{e['kind']}:{e['coordinate']}" for e in result.changes]


@pytest.mark.parametrize("noise, samples", [("ar1", 800), ("lowpass", 2000)])
def test_nothing_changed_under_coloured_noise_and_common_model_errors(puma, noise, samples):
    """(Low-passed noise at 5 % of the Nyquist frequency: 800 samples hold about 40
    independent ones, too few for its autoregression; 2000 are a short real log.)"""
    for seed in range(3):
        before, after, _ = simulate_change(puma, samples=samples, seed=seed, noise=noise)
        result = diagnose_change(puma, before, after)
        assert result.verdict == "nothing changed", (seed, _names(result), result.rest)
        assert result.closed and not result.changes
        assert result.pairing["paired"] and result.pairing["share"] == 1.0


@pytest.mark.parametrize("seed, fraction", [(1, 0.3), (2, 0.5), (3, 0.5)])
def test_payload_named_on_the_last_body_with_its_mass_and_centre(puma, seed, fraction):
    before, after, truth = simulate_change(puma, samples=800, seed=seed, payload=fraction)
    result = diagnose_change(puma, before, after)
    # seed 2 named link4 beside it (800 samples of AR(1) 0.9) until a change had to predict
    # held-out blocks
    assert _names(result) == ["body:link6"], (seed, _names(result))
    entry = result.changes[0]
    m, std = entry["value"]["m"], entry["std"]["m"]
    assert abs(m - truth["payload"]["mass"]) <= max(4 * std, 0.05 * truth["payload"]["mass"])
    assert np.allclose(entry["centre_of_mass"], truth["payload"]["centre"], atol=0.01)
    assert result.verdict == "changed"
    # the common lack (smooth Coulomb law, viscous friction, a delay) is reported apart
    assert result.common["cancelled"] and result.common["nrms"] > result.gap["after"]
    assert abs(result.common["delay"] - truth["delay"]) < 0.3 * truth["delay"]


def test_friction_drift_alone_is_named_as_friction(puma):
    before, after, truth = simulate_change(puma, samples=800, seed=3, friction_drift=0.3, drift_coordinate=2)
    result = diagnose_change(puma, before, after)
    assert _names(result) == ["viscous_friction:q3"]
    entry = result.changes[0]
    assert abs(entry["value"] - truth["friction_drift"]["fv"]) <= 4 * entry["std"]


def test_payload_on_a_generated_chain():
    """Not only the built-ins: a random serial chain with random physical inertias."""
    mechanism = parse_mechanism(generate.serial_chain(11, bodies=4, types="RRRR", samples=600), "chain.toml")
    before, after, truth = simulate_change(mechanism, seed=4, payload=0.5, random_inertia=True, noise="white")
    result = diagnose_change(mechanism, before, after)
    last = f"body:{result.changes[0]['coordinate']}" if result.changes else None
    assert last is not None and result.changes[0]["kind"] in ("body", "mass")
    from baseparams.diagnose.derived import body_name
    assert result.changes[0]["coordinate"] == body_name(mechanism, mechanism.bodies[-1].label)
    m = result.changes[0]["coefficients"]["m"]
    if m["value"] is not None:                  # identifiable on this chain
        assert abs(m["value"] - truth["payload"]["mass"]) <= max(4 * m["std"], 0.05 * truth["payload"]["mass"])


def test_pairing_finds_the_same_state_after_a_time_shift():
    t = np.linspace(0, 10, 1001)
    state = np.stack([np.sin(t), np.cos(t), -np.sin(t)], axis=1)
    partner, distance = pair(state, state[100:])
    assert np.array_equal(partner, np.arange(100, 1001)) and np.all(distance < 1e-12)


def test_rest_test_holds_its_size_on_low_passed_noise_and_finds_structure():
    """The test of what is left, after each coordinate's autoregressive whitening: p values of
    pure low-passed noise against smooth columns are uniform enough that 3 of 40 reject at
    most at 5 %, and a smooth column hidden in it is found."""
    rng = np.random.default_rng(0)
    n, f = 1500, 2
    t = np.linspace(0, 15, n)
    columns = np.zeros((n, f, 4))
    columns[:, 0, 0], columns[:, 0, 1] = np.sin(t), np.sign(np.cos(2 * t))
    columns[:, 1, 2], columns[:, 1, 3] = np.sin(3 * t), np.cos(t)
    pvalues = [rest_test(coloured_noise(rng, (n, f), "lowpass"), columns, np.zeros((n, f, 0)), np.ones(f))["pvalue"]
               for _ in range(40)]
    assert sum(p <= 0.05 for p in pvalues) <= 5
    hidden = coloured_noise(rng, (n, f), "lowpass") + 1.0 * columns[:, :, 1]
    assert rest_test(hidden, columns, np.zeros((n, f, 0)), np.ones(f))["pvalue"] < 1e-6
    assert all(len(a) > 2 for a in ar_whitening(coloured_noise(rng, (n, f), "lowpass")))


def test_cli_between_recordings(tmp_path, puma):
    before, after, truth = simulate_change(puma, samples=800, seed=1, payload=0.5)
    write_measured(tmp_path / "base.csv", before)
    write_measured(tmp_path / "changed.csv", after)
    runner = CliRunner()
    result = runner.invoke(main, ["diagnose", PUMA, str(tmp_path / "changed.csv"), "--baseline",
                                  str(tmp_path / "base.csv"), "--format", "json", "--quiet",
                                  "--plot", str(tmp_path / "change.png")])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["mode"] == "change" and report["verdict"] == "changed"
    assert [(e["kind"], e["coordinate"]) for e in report["effects"]] == [("body", "link6")]
    assert set(report["effects"][0]["value"]) >= {"m", "mx", "my", "mz"}
    assert (tmp_path / "change.png").stat().st_size > 0
    text = runner.invoke(main, ["diagnose", PUMA, str(tmp_path / "changed.csv"), "--baseline",
                                str(tmp_path / "base.csv"), "--quiet"])
    assert text.exit_code == 0
    lines = text.stdout.strip().splitlines()
    assert len(lines) <= 25 and lines[0].startswith("verdict: CHANGED")
    assert any("body on link6" in line and "kg at (" in line for line in lines)
    same = runner.invoke(main, ["diagnose", PUMA, str(tmp_path / "base.csv"), "--baseline",
                                str(tmp_path / "base.csv"), "--quiet"])
    assert same.exit_code == 0 and same.stdout.startswith("verdict: NOTHING CHANGED")


def test_cli_refuses_options_that_do_not_apply(tmp_path, puma):
    before, after, _ = simulate_change(puma, samples=300, seed=1)
    write_measured(tmp_path / "base.csv", before)
    write_measured(tmp_path / "changed.csv", after)
    result = CliRunner().invoke(main, ["diagnose", PUMA, str(tmp_path / "changed.csv"), "--baseline",
                                       str(tmp_path / "base.csv"), "--write", str(tmp_path / "x.toml")])
    assert result.exit_code == 2 and "--baseline" in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "x.toml").exists()
    missing = CliRunner().invoke(main, ["diagnose", PUMA, str(tmp_path / "changed.csv"), "--baseline",
                                        str(tmp_path / "nope.csv")])
    assert missing.exit_code == 2 and "nope.csv" in missing.stderr


KINOVA = Path(__file__).parent / "data" / "kinova_gen3"


@pytest.fixture(scope="module")
def kinova_repeat():
    """A real pair: one commanded motion recorded twice by a Kinova Gen3 (motor currents)."""
    from baseparams.recordings.recording import read_data
    mechanism = resolve(str(KINOVA / "gen3.urdf"))
    before, mechanism = read_data([str(KINOVA / "repeat_RunTrajectory1.toml")], mechanism)
    after, _ = read_data([str(KINOVA / "repeat_Trajectory1.toml")], mechanism)
    return mechanism, before, after


def test_real_repeat_nothing_changed(kinova_repeat):
    mechanism, before, after = kinova_repeat
    result = diagnose_change(mechanism, before, after)
    assert result.verdict == "nothing changed", (_names(result), result.notes)
    assert result.pairing["paired"]


def _hidden_payload(kinova_repeat, mass: float, x: float, z: float):
    """The Kinova repeat with the torque of a point payload at (x, 0, z) on the last link added
    to the second run's currents."""
    import dataclasses
    from baseparams.diagnose.derived import body_columns
    from baseparams.identify.fit import measured_design
    mechanism, before, after = kinova_repeat
    inertial, _, _ = measured_design(mechanism, after, [], [])
    phi = np.zeros(len(mechanism.parameters))
    phi[body_columns(mechanism, "bracelet_link")] = mass * np.array([1, x, 0, z, z * z, 0, -x * z, x * x + z * z, 0,
                                                                      x * x])
    loaded = dataclasses.replace(after, tau=after.tau + inertial.matrix @ phi)
    return diagnose_change(mechanism, before, loaded)


@pytest.mark.parametrize("mass", [0.5, 2.0])
def test_real_repeat_with_a_payload_hidden_in_the_second_run(kinova_repeat, mass):
    """Real noise and real model errors, a known truth: the torque of a payload on the last
    link (3 cm off its axis, 6 cm down it) added to the second run's currents."""
    x, z = 0.03, -0.06
    result = _hidden_payload(kinova_repeat, mass, x, z)
    assert _names(result) == ["body:bracelet_link"], (_names(result), result.notes)
    entry = result.changes[0]
    assert abs(entry["value"]["m"] - mass) <= 3 * entry["std"]["m"]
    assert abs(entry["centre_of_mass"][2] - z) < 0.02
    assert abs(entry["centre_of_mass"][0] - x) < 0.02


def test_real_repeat_with_a_payload_on_the_last_axis_is_the_links_before_it_too(kinova_repeat):
    """A point payload on the last joint's axis does not turn with it: its torques are those
    of the same load on the link before (spherical_wrist_2_link), and no test can tell them
    apart. 'changed', with the last link among the named or ambiguous (this test named the
    last link alone while the F tests pooled the joints' whitened noise at the mean
    variance: the last joint's, which alone tells the links apart, was taken for 0.78 of
    itself)."""
    result = _hidden_payload(kinova_repeat, 2.0, 0.0, -0.06)
    assert result.verdict == "changed"
    named = set(_names(result)) | {f"{c['kind']}:{c['coordinate']}" for group in result.ambiguous
                                   for c in group["candidates"]}
    assert "body:bracelet_link" in named, (named, result.notes)


def test_report_fits_one_screen_whatever_the_counts(puma):
    """Many changes, ambiguous groups and notes: the default text stays within 25 lines and
    says how many more --verbose shows; the change's own notes come before the reading's."""
    from baseparams.api.render import change_text
    before, after, _ = simulate_change(puma, samples=300, seed=1, payload=0.5)
    result = diagnose_change(puma, before, after)
    entry = result.changes[0]
    result.changes = [dict(entry, coordinate=f"body{k}") for k in range(30)]
    result.ambiguous = [{"candidates": [{"kind": "gain", "coordinate": "q1"}, {"kind": "offset", "coordinate": "q1"}]}
                        for _ in range(10)]
    result.notes = [f"baseline: reading note {k}\nover two lines" for k in range(20)] + ["the change's own note"]
    text = change_text(result)
    lines = text.splitlines()
    assert len(lines) <= 25
    assert "more (--verbose)" in text and "more ambiguous groups (--verbose)" in text
    assert "note: the change's own note" in lines
    full = change_text(result, verbose=True).splitlines()
    assert sum(line.startswith("  body on body") for line in full) == 30


def test_shifting_is_exact_on_cubics_on_any_spacing():
    """The delay's columns are the signals as they were d seconds earlier: a cubic in t is
    shifted exactly (irregular stamps too), and before a segment's first row it is held."""
    from baseparams.diagnose.timeshift import local_cubic
    t = np.sort(np.random.default_rng(4).uniform(0.0, 3.0, 400))
    x = np.stack([t ** 3 - 2 * t, 0.5 * t ** 2 + 1.0], axis=1)
    at = np.clip(t - 0.0137, t[0], t[-1])
    expected = np.stack([at ** 3 - 2 * at, 0.5 * at ** 2 + 1.0], axis=1)
    assert np.allclose(local_cubic(t, x, at), expected, rtol=0, atol=1e-9)
    smooth = np.sin(2 * np.pi * 0.7 * t)
    assert np.max(np.abs(local_cubic(t, smooth[:, None], at)[:, 0] - np.sin(2 * np.pi * 0.7 * at))) < 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_payload_through_a_gearbox_with_load_friction_is_one_change(seed):
    """A gear's load friction (mu |tau| sign(qd), mu 0.1, not in the model, common to both
    runs) grows with a payload's torque: the shared model holds it, computed from each side's
    own torque, so the payload is the change and no joint's friction is named beside it
    (before: friction changes on two or three of the shoulder and elbow joints)."""
    ur5 = resolve(str(Path(__file__).parent / "data" / "urdf" / "ur5.urdf"))
    before, after, truth = simulate_change(ur5, samples=1000, seed=seed, payload_mass=0.48, load_friction=0.1,
                                           quantum=0.01)
    result = diagnose_change(ur5, before, after)
    first = result.changes[0]
    assert (first["kind"], first["coordinate"]) == ("body", "wrist_3_link"), _names(result)
    assert abs(first["value"]["m"] - 0.48) <= 0.05 * 0.48
    assert all(e["coordinate"] in ("wrist_3_link", "wrist_3_joint") for e in result.changes), _names(result)
    assert all(0.05 < mu < 0.15 for mu in result.common["load_friction"].values()), result.common["load_friction"]


def test_real_tx40_halves_nothing_changed():
    """The real TX40 recording (motor side, coupled wrist) split in two halves of other
    motions: nothing changed between them, so nothing is named (a load friction fitted on one
    half and extrapolated to the other once named an 85 % gain change on joint 5)."""
    import baseparams as bp
    tx40 = Path(__file__).parent / "data" / "tx40"
    result = bp.diagnose(str(tx40 / "tx40_mdh_modified.urdf"), str(tx40 / "recording.toml") + "#last",
                         baseline=str(tx40 / "recording.toml") + "#first")
    assert result.to_json()["verdict"] == "nothing changed", result.to_json()["changes"]



def _other_motion_runs(mechanism, payload: float, seed: int):
    """Two runs of other motions (the default trajectory, then it time-reversed and 1.3 times
    slower: no state is shared), one friction law for both (a smooth Coulomb law and viscous
    friction, not in the model), AR(1) noise at 1 % of the RMS torques, and in the second a
    payload of ``payload`` times the last body's mass, off its frame's origin."""
    from baseparams.dynamics.forces import Motion, design, evaluate, independent_names, standard_parameters
    from baseparams.recordings.data import MeasuredData
    from baseparams.recordings.simulate import coloured_noise, trajectory_motion
    first = trajectory_motion(mechanism, 1500)
    second = Motion(first.t * 1.3, first.q[::-1].copy(), -first.qd[::-1] / 1.3, first.qdd[::-1] / 1.3 ** 2)
    phi = standard_parameters(mechanism)
    rigid = design(mechanism, first, [], evaluate(mechanism, first))[0].matrix @ phi
    peak, speed = np.max(np.abs(rigid), axis=0), np.sqrt(np.mean(first.qd ** 2, axis=0))
    fastest, sd = np.max(np.abs(first.qd), axis=0), 0.01 * np.sqrt(np.mean(rigid ** 2, axis=0))
    last = len(mechanism.bodies) - 1
    x, y, z = 0.03, 0.02, 0.04
    change = np.zeros_like(phi)
    change[10 * last:10 * last + 10] = payload * phi[10 * last] * np.array(
        [1.0, x, y, z, y * y + z * z, -x * y, -x * z, x * x + z * z, -y * z, x * x + y * y])
    rng = np.random.default_rng(seed)
    runs = []
    for motion, extra in ((first, 0 * change), (second, change)):
        sample = evaluate(mechanism, motion)
        K = design(mechanism, motion, [], sample)[0].matrix
        friction = 0.05 * peak * np.tanh(motion.qd / (0.1 * speed)) + 0.02 * peak * motion.qd / fastest
        tau = K @ (phi + extra) + friction + coloured_noise(rng, K.shape[:2], "ar1") * sd
        runs.append(MeasuredData(motion, tau, independent_names(mechanism), None, (), (), sample))
    return runs, payload * phi[10 * last]


@pytest.mark.parametrize("payload", [0.0, 0.5])
def test_other_motions_nothing_changed_or_the_payload_on_its_body(puma, payload):
    """Unpaired (no shared state): what both lack does not cancel, so a change is named only
    when it outgrows what the shared model misses on the baseline's own motion; a payload of
    half link6's mass (45 g) is still named there, within 15 %."""
    (before, after), mass = _other_motion_runs(puma, payload, seed=1)
    result = diagnose_change(puma, before, after)
    assert not result.pairing["paired"]
    if payload == 0.0:
        assert result.verdict == "nothing changed", _names(result)
    else:
        assert _names(result) == ["body:link6"], _names(result)
        assert abs(result.changes[0]["value"]["m"] - mass) <= 0.15 * mass


def test_a_candidate_that_borrows_its_force_from_a_true_change_is_too_small_to_name():
    """The size check weighs what a change adds to the others' fitted force, not its own
    force fitted beside them. A body-like change (a swing and a near-constant gravity column)
    and an offset that imitates the gravity column: the noise's component along what tells
    them apart gives the offset a force of several noise SDs, all of it given back by the
    body (issue 49: an offset of 0.12 N m beside a load on the arm's back link), so it is
    not named; an independent true change beside the body is."""
    from baseparams.diagnose.changesearch import Search, _large_enough
    from baseparams.diagnose.selection import Candidate
    t = np.linspace(0.0, 20.0, 2000)
    rng = np.random.default_rng(3)
    body = np.stack([np.sin(t), 1.0 + 0.05 * np.cos(3 * t)], axis=1)[:, None, :]
    offset = np.ones((len(t), 1, 1))
    drift = np.cos(0.5 * t)[:, None, None]
    noise = 0.1 * rng.standard_normal((len(t), 1)) + 0.01 * np.cos(3 * t)[:, None]
    y = body @ np.array([2.0, 0.5]) + noise
    candidates = [Candidate("body", "link", ("a", "b"), body), Candidate("offset", "q", ("c",), offset),
                  Candidate("viscous_friction", "q", ("d",), drift)]

    def kept(y: np.ndarray, members: list[int]) -> set:
        search = Search(candidates, members, {}, {}, np.ones(3), [], np.ones(1))
        return _large_enough(search, y, set(members), [])

    # the offset's own force beside the body: several noise SDs (what the check used to weigh)
    X = np.concatenate([body, offset], axis=-1)
    values = np.linalg.lstsq(X[:, 0], y[:, 0], rcond=None)[0]
    one_run = np.sqrt(np.mean((y[:, 0] - X[:, 0] @ values) ** 2) / 2)
    assert abs(values[2]) > 2 * one_run > 0            # the offset column is 1
    assert kept(y, [0, 1]) == {0}
    assert kept(y + 0.3 * drift[:, :, 0], [0, 2]) == {0, 2}
    assert kept(y + 0.3 * drift[:, :, 0], [0, 1, 2]) == {0, 2}


def test_real_repeat_window_is_read_with_the_baselines_filter(tmp_path):
    """A window of the Kinova repeat's second run (0.3-1.6 s: joint 1 at near-constant speed)
    read alone takes its positions' bandwidth from the speed ripple (54.5 Hz against the whole
    run's 4.1), kept 200 Hz against the baseline's 41, paired 27 % of its samples and named
    two bodies. Both sides are now read with the baseline's low-pass: nothing changed."""
    import shutil
    import baseparams as bp
    shutil.copy(KINOVA / "repeat_Trajectory1.csv", tmp_path)
    text = (KINOVA / "repeat_Trajectory1.toml").read_text()
    (tmp_path / "window.toml").write_text(text.replace('file = "repeat_Trajectory1.csv"',
                                                       'file = "repeat_Trajectory1.csv"\nwindow = [0.3, 1.6]'))
    result = bp.diagnose(str(KINOVA / "gen3.urdf"), str(tmp_path / "window.toml"),
                         baseline=str(KINOVA / "repeat_RunTrajectory1.toml")).to_json()
    assert result["verdict"] == "nothing changed", (result["changes"], result["notes"])
    assert any(n.startswith("changed:") and "the fit's filter" in n for n in result["notes"]), result["notes"]
