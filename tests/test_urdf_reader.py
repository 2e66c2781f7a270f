"""The URDF reader (docs/urdf.md): exact numbers and rotations, inertias, fixed-link merging,
effects, limits and the default trajectory, the Free joint, and every refusal (exit 2 with
file, element and reason). Parity with Pinocchio is in tests/test_urdf_pinocchio.py."""

import math
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import mpmath
import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.trajectory import Trajectory, samples_float64
from baseparams.errors import InputError
from baseparams.io.loader import load_mechanism
from baseparams.kinematics.tree import TreeKinematics
from baseparams.numeric.backends import Float64
from baseparams.plugins.urdf.parse import parse_urdf, transform_parameters
from baseparams.plugins.urdf.reader import read_urdf
from baseparams.plugins.urdf.rotations import cos_sin, rpy_matrix

DATA = Path(__file__).parent / "data" / "urdf"
ROBOTS = sorted(DATA.glob("*.urdf"))


def robot(*links_and_joints, name="probe"):
    return f'<robot name="{name}">\n<link name="base"/>\n' + "\n".join(links_and_joints) + "\n</robot>\n"


def link(name, mass="1", xyz="0 0 0", rpy="0 0 0", inertia=("0.01", "0", "0", "0.02", "0", "0.03")):
    ixx, ixy, ixz, iyy, iyz, izz = inertia
    return (f'<link name="{name}"><inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/></inertial></link>')


def joint(name, kind="revolute", parent="base", child="l1", xyz="0 0 0", rpy="0 0 0", axis="0 0 1", extra=""):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{extra}</joint>')


