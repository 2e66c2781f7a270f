"""URDF files as users have them (issue 22): inertia checks that fit the verb, rounding,
mimic on fixed joints and towards unknown joints, a floating robot with inertia on its root
only. Parity with Pinocchio on whole robots is in tests/test_urdf_pinocchio.py."""

from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.model.consistency import check_body, principal_moments, require_physical
from baseparams.plugins.urdf.reader import read_urdf


def link(name, mass="1", xyz="0 0 0", inertia=("0.01", "0", "0", "0.02", "0", "0.03")):
    ixx, ixy, ixz, iyy, iyz, izz = inertia
    return (f'<link name="{name}"><inertial><origin xyz="{xyz}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/></inertial></link>')


def joint(name, parent, child, kind="revolute", axis="0 0 1", xyz="0 0 0", extra=""):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
            f'{extra}</joint>')


# an arm whose second link breaks the triangle inequality (principal moments 1e-3, 1e-3, 1e-2,
# as PR2's sensor_mount_link) and whose first link has a negative ixx-iyy minor (TIAGo's antennas)
BAD_ARM = ('<robot name="bad_arm"><link name="base"/>'
           + link("upper", "2", "0.2 0 0", ("0.01", "0.02", "0", "0.01", "0", "0.01"))
           + link("sensor_mount", "1", "0.1 0 0", ("0.001", "0", "0", "0.001", "0", "0.01"))
           + joint("shoulder", "base", "upper", axis="0 1 0")
           + joint("elbow", "upper", "sensor_mount", axis="0 1 0", xyz="0.4 0 0") + "</robot>")


@pytest.fixture
def bad_arm(tmp_path):
    path = tmp_path / "bad_arm.urdf"
    path.write_text(BAD_ARM)
    return path


def test_non_physical_inertia_is_a_warning_where_values_do_not_matter(bad_arm):
    mech = read_urdf(bad_arm).mechanism
    assert [key for key, _ in mech.nonphysical] == ["link[name=upper].inertia", "link[name=sensor_mount].inertia"]
    runner = CliRunner()
    for args in (["show", str(bad_arm)], ["solve", str(bad_arm), "--solver", "dp"],
                 ["convert", str(bad_arm), "-o", str(bad_arm.with_suffix(".out.urdf"))]):
        result = runner.invoke(main, args)
        assert result.exit_code == 0, (args, result.output, result.stderr)
        warned = [line for line in result.stderr.splitlines() if line.startswith("warning: ")]
        assert any("link[name=upper].inertia" in w and "not positive semi-definite" in w for w in warned), args
        assert any("link[name=sensor_mount].inertia" in w and "triangle inequality" in w
                   and "0.001, 0.001, 0.01" in w for w in warned), args


def test_base_parameters_do_not_depend_on_the_inertia_values(bad_arm, tmp_path):
    """The same arm with physical inertias: the same rank and the same base expressions."""
    good = tmp_path / "good_arm.urdf"
    good.write_text(BAD_ARM.replace('ixy="0.02"', 'ixy="0"').replace('izz="0.01"/></inertial></link><joint',
                                                                       'izz="0.0015"/></inertial></link><joint'))
    dp = registry.solvers()["dp"].item
    bad, fine = dp.solve(read_urdf(bad_arm).mechanism), dp.solve(read_urdf(good).mechanism)
    assert not read_urdf(good).mechanism.nonphysical
    assert bad.rank == fine.rank and [b["expression"] for b in bad.base] == [b["expression"] for b in fine.base]


def test_verbs_that_use_the_values_refuse_them(bad_arm, tmp_path):
    result = CliRunner().invoke(main, ["simulate", str(bad_arm), "-o", str(tmp_path / "data.csv")])
    assert result.exit_code == 2, result.output
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith("error: ") and str(bad_arm) in line and "link[name=upper].inertia" in line
    assert "simulate" in line and "(1 more body too)" in line and "Traceback" not in result.stderr
    assert not (tmp_path / "data.csv").exists()
    random = CliRunner().invoke(main, ["simulate", str(bad_arm), "-o", str(tmp_path / "data.csv"),
                                       "--random-inertia"])
    assert random.exit_code == 0, random.stderr               # the file's values are not used
    with pytest.raises(InputError, match=r"link\[name=upper\]\.inertia.*diagnose --params uses the inertia"):
        require_physical(read_urdf(bad_arm).mechanism, "diagnose --params")


