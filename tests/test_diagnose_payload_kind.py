"""diagnose --params: a compact load named as a ``payload`` (its mass and first moments), and a
body confusable with another effect leaving the payload named (issue 42, a second make of arm).

The UR5 (tests/data/urdf/ur5.urdf) carries a 94 g point load 3-5 cm off its wrist_3 origin. As
a mass at the origin it was named 11-25 % heavy (the mass took the first moments' force). When
the body entered as confusable with the last joint's rotor inertia (the load's inertia about the
axis), it took the payload's columns with it and the report said "body or rotor inertia".
"""

import json

import numpy as np
import pytest

import baseparams as bp
from baseparams.diagnose.change import shared_effects
from baseparams.diagnose.gates import _fixed
from baseparams.diagnose.selection import Candidate, _beyond_named
from baseparams.errors import InputError
from baseparams.io.loader import resolve
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate_change

UR5 = "tests/data/urdf/ur5.urdf"


def _diagnosed(tmp_path, seed: int, **simulation):
    mechanism = resolve(UR5)
    before, after, truth = simulate_change(mechanism, samples=1000, seed=seed, **simulation)
    base, changed, held = tmp_path / "base.csv", tmp_path / "changed.csv", tmp_path / "base.json"
    write_measured(base, before)
    write_measured(changed, after)
    effects = [f"{e.kind}:{e.coordinate}" for e in shared_effects(mechanism)]
    held.write_text(json.dumps(bp.identify(UR5, str(base), effects=effects).to_json()))
    return bp.diagnose(UR5, str(changed), params=str(held)), truth


def _named(report: dict) -> list[str]:
    return [f"{e['kind']}:{e['coordinate']}" for e in report["effects"]] + \
        [f"ambiguous:{a['strongest']}" for a in report["ambiguous"]]


@pytest.mark.parametrize("noise", ["white", "ar1"])
def test_a_load_off_the_origin_is_named_with_its_mass_and_centre(tmp_path, noise):
    """No model error: the load is named on wrist_3_link, as a payload or (where the data see
    its inertia about the origin, which a payload leaves out) a body, its mass within 5 % and
    its centre within 5 mm of the simulated ones (the issue's 5 %), and the text says where."""
    result, truth = _diagnosed(tmp_path, 0, payload=0.5, common_errors=False, noise=noise)
    report = result.to_json()
    assert _named(report) in (["payload:wrist_3_link"], ["body:wrist_3_link"]), _named(report)
    c = report["effects"][0]["coefficients"]
    m = c["m"]["value"]
    assert m == pytest.approx(truth["payload"]["mass"], rel=0.05)
    centre = np.array([c[k]["value"] for k in ("mx", "my", "mz")]) / m
    assert np.max(np.abs(centre - truth["payload"]["centre"])) < 0.005
    assert f"{report['effects'][0]['kind']} on wrist_3_link:" in result.to_text()
    assert ") m in its axes" in result.to_text()
    assert not any("leaves NRMS" in n for n in report["notes"])     # a held fit to its noise: nothing to say


def test_a_body_confusable_with_a_rotor_inertia_leaves_the_payload_named(tmp_path):
    """Seed 3 of ``bench_diagnose_held.py --mechanism ur5.urdf``: AR(1) noise and model errors
    common to both runs (a delay among them). Before, 'ambiguous: body:wrist_3_link |
    rotor_inertia:wrist_3_joint' and no mass; now the load alone on wrist_3_link, its mass within
    10 %. As a payload or as a body: the two forms are equally supported here, and which one the
    selection takes is set by rounding (torques moved by a relative 1e-15 turn one into the other
    in 2 of 5 runs, in the code before and after issue 42's fourth speed pass)."""
    result, truth = _diagnosed(tmp_path, 3, payload=0.5)
    report = result.to_json()
    assert _named(report) in (["payload:wrist_3_link"], ["body:wrist_3_link"]), _named(report)
    assert report["effects"][0]["coefficients"]["m"]["value"] == pytest.approx(truth["payload"]["mass"], rel=0.10)


def _candidate(kind: str, columns: np.ndarray, generalises=()) -> Candidate:
    names = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")[:columns.shape[-1]]
    return Candidate(kind, "link", tuple(f"{n}_link" for n in names), columns, generalises=generalises)