def rpy_float(r, p, y):
    """URDF's R = Rz(yaw) Ry(pitch) Rx(roll) in float64 (the independent reference)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


# ----- rotations ------------------------------------------------------------------------------
@pytest.mark.parametrize("text", ["1.5707963267948966", "1.57079632679", "-3.14159265359", "4.71238898038469", "0"])
def test_angles_near_quarter_turns_are_exact(text):
    c, s, how = cos_sin(Decimal(text))
    assert {c, s} <= {Fraction(-1), Fraction(0), Fraction(1)} and c * c + s * s == 1
    assert abs(float(c) - math.cos(float(text))) < 1e-9 and abs(float(s) - math.sin(float(text))) < 1e-9
    assert how == ("exact" if text == "0" else "snapped")


@pytest.mark.parametrize("rpy", [("0.3", "0", "0"), ("0.1", "0.2", "0.3"), ("-2.5", "1.570796325", "3"),
                                 ("1e-5", "-0.7", "0.000001")])
def test_other_rotations_are_exactly_orthogonal_and_within_1e_16(rpy):
    rot, how = rpy_matrix(*(Decimal(v) for v in rpy))
    assert "rational" in how
    gram = [[sum(rot[k][i] * rot[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    assert gram == [[Fraction(int(i == j)) for j in range(3)] for i in range(3)]       # exactly R^T R = 1
    with mpmath.workdps(40):                          # the true rotation, at 40 digits
        r, p, y = (mpmath.mpf(v) for v in rpy)
        rx = mpmath.matrix([[1, 0, 0], [0, mpmath.cos(r), -mpmath.sin(r)], [0, mpmath.sin(r), mpmath.cos(r)]])
        ry = mpmath.matrix([[mpmath.cos(p), 0, mpmath.sin(p)], [0, 1, 0], [-mpmath.sin(p), 0, mpmath.cos(p)]])
        rz = mpmath.matrix([[mpmath.cos(y), -mpmath.sin(y), 0], [mpmath.sin(y), mpmath.cos(y), 0], [0, 0, 1]])
        true = rz * ry * rx
        gap = max(abs(mpmath.mpf(rot[i][j].numerator) / rot[i][j].denominator - true[i, j])
                  for i in range(3) for j in range(3))
    assert gap < 5e-17


def test_inertial_frame_turned_and_shifted_exactly():
    """<inertial> rpy and xyz: I_link = R I R^T + m(|c|^2 1 - c c^T), against numpy."""
    inertia = ("0.004", "0.0001", "-0.0002", "0.006", "0.0003", "0.005")
    text = robot(link("l1", "2.5", "0.1 -0.2 0.05", "0.4 -0.3 1.2", inertia), joint("j1"))
    phi = read_urdf_text(text).bodies[0].inertia
    assert all(isinstance(v, Fraction) for v in phi)
    i = np.array([[0.004, 0.0001, -0.0002], [0.0001, 0.006, 0.0003], [-0.0002, 0.0003, 0.005]])
    r = rpy_float(0.4, -0.3, 1.2)
    c = np.array([0.1, -0.2, 0.05])
    expected = r @ i @ r.T + 2.5 * (c @ c * np.eye(3) - np.outer(c, c))
    got = np.array([[phi[4], phi[5], phi[6]], [phi[5], phi[7], phi[8]], [phi[6], phi[8], phi[9]]], dtype=float)
    assert np.allclose(got, expected, atol=1e-16, rtol=0)
    assert [float(v) for v in phi[:4]] == pytest.approx([2.5, 0.25, -0.5, 0.125], abs=1e-16)


def read_urdf_text(text, tmp=None, **options):
    path = Path(tmp or "/tmp") / "probe_reader_test.urdf"
    path.write_text(text)
    return read_urdf(path, **options).mechanism


def test_numbers_never_pass_through_floats():
    text = robot(link("l1", "0.1000000000000000000000000001"), joint("j1", xyz="0 0 0.3000000000000000000000001"))
    mech = read_urdf_text(text)
    assert mech.bodies[0].inertia[0] == Fraction("0.1000000000000000000000000001")
    assert mech.joints[0].parent_frame.point[2] == Fraction("0.3000000000000000000000001")


# ----- joints ----------------------------------------------------------------------------------
def test_joint_frames_move_the_child_link_as_urdf_says():
    """The child link's pose from our kinematics equals origin * Rot(axis, q) (float reference)."""
    text = robot(link("l1"), link("l2"), joint("j1", xyz="0.1 0.2 0.3", rpy="0.3 -0.2 0.1", axis="0 0.6 0.8"),
                 joint("j2", "prismatic", "l1", "l2", "0 0 0.5", "1.5707963267948966 0 0", "1 0 0",
                       '<limit lower="-1" upper="1" effort="1" velocity="1"/>'))
    mech = read_urdf_text(text)
    kin = TreeKinematics(mech, Float64())
    q = [0.7, 0.25]
    states = kin.forward(q)
    a = np.array([0, 0.6, 0.8])
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    rot_axis = np.eye(3) + math.sin(0.7) * k + (1 - math.cos(0.7)) * k @ k
    r1 = rpy_float(0.3, -0.2, 0.1) @ rot_axis
    p1 = np.array([0.1, 0.2, 0.3])
    assert np.allclose(np.array(states[1].rot, dtype=float), r1, atol=1e-15)
    assert np.allclose(np.array(states[1].pos, dtype=float), p1, atol=1e-15)
    r2 = r1 @ rpy_float(math.pi / 2, 0, 0)
    p2 = p1 + r1 @ np.array([0, 0, 0.5]) + r2 @ np.array([0.25, 0, 0])
    assert np.allclose(np.array(states[2].pos, dtype=float), p2, atol=1e-15)


def test_types_limits_effects_and_default_trajectory():
    mech = read_urdf(DATA / "gripper_arm.urdf", merge_fixed=False).mechanism
    types = {j.name: j.type.name for j in mech.joints}
    assert types == {"turret": "R", "shoulder": "R", "elbow": "R", "wrist": "Fixed", "finger_left": "P",
                     "finger_right": "P", "camera_pan": "R"}
    assert mech.joint_of_coordinate("finger_left").limits == {"finger_left": (0.0, 0.04)}
    assert mech.joint_of_coordinate("camera_pan").limits == {}                        # continuous
    effects = {(e.kind, e.coordinate): e.values for e in mech.effects}
    assert effects[("viscous_friction", "turret")] == {"fv": Fraction("0.8")}
    assert effects[("coulomb_friction", "finger_left")] == {"fc": Fraction("0.1")}
    assert ("viscous_friction", "shoulder") not in effects