def test_a_body_welded_to_the_ground_need_not_be_physical_for_given_parameters(tmp_path):
    """A link fixed to the base with a non-physical inertia (the TIAGo's antennas) moves never
    and no force depends on its values: kept as a body (merge_fixed=False) it is flagged, lumped
    (the default) it is part of the ground, and diagnose --params holds the file as given without a
    word; a moving link's bad inertia is held as given too (the user's model, issue 48), with
    a note naming it (tests/test_impossible_estimates.py)."""
    from baseparams.diagnose.given import given_parameters
    fixed = BAD_ARM.replace('<link name="base"/>', '<link name="base"/>' + link(
        "antenna", "0.01", "0 0 0.1", ("1e-8", "2e-8", "0", "1e-8", "0", "1e-8"))
        + '<joint name="antenna_mount" type="fixed"><parent link="base"/><child link="antenna"/></joint>')
    good_arm = fixed.replace('ixy="0.02"', 'ixy="0"').replace('izz="0.01"/></inertial></link><joint name="shoulder"',
                                                                'izz="0.0015"/></inertial></link><joint name="shoulder"')
    (tmp_path / "a.urdf").write_text(fixed)
    (tmp_path / "b.urdf").write_text(good_arm)
    arm = read_urdf(tmp_path / "b.urdf", merge_fixed=False).mechanism      # the antenna a body of its own
    assert [key for key, _ in arm.nonphysical] == ["link[name=antenna].inertia"]
    lumped = read_urdf(tmp_path / "b.urdf").mechanism                       # the default: part of the ground
    assert "antenna" not in [b.name for b in lumped.bodies] and not lumped.nonphysical
    held = given_parameters(lumped, str(tmp_path / "b.urdf"))
    assert len(held.parameters) == len(lumped.parameters) and held.notes == []
    notes = given_parameters(read_urdf(tmp_path / "a.urdf").mechanism, str(tmp_path / "a.urdf")).notes
    assert len(notes) == 1 and "(upper)" in notes[0] and "antenna" not in notes[0]


def test_rounding_is_not_physics():
    """iCub's head: ixx = izz = 0 and ixz = 2.4e-35 at the centre of mass, mass 1.34 at 0.11 m:
    a violation 1e-33 of the inertia's scale is rounding; 1e-12 of it is not."""
    icub = ('<robot name="icub_head"><link name="base"/>'
            + link("head", "1.33687", "0.0185 -0.1108 6.78454e-18", ("0", "0", "2.40741e-35", "0", "0", "0"))
            + joint("neck", "base", "head") + "</robot>")
    from baseparams.plugins.urdf.parse import parse_urdf
    from baseparams.plugins.urdf.reader import build
    mech = build(parse_urdf(icub)).mechanism
    assert not mech.nonphysical and not mech.warnings
    past = build(parse_urdf(icub.replace('izz="0"', 'izz="-1e-14"'))).mechanism
    assert past.nonphysical


def test_exact_zeros_print_as_zeros():
    """A thin rod along z (moments 0, 0 about its axis... and a point mass): the exact
    characteristic polynomial gives exact zeros, where float eigenvalues give 1e-22."""
    third = Fraction(1, 3)
    assert principal_moments([[0, 0, 0], [0, 0, 0], [0, 0, Fraction(3, 10 ** 6)]]) == [0.0, 0.0, 3e-6]
    assert principal_moments([[third, third, 0], [third, third, 0], [0, 0, 1]]) == pytest.approx([0, 2 / 3, 1])
    assert principal_moments([[third, third, 0], [third, third, 0], [0, 0, 1]])[0] == 0.0
    verdict = check_body((Fraction(1), 0, 0, 0, 0, 0, 0, 0, 0, Fraction(3, 10 ** 6)))
    assert "principal moments 0, 0, 3e-06" in verdict.error


def test_mimic_on_a_fixed_joint_is_ignored_as_pinocchio_does(tmp_path):
    """Talos's gripper: a fixed joint with a <mimic> tag; urdfdom and Pinocchio ignore it."""
    text = ('<robot name="grip"><link name="base"/>' + link("finger") + link("pad")
            + joint("grip", "base", "finger")
            + joint("pad_joint", "finger", "pad", kind="fixed", extra='<mimic joint="grip" multiplier="2"/>')
            + "</robot>")
    path = tmp_path / "grip.urdf"
    path.write_text(text)
    result = read_urdf(path)
    assert not result.mechanism.couplings and result.mechanism.independent == ("grip",)
    assert any("joint[name=pad_joint].mimic" in note and "ignored" in note for note in result.notes)


