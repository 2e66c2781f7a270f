"""Joints held still (a recording's ``[held]``): the held mechanism moves as the original with
those coordinates at their values, and a log without their channels is identified with the
held mechanism's base parameters. Why: a Panda's fingers do not move and a real log has no
channels for them; fitted as joints, identify's condition number was 5e13 and its base
parameters 1e7 +- 1e13, and a log without them could not be read."""

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.errors import InputError
from baseparams.identify.base import BaseModel
from baseparams.diagnose.problem import prepare
from baseparams.identify.fit import identify
from baseparams.dynamics.forces import Motion, evaluate, standard_parameters
from baseparams.recordings.recording import read_data
from baseparams.recordings.simulate import trajectory_motion
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.model.held import hold

URDF = Path(__file__).parent / "data" / "urdf" / "gripper_arm.urdf"


def _torques(mechanism, motion: Motion) -> np.ndarray:
    problem = prepare(mechanism, motion, evaluate(mechanism, motion))
    return problem.known + problem.inertial @ standard_parameters(mechanism)


def _still(mechanism, motion: Motion, values: dict[str, float]) -> Motion:
    """``motion`` with the coordinates of ``values`` held there."""
    out = Motion(motion.t, motion.q.copy(), motion.qd.copy(), motion.qdd.copy())
    for name, value in values.items():
        k = list(mechanism.independent).index(name)
        out.q[:, k], out.qd[:, k], out.qdd[:, k] = value, 0.0, 0.0
    return out


def _without(mechanism, motion: Motion, names) -> Motion:
    keep = [k for k, c in enumerate(mechanism.independent) if c not in names]
    return Motion(motion.t, motion.q[:, keep], motion.qd[:, keep], motion.qdd[:, keep])


def _mimic_arm(tmp_path) -> Path:
    """gripper_arm whose right finger follows the left one (a URDF <mimic>)."""
    text = URDF.read_text().replace('<axis xyz="0 -1 0"/>', '<axis xyz="0 -1 0"/>\n    <mimic joint="finger_left"/>')
    path = tmp_path / "mimic_arm.urdf"
    path.write_text(text)
    return path


@pytest.mark.parametrize("source, values", [
    ("puma560", {"q2": "0.37"}), ("puma560", {"q6": "-1.2", "q4": "0.5"}), ("scara", {"d3": "0.1"}),
    ("chain", {"q3": "2.5"}), ("gripper", {"finger_left": "0.01", "finger_right": "0.03"}),
    ("gripper", {"camera_pan": "-0.8"}), ("mimic", {"finger_left": "0.02"})])
def test_a_held_joint_moves_its_child_as_the_joint_at_that_value(tmp_path, source, values):
    """Forces on the other coordinates along a motion equal the original mechanism's with the
    held coordinates at their values (turning and sliding joints, several at once, a branch,
    a mimic joint held with its leader), to rounding."""
    mechanism = {"chain": lambda: parse_mechanism(generate.serial_chain(4)), "gripper": lambda: resolve(str(URDF)),
                 "mimic": lambda: resolve(str(_mimic_arm(tmp_path)))}.get(source, lambda: resolve(source))()
    held = hold(mechanism, {k: Fraction(v) for k, v in values.items()})
    gone = set(values) | ({"finger_right"} if source == "mimic" else set())
    assert set(held.independent) == set(mechanism.independent) - gone
    motion = _still(mechanism, trajectory_motion(mechanism, 60), {k: float(v) for k, v in values.items()})
    keep = [k for k, c in enumerate(mechanism.independent) if c not in gone]
    original = _torques(mechanism, motion)[:, keep]
    assert np.max(np.abs(_torques(held, _without(mechanism, motion, gone)) - original)) \
        <= 1e-12 * np.max(np.abs(original))