@pytest.mark.parametrize("path", ROBOTS, ids=lambda p: p.stem)
def test_default_trajectory_stays_inside_the_limits_and_excites(path):
    mech = load_mechanism(path)
    sample, t = samples_float64(mech, Trajectory.default(mech))      # raises if a limit is left
    q = np.array([np.broadcast_to(v, t.shape) for v in sample.q])
    assert np.all(np.ptp(q, axis=1) > 0)                             # every coordinate moves


def test_merge_fixed_is_exact_and_changes_no_torque():
    """Merged parameters (the default) equal the kept links' transformed sum, and K phi is
    unchanged (tests/test_urdf_lumping.py checks against an independent composition)."""
    kept = read_urdf(DATA / "gripper_arm.urdf", merge_fixed=False).mechanism
    merged = read_urdf(DATA / "gripper_arm.urdf").mechanism
    assert [b.name for b in merged.bodies] == ["turret_link", "upper_arm", "forearm", "finger_left_link",
                                                "finger_right_link", "camera"]
    forearm, palm = (next(b for b in kept.bodies if b.name == n) for n in ("forearm", "palm"))
    wrist = next(j for j in kept.joints if j.name == "wrist")
    rot = [[Fraction(0), Fraction(0), Fraction(1)], [Fraction(0), Fraction(1), Fraction(0)],
           [Fraction(-1), Fraction(0), Fraction(0)]]                                   # Ry(pi/2)
    expected = [a + b for a, b in zip(forearm.inertia, transform_parameters(palm.inertia, rot, [Fraction(str(v)) for v in wrist.parent_frame.point]))]
    assert next(b for b in merged.bodies if b.name == "forearm").inertia == tuple(expected)
    rng = np.random.default_rng(2)
    z = [rng.uniform(-0.3, 0.3, 4) + (0.02 if c.startswith("finger") else 0) for c in merged.coordinates]
    zd, zdd = ([rng.normal(size=4) for _ in merged.coordinates] for _ in range(2))
    taus = []
    for mech in (kept, merged):
        order = [merged.coordinates.index(c) for c in mech.coordinates]
        k = Evaluator(mech, Float64()).sample([z[i] for i in order], [zd[i] for i in order],
                                              [zdd[i] for i in order]).regressor_array()
        phi = np.array([float(v) for b in mech.bodies for v in b.inertia])
        taus.append((k @ phi)[:, np.argsort(order)])
    assert np.allclose(taus[0], taus[1], rtol=1e-12, atol=1e-12)


def test_a_link_fixed_to_the_ground_has_no_effect_on_the_base_parameters():
    dp = registry.solvers()["dp"].item
    kept = read_urdf(DATA / "ur5.urdf", merge_fixed=False).mechanism
    assert kept.bodies[0].name == "base_link" and kept.joints[0].type.name == "Fixed"
    merged = read_urdf(DATA / "ur5.urdf").mechanism
    assert "base_link" not in [b.name for b in merged.bodies]
    assert dp.solve(kept, samples=60).rank == dp.solve(merged, samples=60).rank == 36


def test_floating_joint_and_floating_base_option():
    mech = read_urdf(DATA / "quadruped.urdf").mechanism
    free = mech.joints[0]
    assert free.type.name == "Free" and free.parent == 0 and len(free.coordinates) == 6
    assert registry.transfer_rules("Free") == []                     # nothing crosses a free joint
    bare = read_urdf(DATA / "ur5.urdf", floating_base=True).mechanism
    assert bare.bodies[0].name == "world" and bare.joints[0].type.name == "Free"


def test_free_joint_solvers_agree(tmp_path):
    """A floating body with one leg: dp, exact and symbolic (empty transfer rules) agree."""
    text = ('<robot name="hopper"><link name="world"/>'
            + link("trunk", "2", "0.1 0 0.02", inertia=("0.15", "0", "0.01", "0.2", "0", "0.3"))
            + link("leg", "1", "0 0 -0.1")
            + joint("float", "floating", "world", "trunk")
            + joint("hip", "revolute", "trunk", "leg", "0.2 0 0", "0 0 0", "0 1 0",
                    '<limit lower="-1" upper="1" effort="1" velocity="1"/>') + "</robot>")
    path = tmp_path / "hopper.urdf"
    path.write_text(text)
    mech = load_mechanism(path)
    solvers = registry.solvers()
    ranks = {name: solvers[name].item.solve(mech).rank for name in ("dp", "exact", "symbolic")}
    assert ranks == {"dp": 17, "exact": 17, "symbolic": 17}