def test_beyond_named_drops_the_columns_a_named_simpler_form_holds():
    rng = np.random.default_rng(0)
    block = rng.standard_normal((30, 2, 10))
    body = _candidate("body", block, ("mass", "payload"))
    payload = _candidate("payload", block[:, :, :4].copy(), ("mass",))
    other = _candidate("payload", rng.standard_normal((30, 2, 4)), ("mass",))
    reduced = _beyond_named([body, payload], 0, [1])
    assert reduced.names == body.names[4:]
    assert np.array_equal(reduced.columns, block[:, :, 4:])
    assert _beyond_named([body, other], 0, [1]) is body          # not its columns: kept whole
    assert _beyond_named([body, payload], 0, []) is body          # nothing named: kept whole
    assert _beyond_named([payload, body], 0, [1]) is payload      # a payload does not generalise a body
    # every row of the original at the columns selection kept
    assert np.array_equal(_fixed(body, reduced).columns, block[:, :, 4:])


def test_payload_is_a_candidate_with_params_only():
    """``--candidates payload:BODY`` is accepted with --params and refused (exit 2 wording)
    without, as mass and body are."""
    from baseparams.diagnose.candidates import parse_selection
    mechanism = resolve(UR5)
    assert parse_selection(mechanism, ["payload:wrist_3_link"], given=True) == [("payload", "wrist_3_link")]
    with pytest.raises(InputError, match="only when the inertial parameters are given"):
        parse_selection(mechanism, ["payload:wrist_3_link"], given=False)


def test_late_shifts_run_by_run():
    """``late`` is exact on a line within a run (linear interpolation), holds a run's first
    sample before it, and does not reach across the restart of a second run's clock."""
    from baseparams.diagnose.bodylag import late, segments
    t = np.r_[np.arange(10) * 0.01, np.arange(10) * 0.01]
    x = np.r_[2.0 * np.arange(10) * 0.01, 5.0 + np.arange(10) * 0.01][:, None]
    assert [(s.start, s.stop) for s in segments(t)] == [(0, 10), (10, 20)]
    out = late(x, t, 0.025)
    assert out[5, 0] == pytest.approx(2.0 * (0.05 - 0.025))
    assert out[0, 0] == x[0, 0] and out[10, 0] == x[10, 0]
    assert out[15, 0] == pytest.approx(5.0 + 0.05 - 0.025)


@pytest.mark.parametrize("lag", [0.012, 0.027])
def test_body_lag_finds_the_lag_of_a_loads_force(lag):
    """A load's force 12 or 27 ms late, beside what a held model lacks of the same lag (its own
    torque's derivative) and AR(1) noise: the lag is found within 1 ms and stands clear."""
    from baseparams.diagnose.bodylag import CLEAR, body_lag, late, rate
    from baseparams.diagnose.problem import prepare
    from baseparams.dynamics.forces import evaluate, standard_parameters
    from baseparams.recordings.simulate import coloured_noise, trajectory_motion
    mechanism = resolve("puma560")
    motion = trajectory_motion(mechanism, 1500)
    problem = prepare(mechanism, motion, evaluate(mechanism, motion))
    bodies = problem.inertial                            # (n, f, 10 per body)
    torque = bodies @ standard_parameters(mechanism)
    load = np.zeros(bodies.shape[-1])
    load[50:54] = [0.05, 0.001, 0.002, 0.0008]           # 50 g at (2, 4, 1.6) cm on link6
    force = late(bodies @ load, motion.t, lag)
    rng = np.random.default_rng(1)
    y = force - 0.3 * lag * rate(torque, motion.t) + 0.002 * coloured_noise(rng, torque.shape, "ar1") * np.std(force, axis=0)
    found, z = body_lag(motion.t, y, torque, bodies)
    assert found == pytest.approx(lag, abs=1e-3)
    assert z >= CLEAR


def test_real_repeat_held_against_its_first_run_is_nothing_missing(tmp_path):
    """The real Kinova repeat (tests/data/kinova_gen3, README: the same motion twice, motor-
    current torques): the first run identified and held (``--params``) for the second. Before,
    'coulomb_friction | cogging' on joint_5 were both in the final model, the cogging's
    harmonics predicted the last block 60 times worse, the cross-validated gap grew 0.49 -> 5.3
    and the verdict was 'unexplained'. One effect of each group (its strongest) in the final
    model: the gap does not grow, and the verdict is exit 0."""
    from pathlib import Path
    from click.testing import CliRunner
    from baseparams.cli import main
    folder = Path(__file__).parent / "data" / "kinova_gen3"
    held = tmp_path / "first.json"
    runner = CliRunner()
    done = runner.invoke(main, ["identify", str(folder / "gen3.urdf"), str(folder / "repeat_RunTrajectory1.toml"),
                                "--format", "json", "--quiet"])
    assert done.exit_code == 0, done.output
    held.write_text(done.stdout)
    result = runner.invoke(main, ["diagnose", str(folder / "gen3.urdf"), str(folder / "repeat_Trajectory1.toml"),
                                  "--params", str(held), "--format", "json", "--quiet"])
    report = json.loads(result.stdout)
    assert report["gap"]["cv_after"] <= report["gap"]["cv_before"] + 1e-12
    assert report["verdict"] in ("nothing missing", "explained"), report["verdict"]
    assert result.exit_code == 0
    # exit 0, but the held result leaves NRMS 0.45-0.73 on its own run: said, with --baseline
    lack = [n for n in report["notes"] if "leaves NRMS" in n]
    assert lack and "joint_4" in lack[0], report["notes"]
    assert any("--baseline" in n and "repeat_RunTrajectory1.toml" in n for n in report["notes"]), report["notes"]