def test_what_cannot_be_held_is_refused_with_the_reason(tmp_path):
    puma = resolve("puma560")
    with pytest.raises(InputError, match="not a joint coordinate"):
        hold(puma, {"q9": Fraction(0)})
    with pytest.raises(InputError, match="closed loops"):
        hold(resolve("four_bar"), {resolve("four_bar").independent[0]: Fraction(0)})
    mimic = resolve(str(_mimic_arm(tmp_path)))
    with pytest.raises(InputError, match="follows 'finger_left'"):
        hold(mimic, {"finger_right": Fraction(0)})
    with pytest.raises(InputError, match=r"at 0.02 with it"):
        hold(mimic, {"finger_left": Fraction("0.02"), "finger_right": Fraction("0.03")})
    both = hold(mimic, {"finger_left": Fraction("0.02"), "finger_right": Fraction("0.02")})   # listed as it follows
    assert both.coordinates == hold(mimic, {"finger_left": Fraction("0.02")}).coordinates


def _gripper_log(tmp_path, seed: int = 0) -> tuple[dict, float]:
    """gripper_arm with its fingers still at 0.01 and 0.03 m, logged without them (noise 1 %
    of each moving joint's RMS force): the log's file, and the noise's relative size."""
    mechanism = resolve(str(URDF))
    still = {"finger_left": 0.01, "finger_right": 0.03}
    motion = _still(mechanism, trajectory_motion(mechanism, 1500), still)
    tau = _torques(mechanism, motion)
    rng = np.random.default_rng(seed)
    tau += rng.standard_normal(tau.shape) * 0.01 * np.sqrt(np.mean(tau ** 2, axis=0))
    moving = [c for c in mechanism.independent if c not in still]
    columns = [list(mechanism.independent).index(c) for c in moving]
    header = ["t"] + [f"q_{c}" for c in moving] + [f"tau_{c}" for c in moving]
    rows = np.column_stack([motion.t, motion.q[:, columns], tau[:, columns]])
    np.savetxt(tmp_path / "log.csv", rows, delimiter=",", header=",".join(header), comments="", fmt="%.12g")
    (tmp_path / "plain.toml").write_text(
        '[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n[position]\n'
        + "".join(f'{c} = "q_{c}"\n' for c in moving) + "[torque]\n" + "".join(f'{c} = "tau_{c}"\n' for c in moving))
    (tmp_path / "held.toml").write_text((tmp_path / "plain.toml").read_text()
                                        + "[held]\nfinger_left = 0.01\nfinger_right = 0.03\n")
    return still, 0.01


def test_a_log_without_the_still_joints_is_identified_with_them_held(tmp_path):
    """The log has the four moving joints only. Without ``[held]`` the error names the
    coordinates without channels and says how to hold them (exit 2); with it, identify fits
    the held mechanism's base parameters (fewer than the mechanism's), the fit is
    well-conditioned and its residual is the noise (1 % white, about a third of it after the
    recording's low-pass and decimation)."""
    _gripper_log(tmp_path)
    runner = CliRunner()
    refused = runner.invoke(main, ["identify", str(URDF), str(tmp_path / "plain.toml"), "--quiet"])
    assert refused.exit_code == 2
    assert "[held]" in refused.stderr and "finger_left" in refused.stderr
    result = runner.invoke(main, ["identify", str(URDF), str(tmp_path / "held.toml"), "--format", "json", "--quiet"])
    assert result.exit_code == 0, result.output + result.stderr
    report = json.loads(result.stdout)
    assert report["coordinates"] == ["turret", "shoulder", "elbow", "camera_pan"]
    full = json.loads(runner.invoke(main, ["solve", str(URDF), "--format", "json"]).stdout)["rank"]
    assert report["rank"] < full
    assert report["condition_number"] < 1e4
    assert all(0.001 < v < 0.01 for v in report["nrms"].values()), report["nrms"]     # the filtered noise