def test_names_that_are_not_identifiers_become_coordinates_with_a_note(tmp_path):
    text = robot(link("l1"), joint("joint-1", extra='<limit lower="-1" upper="1" effort="1" velocity="1"/>'))
    path = tmp_path / "names.urdf"
    path.write_text(text)
    result = read_urdf(path)
    assert result.mechanism.coordinates == ("joint_1",)
    assert any("joint_1" in note for note in result.notes)


# ----- refusals: exit 2, file, element, reason ----------------------------------------------------
BAD = {
    "broken_xml": ("<robot name='x'><link name='base'></robot>", "malformed XML"),
    "unknown_type": (robot(link("l1"), joint("j1", "hinge")), "joint[name=j1].type: unknown joint type 'hinge'"),
    "missing_parent": (robot(link("l1"), joint("j1", parent="nowhere")), "joint[name=j1].parent: link 'nowhere' is not defined"),
    "cycle": (robot(link("l1"), link("l2"), joint("a", parent="l1", child="l2"), joint("b", parent="l2", child="l1"),
                    joint("c", parent="base", child="l1")), "already has a parent joint"),
    "cycle_detached": (robot(link("l1"), link("l2"), joint("a", parent="l1", child="l2"),
                             joint("b", parent="l2", child="l1")), "robot: the joints form a cycle"),
    "mesh_only": (robot('<link name="l1"><visual><geometry><mesh filename="a.stl"/></geometry></visual></link>',
                        joint("j1")), "no moving link has an <inertial>"),
    "bad_rpy": (robot(link("l1"), joint("elbow", rpy="0 zero 0")), "joint[name=elbow].origin.rpy: 'zero' is not a number"),
    "short_rpy": (robot(link("l1"), joint("elbow", rpy="0 0")), "joint[name=elbow].origin.rpy: needs 3 number(s)"),
    "planar": (robot(link("l1"), joint("j1", "planar")), "planar joints are not supported"),
    "zero_axis": (robot(link("l1"), joint("j1", axis="0 0 0")), "joint[name=j1].axis.xyz: zero-length axis"),
    "two_roots": (robot(link("l1"), link("l2"), joint("j1")), "more than one root link"),
    "two_inertials": (robot(link("l1").replace("</inertial>", "</inertial>" + link("x").split("<link name=\"x\">")[1]
                                               .replace("</link>", "")), joint("j1")),
                      "link[name=l1].inertial: 2 <inertial> elements: URDF allows one"),
    "two_masses": (robot(link("l1").replace('<mass value="1"/>', '<mass value="1"/><mass value="2"/>'), joint("j1")),
                   "link[name=l1].inertial.mass: 2 <mass> elements: URDF allows one"),
    "two_origins": (robot(link("l1"), joint("j1", extra='<origin xyz="1 0 0"/>')),
                    "joint[name=j1].origin: 2 <origin> elements: URDF allows one"),
    "two_axes": (robot(link("l1"), joint("j1", extra='<axis xyz="1 0 0"/>')),
                 "joint[name=j1].axis: 2 <axis> elements: URDF allows one"),
    "two_mimics": (robot(link("l1"), link("l2"), joint("j1"),
                         joint("j2", parent="l1", child="l2", extra='<mimic joint="j1"/><mimic joint="j1"/>')),
                   "joint[name=j2].mimic: 2 <mimic> elements"),
    "only_the_root": ('<robot name="r"><link name="base"><inertial><mass value="1"/><inertia ixx="1" ixy="0" '
                      'ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link></robot>',
                      "robot: no moving link has an <inertial> element"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_urdf_exit_2_naming_file_element_reason(tmp_path, case):
    text, expected = BAD[case]
    path = tmp_path / f"{case}.urdf"
    path.write_text(text)
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2, result.output
    message = result.stderr
    assert message.startswith("error: ") and str(path) in message and expected in message, message
    assert "Traceback" not in message
    with pytest.raises(InputError):
        parse_urdf(text, path) if case not in ("mesh_only", "only_the_root") else read_urdf(path)