def test_real_repeat_held_names_a_hidden_load_though_the_held_masses_are_impossible(tmp_path):
    """The real Kinova repeat, its first run identified and held, a 2 kg point load's torque (3
    cm off the last link's axis, 6 cm down it) added to the second run's currents. The held
    identification puts the last link at -366 kg (the first link's first moments, through an axis
    4e-6 rad off vertical, are -7e4 kg m, and the masses completed from them follow): the gate
    that keeps a changed body's mass positive refused the load ("the changed body's mass -365 is
    not positive") and nothing was named. No body has the held mass, so it is not judged there."""
    import dataclasses
    from pathlib import Path
    from baseparams.diagnose.derived import body_columns
    from baseparams.diagnose.given import given_parameters
    from baseparams.diagnose.workflow import diagnose_data
    from baseparams.identify.fit import measured_design
    from baseparams.recordings.recording import read_data
    folder = Path(__file__).parent / "data" / "kinova_gen3"
    urdf = str(folder / "gen3.urdf")
    held = tmp_path / "first.json"
    held.write_text(json.dumps(bp.identify(urdf, str(folder / "repeat_RunTrajectory1.toml")).to_json()))
    mechanism = resolve(urdf)
    given = given_parameters(mechanism, str(held))
    assert given.parameters[body_columns(mechanism, "bracelet_link")][0] < 0       # the trap itself
    keys = {(e.kind, e.coordinate) for e in given.effects}
    mechanism = dataclasses.replace(mechanism, effects=tuple(
        e for e in mechanism.effects if (e.kind, e.coordinate) not in keys) + tuple(given.effects))
    after, mechanism = read_data([str(folder / "repeat_Trajectory1.toml")], mechanism)
    mass, x, z = 2.0, 0.03, -0.06
    inertial, _, _ = measured_design(mechanism, after, [], [])
    phi = np.zeros(len(mechanism.parameters))
    phi[body_columns(mechanism, "bracelet_link")] = mass * np.array(
        [1, x, 0, z, z * z, 0, -x * z, x * x + z * z, 0, x * x])
    report = diagnose_data(mechanism, dataclasses.replace(after, tau=after.tau + inertial.matrix @ phi),
                           given=given).to_json()
    named = [(e["kind"], e["coordinate"]) for e in report["effects"]]
    assert named in ([("body", "bracelet_link")], [("payload", "bracelet_link")]), _named(report)
    m = report["effects"][0]["coefficients"]["m"]
    assert abs(m["value"] - mass) <= max(3 * m["std"], 0.1 * mass), m


def test_a_body_beyond_any_physical_scale_is_not_named():
    """gates._beyond_scale: a body's coefficient above a hundred times what the mechanism's
    bodies could have is refused with its reason (its columns cancel one another); within it,
    nothing is said; a mechanism without masses is not judged."""
    from baseparams.identify.impossible import body_limits
    from baseparams.diagnose.gates import _beyond_scale

    class Held:                                    # what _beyond_scale reads of a Problem
        def __init__(self, mechanism):
            self.mechanism = mechanism
    ur5 = resolve(UR5)
    limits = body_limits(ur5)
    body = Candidate("body", "wrist_3_link", ("m",), np.zeros((1, 1, 1)))
    assert "beyond any physical scale" in _beyond_scale(Held(ur5), body, {"m": -1.5 * limits["m"], "mx": 0.0})
    assert _beyond_scale(Held(ur5), body, {"m": 0.5, "mx": 0.01}) == ""
    assert _beyond_scale(Held(resolve("puma560")), body, {"m": 1e12}) == ""          # no masses: not judged