def test_a_description_must_not_give_channels_to_a_held_coordinate(tmp_path):
    _gripper_log(tmp_path)
    text = (tmp_path / "held.toml").read_text().replace("[torque]\n", '[torque]\nfinger_left = "tau_turret"\n')
    (tmp_path / "both.toml").write_text(text)
    result = CliRunner().invoke(main, ["identify", str(URDF), str(tmp_path / "both.toml"), "--quiet"])
    assert result.exit_code == 2 and "'finger_left' is held ([held])" in result.stderr


def test_a_motor_of_held_joints_stops_and_a_coupled_one_is_refused():
    """A motor turning with the held joint alone stops with it (dropped, with its effects: the
    SO-101's URDF gives its gripper a motor); one coupling it with a moving joint (a TX40-like
    wrist) cannot be held apart: refused."""
    from dataclasses import replace

    from baseparams.model.mechanism import EffectSpec, Motor
    puma = resolve("puma560")
    alone = replace(puma, motors=(Motor("m6", (("q6", Fraction(50)),)),),
                    effects=(EffectSpec("viscous_friction", "m6", {"fv": Fraction(1)}),))
    held = hold(alone, {"q6": Fraction(0)})
    assert held.motors == () and held.effects == ()
    coupled = replace(puma, motors=(Motor("m56", (("q5", Fraction(32)), ("q6", Fraction(32)))),))
    with pytest.raises(InputError, match="coupled motor"):
        hold(coupled, {"q6": Fraction(0)})


@pytest.mark.parametrize("held, message", [
    ("[held]\nturret = 0\nshoulder = 0\nelbow = 0\ncamera_pan = 0\nfinger_left = 0.01\nfinger_right = 0.03\n",
     "every coordinate is held"),
    ("", "no position channels")])
def test_a_description_with_nothing_to_read_is_bad_input(tmp_path, held, message):
    """Every coordinate held, or no channel at all: exit 2 with the reason (both were internal
    errors: an assertion in the run's reader)."""
    _gripper_log(tmp_path)
    (tmp_path / "none.toml").write_text('[recording]\ntime = "t"\n[[runs]]\nfile = "log.csv"\n[position]\n[torque]\n'
                                        + held)
    result = CliRunner().invoke(main, ["identify", str(URDF), str(tmp_path / "none.toml"), "--quiet"])
    assert result.exit_code == 2 and message in result.stderr, result.output + result.stderr


@pytest.mark.parametrize("held", ['"finger_*" = 0.01\nfinger_right = 0.03\n',
                                  '"*" = 0.01\nfinger_right = 0.03\n',
                                  'finger_right = 0.03\n"*_l?ft" = 0.01\n'])
def test_a_pattern_holds_every_coordinate_it_matches_without_a_channel(tmp_path, held):
    """``"finger_*" = 0.01`` or ``"*" = 0.01`` (fnmatch) holds every coordinate it matches that
    has no channel; one named by itself keeps its own value. The fit is the one with every
    joint listed by name (a TIAGo's log has 8 of its model's 48 joints)."""
    _gripper_log(tmp_path)
    (tmp_path / "pattern.toml").write_text((tmp_path / "plain.toml").read_text() + "[held]\n" + held)
    mechanism = resolve(str(URDF))
    by_name, model = read_data([str(tmp_path / "held.toml")], mechanism)
    by_pattern, pattern_model = read_data([str(tmp_path / "pattern.toml")], mechanism)
    assert pattern_model.coordinates == model.coordinates
    base = BaseModel.from_result(registry.solvers()["dp"].item.solve(model), model)
    np.testing.assert_array_equal(identify(pattern_model, by_pattern, base=base).estimates,
                                  identify(model, by_name, base=base).estimates)