def test_root_only_inertia_floats_with_rank_10(tmp_path):
    """The hector quadrotor: inertia on the root link only. Fixed, nothing moves (refused with
    the reason); floating, the root is a free body whose ten parameters are all identifiable."""
    text = ('<robot name="quad">' + link("base_link", "1.477", "0 0 0", ("0.01152", "0", "0", "0.01152", "0",
                                                                        "0.0218"))
            + '<link name="camera"/>' + joint("cam", "base_link", "camera", kind="fixed") + "</robot>")
    path = tmp_path / "quad.urdf"
    path.write_text(text)
    with pytest.raises(InputError, match="no moving link has an <inertial>.*--floating-base"):
        read_urdf(path)
    mech = read_urdf(path, floating_base=True).mechanism
    solvers = registry.solvers()
    assert {name: solvers[name].item.solve(mech).rank for name in ("dp", "exact")} == {"dp": 10, "exact": 10}


def test_a_duplicate_inertial_is_exit_2(tmp_path):
    text = BAD_ARM.replace("</inertial></link>", "</inertial><inertial><mass value=\"3\"/></inertial></link>", 1)
    path = tmp_path / "twice.urdf"
    path.write_text(text)
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2
    assert result.stderr.startswith("error: ") and "link[name=upper].inertial: 2 <inertial> elements" in result.stderr


def test_dummy_base_inertia_floats_with_a_warning(tmp_path):
    """HyQ, ANYmal B, Go1 in floating mode: a 1e-6 dummy root inertia (not a mass distribution)
    is a warning; the rank equals that with a physical root minus nothing (dp and exact agree)."""
    text = ('<robot name="legged">' + link("trunk", "0.001", "0 0 0", ("1e-6", "0", "0", "1e-6", "0", "1e-2"))
            + link("leg", "1", "0 0 -0.1") + joint("hip", "trunk", "leg", axis="0 1 0", xyz="0.2 0 0") + "</robot>")
    path = tmp_path / "legged.urdf"
    path.write_text(text)
    mech = read_urdf(path, floating_base=True).mechanism
    assert [key for key, _ in mech.nonphysical] == ["link[name=trunk].inertia"]
    solvers = registry.solvers()
    ranks = {name: solvers[name].item.solve(mech).rank for name in ("dp", "exact")}
    assert ranks["dp"] == ranks["exact"] and np.isfinite(ranks["dp"])


def test_follower_limits_that_contradict_the_mimic_are_dropped_with_a_warning(tmp_path):
    """PR2's gripper: r_parallel = -1 x l_finger, both limited to [0, 0.548]: only 0 meets
    both, so the default trajectory could not move; the follower's limits are not enforced."""
    text = ('<robot name="pr2_grip"><link name="base"/>' + link("left") + link("right")
            + joint("l_finger", "base", "left").replace('lower="-1" upper="1"', 'lower="0" upper="0.548"')
            + joint("r_parallel", "base", "right", extra='<mimic joint="l_finger" multiplier="-1"/>')
            .replace('lower="-1" upper="1"', 'lower="0" upper="0.548"') + "</robot>")
    path = tmp_path / "pr2_grip.urdf"
    path.write_text(text)
    mech = read_urdf(path).mechanism
    assert any("joint[name=r_parallel].limit" in w and "contradict" in w for w in mech.warnings)
    assert "r_parallel" not in mech.joint_of_coordinate("r_parallel").limits
    assert registry.solvers()["dp"].item.solve(mech).rank > 0


def test_ros2_control_transmissions_inside_their_element_are_motors(tmp_path):
    """ros2_control nests <transmission> inside <ros2_control> (TIAGo Pro): read as ROS 1's."""
    text = ('<robot name="wheel"><link name="base"/>' + link("rim") + joint("spin", "base", "rim")
            + '<ros2_control name="hw" type="system"><joint name="spin"><state_interface name="position"/>'
              '</joint><transmission name="spin_trans"><plugin>transmission_interface/SimpleTransmission'
              '</plugin><actuator name="spin_motor" role="actuator1"/><joint name="spin" role="joint1">'
              '<mechanical_reduction>50</mechanical_reduction></joint></transmission></ros2_control></robot>')
    path = tmp_path / "wheel.urdf"
    path.write_text(text)
    (motor,) = read_urdf(path).mechanism.motors
    assert motor.name == "spin_motor" and motor.ratios == (("spin", Fraction(50)),)
