"""Bad mechanism files through the command line: exit code 2, one line naming the file,
the key path and the reason, and never a traceback (docs/design.md, "Command line")."""

import subprocess
import sys

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
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_file_is_reported_with_file_key_and_reason(case, tmp_path):
    text, key, reasons = CASES[case]
    path = tmp_path / f"{case}.toml"
    path.write_text(text, encoding="utf-8")
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)          # not an unhandled exception
    assert result.stdout == ""
    message = result.stderr.strip()
    assert "\n" not in message and "Traceback" not in result.output
    assert message.startswith(f"error: {path}: ")
    assert key in message
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
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.startswith(f"error: {path}: {key}: unknown joint type")
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