@pytest.mark.parametrize("held, message", [
    ('"wrist_*" = 0\n', "the pattern 'wrist_*' matches no coordinate without a channel"),
    ('"turret*" = 0\n"finger_*" = 0.01\nfinger_right = 0.03\n',
     "the pattern 'turret*' matches no coordinate without a channel"),
    ('"finger_*" = 0.01\n"*_right" = 0.03\n', "'finger_right' is matched by 'finger_*' and '*_right' with different"),
])
def test_a_pattern_that_matches_nothing_or_disagrees_is_bad_input(tmp_path, held, message):
    """A pattern matching no coordinate without a channel (a typo, or only channelled joints)
    and two patterns giving one coordinate two values are exit 2, naming the pattern."""
    _gripper_log(tmp_path)
    (tmp_path / "pattern.toml").write_text((tmp_path / "plain.toml").read_text() + "[held]\n" + held)
    result = CliRunner().invoke(main, ["identify", str(URDF), str(tmp_path / "pattern.toml"), "--quiet"])
    assert result.exit_code == 2 and message in result.stderr, result.stderr


def test_a_log_in_the_tiago_exports_format_reads_as_it_is(tmp_path):
    """The TIAGo's published logs (FIGAROH's examples): one file per quantity, each with the
    same ROS clock ``t`` (100 Hz, steps 7.7-12.3 ms), columns named ``- <joint>_position``,
    ``_velocity`` (a filtered derivative, not used), ``_effort`` (rounded to 0.001 of the
    drive's unit), and a model with joints the log lacks. A description of a few lines
    (``"*" = 0`` holds the rest) reads them as written, and with nothing hidden diagnose
    finds nothing missing: before the fourteenth session the jittered clock and the
    rounding each made such data "unexplained"."""
    from baseparams.dynamics.trajectory import Trajectory
    from baseparams.numeric.backends import Float64
    mechanism = resolve(str(URDF))
    rng = np.random.default_rng(5)
    t = np.concatenate([[0], np.cumsum(np.clip(0.01 + 0.0012 * rng.standard_normal(4000), 0.0077, 0.0123))])
    t = t[t < 30]
    z, zd, zdd = Trajectory.default(mechanism).independent_values(mechanism, Float64(), t)
    motion = Motion(t, *(np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in a], axis=1)
                         for a in (z, zd, zdd)))
    motion = _still(mechanism, motion, {"finger_left": 0.0, "finger_right": 0.0})
    tau = _torques(mechanism, motion)
    tau += rng.standard_normal(tau.shape) * 0.01 * np.sqrt(np.mean(tau ** 2, axis=0))
    moving = ["turret", "shoulder", "elbow", "camera_pan"]
    columns = [list(mechanism.independent).index(c) for c in moving]
    rms = np.sqrt(np.mean(tau[:, columns] ** 2, axis=0))
    gains = [1.0, 1.0, 1.0, float(0.5 * rms[3] / 0.001)]            # camera_pan: a grid of half its RMS
    effort = np.round(tau[:, columns] / gains, 3)
    for what, values in (("position", motion.q[:, columns]), ("velocity", motion.qd[:, columns]), ("effort", effort)):
        header = "t," + ",".join(f"- {c}_{what}" for c in moving)
        np.savetxt(tmp_path / f"tiago_{what}.csv", np.column_stack([t, values]), delimiter=",", header=header,
                   comments="", fmt="%.17g")
    (tmp_path / "rec.toml").write_text(
        '[recording]\ntime = "t"\n[[runs]]\nfiles = { pos = "tiago_position.csv", eff = "tiago_effort.csv" }\n'
        "[position]\n" + "".join(f'{c} = "pos:- {c}_position"\n' for c in moving) + "[torque]\n"
        + "".join(f'{c} = {{ column = "eff:- {c}_effort", gain = {g!r} }}\n' for c, g in zip(moving, gains))
        + '[held]\n"*" = 0\n')
    result = CliRunner().invoke(main, ["diagnose", str(URDF), str(tmp_path / "rec.toml"), "--format", "json",
                                       "--quiet", "--urdf-dynamics"])      # its damping is the simulation's
    assert result.exit_code == 0, result.output + result.stderr
    report = json.loads(result.stdout)
    assert report["verdict"] == "nothing missing" and report["effects"] == [], report
    assert any("irregular time steps" in n for n in report["notes"])
    assert any(n.startswith("quantised torque channels") for n in report["notes"])
