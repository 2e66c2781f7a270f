"""Writing URDF keeps the joint limits it read and invents none (issue 23, item 9).

A URDF's ``<limit lower upper effort velocity>`` is carried by the mechanism (positions in
``Joint.limits``, velocity and effort in ``Joint.drive_limits``), survives a mechanism file
(``limits``, ``drive_limits``) and is written back as read; a mechanism that knows no limit
writes none (never ``effort="0" velocity="0"``, which ROS, Gazebo and MoveIt read as "cannot
move"): an unlimited revolute joint becomes ``continuous``. The expected values come from
the source file itself, read with ElementTree, not from our reader.
"""

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from click.testing import CliRunner

from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.io.loader import load_mechanism, parse_mechanism
from baseparams.model import generate
from baseparams.plugins.urdf.reader import read_urdf
from baseparams.plugins.urdf.writer import mechanism_urdf
from urdf_reference import example_robot_data, robot_id

DATA = Path(__file__).parent / "data" / "urdf"
ERD = example_robot_data()
# in the default run (about 0.1 s each): renamed joints (allegro), mimic followers whose range
# the reader drops (pr2), continuous joints, limited arms; the other 60 robots are `slow`
FAST = {"allegro_hand_description/allegro_left_hand", "pr2_description/pr2", "panda_description/panda",
        "double_pendulum_description/double_pendulum_continuous", "ur_description/ur5_robot",
        "talos_data/talos_left_arm", "so_arm_description/so100"}


def source_limits(path: Path) -> dict[str, dict[str, float]]:
    """{joint: {lower, upper, effort, velocity}} as the file states them (positive effort and
    velocity only: 0 is the common "not given"; a position range only with lower < upper;
    no position range on a continuous joint), for revolute, continuous and prismatic joints."""
    out = {}
    for joint in ET.parse(path).getroot().findall("joint"):
        kind, limit = joint.get("type"), joint.find("limit")
        if kind not in ("revolute", "continuous", "prismatic") or limit is None:
            continue
        values = {k: float(limit.get(k)) for k in ("effort", "velocity") if float(limit.get(k, 0)) > 0}
        lo, hi = float(limit.get("lower", 0)), float(limit.get("upper", 0))
        if kind != "continuous" and lo < hi:
            values.update(lower=lo, upper=hi)
        out[joint.get("name")] = values
    return out


def mechanism_limits(mech) -> dict[str, dict[str, float]]:
    """The same view of a mechanism: per coordinate, its position range and drive limits."""
    out = {}
    for joint in mech.joints:
        for name in joint.coordinates:
            values = dict(joint.drive_limits.get(name, {}))
            if name in joint.limits:
                values.update(zip(("lower", "upper"), joint.limits[name]))
            out[name] = values
    return out


def written(mech, tmp_path: Path) -> tuple[Path, list[str]]:
    """The mechanism written anew (generate mode, not a patch of its source file)."""
    text, notes = mechanism_urdf(mech)
    path = tmp_path / "written.urdf"
    path.write_text(text, encoding="utf-8")
    return path, notes


def erd_cases() -> list:
    if not ERD:
        return [pytest.param(None, marks=pytest.mark.skip(reason="example-robot-data is not installed "
                                                                 "(pip install example-robot-data)"))]
    return [pytest.param(path, id=robot_id(path), marks=() if robot_id(path) in FAST else pytest.mark.slow)
            for path in ERD]


def _readable(path: Path):
    try:
        return read_urdf(path)
    except InputError as exc:                      # refused with a reason (nothing moves, ...)
        pytest.skip(f"the reader refuses it: {str(exc)[:80]}")


def check_round_trip(path: Path, tmp_path: Path) -> None:
    result = _readable(path)
    mech = result.mechanism
    if not mech.coordinates:
        pytest.skip("nothing moves")
    renamed = dict(re.findall(r"joint\[name=(.*?)\]: coordinate named '(.*?)'", "\n".join(result.notes)))
    dropped = re.findall(r"joint\[name=(.*?)\]\.limit: .* not enforced", "\n".join(mech.warnings))
    expected = {}
    for name, values in source_limits(path).items():
        if name in dropped:             # a follower's range that contradicts its <mimic> (PR2), warned
            values = {k: v for k, v in values.items() if k not in ("lower", "upper")}
        if values and renamed.get(name, name) in mech.coordinates:
            expected[renamed.get(name, name)] = values
    got = {name: values for name, values in mechanism_limits(mech).items() if values}
    assert {k: v for k, v in got.items() if k in expected} == expected   # read: every limit kept
    assert set(got) <= set(expected)
    out, _ = written(mech, tmp_path)
    back = load_mechanism(out)
    assert {k: v for k, v in mechanism_limits(back).items() if v} == got  # written back exactly
    for limit in ET.parse(out).getroot().iter("limit"):                  # and nothing invented
        for attr in ("effort", "velocity"):
            assert attr not in limit.attrib or float(limit.get(attr)) > 0


