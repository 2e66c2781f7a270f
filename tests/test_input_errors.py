"""Bad mechanism files through the command line: exit code 2, one line naming the file,
the key path and the reason, and never a traceback (docs/design.md, "Command line")."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from baseparams.cli.commands import main

# A valid one-body mechanism; each case below breaks one thing in it.
GOOD = """\
[mechanism]
name = "probe"

[geometry]
L = "0.5"

[[bodies]]
label = 1
name = "rod"

[[joints]]
name = "pivot"
type = "R"
parent = 0
child = 1
parent_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"] }

[trajectory]
q = { pivot = "0.5*sin(t)" }
"""

PARENT_FRAME = 'parent_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"] }'

# Three bodies in a plane (a triangle of parallel revolute joints): the loop locks it.
TRUSS = """\
[mechanism]
name = "truss"

[[bodies]]
label = 1

[[bodies]]
label = 2

[[joints]]
type = "R"
parent = 0
child = 1
parent_frame = { point = ["0", "0", "0"] }
child_frame = { point = ["0", "0", "0"] }

[[joints]]
type = "R"
parent = 0
child = 2
parent_frame = { point = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0"] }

[[joints]]
type = "R"
parent = 1
child = 2
parent_frame = { point = ["0.5", "0.5", "0"] }
child_frame = { point = ["-0.5", "0.5", "0"] }
"""


def edit(old, new):
    assert old in GOOD
    return GOOD.replace(old, new, 1)


CASES = {
    # name: (file text, key path, words of the reason); a TOML syntax error has no key
    # path yet, so its location is the line
    "malformed_toml": (GOOD.replace('name = "rod"', 'name = "rod'), "line 9", ["malformed TOML"]),
    "unknown_joint_type": (edit('type = "R"', 'type = "Q"'), "joints[0].type",
                           ["unknown joint type 'Q'", "known:", "Fixed", "P", "R", "S", "U"]),
    "unknown_body": (edit("child = 1", "child = 5"), "joints[0].child", ["unknown body 5"]),
    "duplicate_label": (edit('name = "rod"', 'name = "rod"\n\n[[bodies]]\nlabel = 1'),
                        "bodies[1].label", ["duplicate body label 1"]),
    "not_connected": (edit('name = "rod"', 'name = "rod"\n\n[[bodies]]\nlabel = 2'),
                      "joints", ["body 2 is not connected to ground"]),
    "zero_axis": (edit(PARENT_FRAME, PARENT_FRAME.replace('["0", "1", "0"]', '["0", "0", "0"]')),
                  "joints[0].parent_frame.axis", ["zero-length axis"]),
    "geometry_not_decimal": (edit('L = "0.5"', 'L = "0.5 m"'), "geometry.L",
                             ["'0.5 m' is not a decimal number"]),
    "point_with_two_components": (
        edit(PARENT_FRAME, PARENT_FRAME.replace('["0", "0", "0"]', '["0", "0"]')),
        "joints[0].parent_frame.point", ["must be a list of 3"]),
    "no_degree_of_freedom": (TRUSS, "joints", ["no degree of freedom", "Gruebler count -3"]),
    "unknown_name": (edit(PARENT_FRAME, PARENT_FRAME.replace('["0", "0", "0"]', '["Lx", "0", "0"]')),
                     "joints[0].parent_frame.point[0]", ["unknown name 'Lx'", "geometry names: L"]),
    # the schema: unknown keys with a suggestion, types before use
    "misspelt_key": (edit('type = "R"', 'typ = "R"'), "joints[0].typ",
                     ["unknown key; did you mean 'type'?", "known: name, type"]),
    "misspelt_frame_key": (edit(PARENT_FRAME, PARENT_FRAME.replace("axis", "axes")),
                           "joints[0].parent_frame.axes", ["did you mean 'axis'?"]),
    "misspelt_section": (GOOD.replace("[trajectory]", "[trajectroy]"), "trajectroy",
                         ["unknown section; did you mean 'trajectory'?"]),
    "missing_required": (edit('type = "R"\n', ""), "joints[0].type", ["missing (required)"]),
    "type_is_a_list": (edit('type = "R"', 'type = ["R"]'), "joints[0].type",
                       ["must be a string, not an array"]),
    "label_is_a_string": (edit("label = 1", 'label = "1"'), "bodies[0].label",
                          ["must be an integer, not a string"]),
    "huge_integer": (edit("child = 1", "child = " + "9" * 5000), "line 15",
                     ["an integer with more than 4300 digits"]),
    "samples_too_many": (edit("[trajectory]", "[trajectory]\nsamples = 1000000000"), "trajectory.samples",
                         ["from 2 to 1,000,000"]),
    # names
    "parameter_name": (edit('L = "0.5"', 'L = "0.5"\nIzz1 = "1"'), "geometry.Izz1",
                       ["inertial parameter's name"]),
    "sympy_name": (edit('L = "0.5"', 'L = "0.5"\nE = "1"'), "geometry.E", ["means something else to sympy"]),
    "reserved_coordinate": (edit('name = "pivot"', 'name = "pivot"\ncoordinates = ["t"]'), "joints[0].coordinates",
                            ["name 't' is reserved"]),
    "keyword_joint_name": (edit('name = "pivot"', 'name = "lambda"').replace("pivot =", "lambda ="),
                           "joints[0].coordinates", ["name 'lambda' is reserved", "joint's name is its coordinate's"]),
    # physics
    "negative_mass": (edit('name = "rod"', 'name = "rod"\nmass = "-1"\ncom = ["0", "0", "0"]\n'
                                         'inertia_com = ["1", "0", "0", "1", "0", "1"]'),
                      "bodies[0].mass", ["body 1 (rod): negative mass -1"]),
    "inertia_not_psd": (edit('name = "rod"', 'name = "rod"\nmass = "1"\ncom = ["L", "0", "0"]\n'
                                           'inertia_com = ["1", "2", "0", "1", "0", "1"]'),
                        "bodies[0].inertia_com", ["body 1 (rod)", "not positive semi-definite", "-1, 1, 3"]),
    "triangle_inequality": (edit('name = "rod"', 'name = "rod"\nmass = "1"\ncom = ["0", "0", "0"]\n'
                                               'inertia_com = ["1", "0", "0", "0.1", "0", "0.1"]'),
                            "bodies[0].inertia_com", ["triangle inequality", "0.1, 0.1, 1"]),
    "inertia_about_origin": (edit('name = "rod"', 'name = "rod"\ninertia = { m = "1", mx = "1", my = "0", '
                                                'mz = "0", Ixx = "0", Ixy = "0", Ixz = "0", Iyy = "0", Iyz = "0", '
                                                'Izz = "0" }'),
                             "bodies[0].inertia", ["at the centre of mass is not positive semi-definite"]),
    "mass_without_com": (edit('name = "rod"', 'name = "rod"\nmass = "1"'), "bodies[0].com", ["must be a list of 3"]),
    # numerics and the trajectory (show checks what solve would)
    "coaxial_twin": (GOOD.replace("[trajectory]", "[[joints]]\nname = \"twin\"\ntype = \"R\"\nparent = 0\n"
                                  "child = 1\nloop = true\n" + PARENT_FRAME + "\n"
                                  + PARENT_FRAME.replace("parent_", "child_") + "\n\n[trajectory]"),
                     "joints[1]", ["joint 'twin' (R, 0 -> 1) is redundant"]),
    "trajectory_leaves_limits": (edit('name = "pivot"', 'name = "pivot"\nlimits = { pivot = ["-0.1", "0.1"] }'),
                                 "trajectory", ["coordinate pivot", "leaves its range [-0.1, 0.1]"]),
    "trajectory_not_finite": (edit('"0.5*sin(t)"', '"1/(t - 10)"'), "trajectory", ["not finite"]),
    "utf16": (None, "", ["not UTF-8 text"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_file_is_reported_with_file_key_and_reason(case, tmp_path):
    text, key, reasons = CASES[case]
    path = tmp_path / f"{case}.toml"
    if text is None:                                   # the good file, UTF-16 encoded
        path.write_text(GOOD, encoding="utf-16")
    else:
        path.write_text(text, encoding="utf-8")
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)          # not an unhandled exception
    assert result.stdout == ""
    message = result.stderr.strip()
    assert "\n" not in message and "Traceback" not in result.output
    assert message.startswith(f"error: {path}: ")
    assert key in message
    assert "Decimal(" not in message and "Fraction(" not in message
    for reason in reasons:
        assert reason in message


def test_the_good_file_loads(tmp_path):
    """The cases above fail because of their one change, not because the base file is bad."""
    path = tmp_path / "good.toml"
    path.write_text(GOOD, encoding="utf-8")
    result = CliRunner().invoke(main, ["show", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert '"dof": 1' in result.stdout


def test_missing_file_and_unknown_name():
    result = CliRunner().invoke(main, ["show", "no/such/file.toml"])
    assert result.exit_code == 2
    assert result.stderr.strip() == "error: no/such/file.toml: no such file"
    result = CliRunner().invoke(main, ["show", "no_such_mechanism"])
    assert result.exit_code == 2
    assert "unknown mechanism 'no_such_mechanism'" in result.stderr and "sla_suspension" in result.stderr


def test_real_process_prints_no_traceback(tmp_path):
    """The same through a real interpreter: stderr is the one message, nothing else."""
    text, key, _ = CASES["unknown_joint_type"]
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "baseparams.cli", "show", str(path)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.startswith(f"error: {path}: {key}: unknown joint type")
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr


def test_a_utf8_byte_order_mark_is_skipped(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD.encode("utf-8"))
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 0, result.output


def test_zero_mass_with_inertia_is_a_warning_show_prints(tmp_path):
    path = tmp_path / "rotor.toml"
    path.write_text(edit('name = "rod"', 'name = "rod"\nmass = "0"\ncom = ["0", "0", "0"]\n'
                                       'inertia_com = ["0", "0", "0", "0", "0", "0.35"]'), encoding="utf-8")
    result = CliRunner().invoke(main, ["show", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert result.stderr.startswith(f"warning: {path}: bodies[0].inertia_com: body 1 (rod): zero mass")
    assert json.loads(result.stdout)["warnings"] == [result.stderr.strip().removeprefix("warning: ")]


def test_a_long_number_is_not_echoed_whole(tmp_path):
    path = tmp_path / "long.toml"
    path.write_text(edit('L = "0.5"', 'L = "' + "9" * 5000 + '"'), encoding="utf-8")
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2 and len(result.stderr) < 300 and "9" * 100 not in result.stderr


def test_sample_memory_is_estimated_and_refused_before_allocating(tmp_path, monkeypatch):
    """The estimate and how to raise the limit; raising it lets the same run through. (dp
    builds W in row blocks within the limit instead, since issue 47: tests/test_full_size.py.)"""
    monkeypatch.setenv("BASEPARAMS_MAX_MEMORY", "1M")
    result = CliRunner().invoke(main, ["solve", "pendulum", "--solver", "vp", "--samples", "5000"])
    assert result.exit_code == 2
    assert "5,000 samples need about 19 MiB of working memory" in result.stderr
    assert "above the limit of 1 MiB" in result.stderr and "BASEPARAMS_MAX_MEMORY" in result.stderr
    result = CliRunner().invoke(main, ["solve", "pendulum", "--solver", "dp", "--samples", "5000"])
    assert result.exit_code == 0 and "row blocks" in result.output, result.output
    monkeypatch.setenv("BASEPARAMS_MAX_MEMORY", "1G")
    result = CliRunner().invoke(main, ["solve", "pendulum", "--solver", "dp", "--samples", "5000"])
    assert result.exit_code == 0, result.output
    monkeypatch.setenv("BASEPARAMS_MAX_MEMORY", "lots")
    result = CliRunner().invoke(main, ["solve", "pendulum", "--solver", "dp"])
    assert result.exit_code == 2 and "BASEPARAMS_MAX_MEMORY must be a size" in result.stderr


def test_write_errors_and_unknown_image_formats_are_bad_input(tmp_path):
    if Path("/dev/full").exists():
        result = CliRunner().invoke(main, ["report", "pendulum", "--no-certify", "-o", "/dev/full"])
        assert result.exit_code == 2 and "cannot write the report" in result.stderr
    result = CliRunner().invoke(main, ["plot", "mechanism", "pendulum", "-o", str(tmp_path / "x.jpg")])
    assert result.exit_code == 2 and "cannot write a 'jpg' image" in result.stderr
    assert not (tmp_path / "x.jpg").exists()