@pytest.mark.parametrize("path", sorted(DATA.glob("*.urdf")), ids=lambda p: p.stem)
def test_limits_survive_read_write_read(tmp_path, path):
    check_round_trip(path, tmp_path)


@pytest.mark.parametrize("path", erd_cases())
def test_example_robot_data_limits_survive_read_write_read(tmp_path, path):
    check_round_trip(path, tmp_path)


def test_limits_survive_a_mechanism_file(tmp_path):
    """URDF -> TOML -> URDF (README's convert example): the TOML carries them."""
    source = DATA / "ur5.urdf"
    toml, urdf = tmp_path / "ur5.toml", tmp_path / "ur5.urdf"
    for args in (["convert", str(source), "-o", str(toml)], ["convert", str(toml), "-o", str(urdf)]):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.stderr
    assert "drive_limits" in toml.read_text()
    assert mechanism_limits(load_mechanism(urdf)) == mechanism_limits(load_mechanism(source))
    assert {k: v for k, v in mechanism_limits(load_mechanism(urdf)).items() if v} == source_limits(source)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_mechanism_without_limits_writes_no_limit(tmp_path, seed):
    """Generated trees (R and P joints, no limits): no <limit> at all, revolute joints written
    continuous, and a note names the prismatic joints URDF wants a <limit> for."""
    mech = parse_mechanism(generate.tree(seed, bodies=5))
    assert not any(j.limits or j.drive_limits for j in mech.joints)
    out, notes = written(mech, tmp_path)
    root = ET.parse(out).getroot()
    assert root.find(".//limit") is None
    kinds = {j.get("name"): j.get("type") for j in root.findall("joint")}
    for joint in mech.joints:
        want = {"R": "continuous", "P": "prismatic"}.get(joint.type.name)
        if want:
            assert kinds[joint.coordinates[0]] == want
    prismatic = [j.coordinates[0] for j in mech.joints if j.type.name == "P"]
    assert all(any(name in note and "not written" in note for note in notes) for name in prismatic)


def test_positions_without_drive_limits_are_written_without_invented_ones(tmp_path):
    """PUMA 560's file has position ranges only: they are written, effort and velocity are
    not (and the note says URDF parsers need them)."""
    from baseparams.io.loader import resolve
    mech = resolve("puma560")
    out, notes = written(mech, tmp_path)
    limits = list(ET.parse(out).getroot().iter("limit"))
    assert len(limits) == 6 and all(set(limit.attrib) == {"lower", "upper"} for limit in limits)
    assert any("effort, velocity" in note for note in notes)
    back = load_mechanism(out)
    assert mechanism_limits(back) == mechanism_limits(mech)


def test_continuous_joint_keeps_effort_and_velocity(tmp_path):
    text = ('<robot name="wheel"><link name="base"/><link name="wheel"><inertial><mass value="1"/>'
            '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="2"/></inertial></link>'
            '<joint name="spin" type="continuous"><parent link="base"/><child link="wheel"/>'
            '<axis xyz="0 0 1"/><limit effort="12.5" velocity="30"/></joint></robot>')
    path = tmp_path / "wheel.urdf"
    path.write_text(text)
    mech = read_urdf(path).mechanism
    assert mech.joints[0].drive_limits == {"spin": {"effort": 12.5, "velocity": 30.0}}
    assert mech.joints[0].limits == {}
    out, _ = written(mech, tmp_path)
    joint = ET.parse(out).getroot().find("joint")
    assert joint.get("type") == "continuous"
    assert joint.find("limit").attrib == {"effort": "12.5", "velocity": "30.0"}


@pytest.mark.parametrize("entry,reason", [('effort = "-1"', "must be a positive number"),
                                          ('effort = "0"', "must be a positive number"),
                                          ('speed = "1"', "unknown key")])
def test_bad_drive_limits_are_refused_with_the_key(entry, reason):
    text = generate.serial_chain(1, bodies=1)
    name = parse_mechanism(text).joints[0].coordinates[0]
    bad = text.replace("[[joints]]\n", f"[[joints]]\ndrive_limits = {{ {name} = {{ {entry} }} }}\n", 1)
    with pytest.raises(InputError, match=reason) as info:
        parse_mechanism(bad)
    assert "joints[0].drive_limits" in str(info.value)
