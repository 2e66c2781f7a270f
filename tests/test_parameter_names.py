"""Link names in parameter names (issue 45): a URDF model's parameters are named after its
links (``m_forearm``), in every output; mechanism files keep their numbered names
(``m3``); inputs take either form. Names are made by ``params.parameter_name`` and read by
``params.split_name`` alone."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import baseparams as bp
from baseparams.cli.commands import main
from baseparams.io.loader import load_mechanism, resolve
from baseparams.model.params import PARAMETER_KINDS, parameter_name, parameter_names, split_name

DATA = Path(__file__).parent / "data" / "urdf"
ARM = DATA / "gripper_arm.urdf"
LINKS = ["turret_link", "upper_arm", "forearm", "finger_left_link", "finger_right_link", "camera"]


def _cli(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.parametrize("kind", PARAMETER_KINDS)
@pytest.mark.parametrize("body", [1, 12, "forearm", "m_x1", "x", "12"])
def test_a_name_reads_back_to_its_kind_and_body(kind, body):
    assert split_name(parameter_name(kind, body)) == (kind, body)


def test_numbered_and_named_forms_do_not_collide():
    """'mx1' (body 1's mx) and 'm_x1' (a body named x1's m) are apart; so are every kind's."""
    numbered = set(parameter_names(range(1, 30)))
    named = set(parameter_names(["x1", "x", "y2", "xx1", "1"]))
    assert not numbered & named and len(named) == 50
    for bad in ("m", "m_", "q1", "Ixx", "mx-1", "m１"):
        with pytest.raises(ValueError):
            split_name(bad)


def test_a_urdf_names_its_parameters_after_its_links_and_a_mechanism_file_by_labels():
    arm = load_mechanism(ARM)
    assert arm.parameters == [f"{k}_{link}" for link in LINKS for k in PARAMETER_KINDS]
    assert resolve("planar_2r").parameters[:11] == ["m1", "mx1", "my1", "mz1", "Ixx1", "Ixy1", "Ixz1", "Iyy1",
                                                    "Iyz1", "Izz1", "m2"]
    # either form names the same parameter; anything else is no parameter of the arm
    assert arm.parameter("Izz3") == arm.parameter("Izz_forearm") == "Izz_forearm"
    assert arm.parameter_body("m_camera") == ("m", 6) and arm.body_parameters(3)[0] == "m_forearm"
    for bad in ("m7", "m_palm", "fv_turret"):
        with pytest.raises(ValueError):
            arm.parameter(bad)


def test_link_names_that_are_no_identifiers_are_made_identifiers(tmp_path):
    urdf = tmp_path / "odd.urdf"
    urdf.write_text('<robot name="odd"><link name="base"/><link name="arm-1.a"><inertial><mass value="1"/>'
                    '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
                    '<joint name="j" type="revolute"><parent link="base"/><child link="arm-1.a"/>'
                    '<axis xyz="0 0 1"/></joint></robot>')
    from baseparams.plugins.urdf.reader import read_urdf
    result = read_urdf(urdf)
    assert result.mechanism.parameters[0] == "m_arm_1_a"
    assert any("m_arm_1_a" in note for note in result.notes)


def test_every_output_of_a_urdf_carries_the_link_names(tmp_path):
    """solve's text, JSON and CSV, show, export, the frames: one set of names, the links'."""
    names = set(load_mechanism(ARM).parameters)
    text = _cli("solve", ARM, "--solver", "exact", "--quiet")
    data = json.loads(_cli("solve", ARM, "--solver", "exact", "--format", "json", "--quiet"))
    csv = _cli("solve", ARM, "--solver", "exact", "--format", "csv", "--quiet")
    assert set(data["parameters"]) == names and set(data["eliminated"]) <= names
    used = {p for row in data["base"] for p in row["expression"]}
    assert used <= names and "mx_upper_arm" in used
    for out in (text, csv):
        written = set(re.findall(r"\b(?:m|mx|my|mz|I[xyz]{2})\w*", out))
        assert written & names and not {w for w in written if re.fullmatch(r"(?:m|mx|my|mz|I[xyz]{2})\d+", w)}
    shown = json.loads(_cli("show", ARM, "--format", "json"))
    assert set(shown["parameters"]) == names
    module = bp.export(str(ARM), solver="exact").source
    assert "'m_forearm'" in module and "'m3'" not in module
    frame = bp.solve(str(ARM), solver="exact").to_frame()
    assert list(frame["expression"]) == [line.split(",", 1)[1] for line in csv.splitlines()[1:]]


def test_identify_and_diagnose_read_results_in_either_form(tmp_path):
    """An identify result written with numbered names (m3: before issue 45, or by hand) is
    read by diagnose --params as the same result as the one with the links' names."""
    from baseparams.diagnose.given import given_parameters
    data = tmp_path / "arm.csv"
    bp.simulate(str(ARM), output=str(data), noise=0.001, seed=2)
    fit = bp.identify(str(ARM), str(data), solver="dp").to_json()
    assert {p for row in fit["base"] for p in row["expression"]} <= set(load_mechanism(ARM).parameters)
    mech = load_mechanism(ARM)
    rename = {name: f"{kind}{label}" for name in mech.parameters for kind, label in [mech.parameter_body(name)]}

    def numbered_names(value):               # every standard parameter's name, wherever it is written
        if isinstance(value, dict):
            return {rename.get(k, k): numbered_names(v) for k, v in value.items()}
        if isinstance(value, list):
            return [numbered_names(v) for v in value]
        return rename.get(value, value) if isinstance(value, str) else value

    numbered = numbered_names(fit)
    assert "m3" in json.dumps(numbered) and "m_forearm" not in json.dumps(numbered)
    paths = [tmp_path / "named.json", tmp_path / "numbered.json"]
    for path, content in zip(paths, (fit, numbered)):
        path.write_text(json.dumps(content))
    named_given, numbered_given = (given_parameters(mech, str(p)) for p in paths)
    assert np.array_equal(named_given.parameters, numbered_given.parameters)
    assert np.array_equal(named_given.base_map, numbered_given.base_map)


def test_the_symbolic_derivation_writes_a_link_name_as_a_subscript():
    from baseparams.cli.report import _Writer
    writer = _Writer.__new__(_Writer)
    writer.fmt = "latex"
    assert writer.param("Izz12") == r"\mathit{Izz}_{12}"
    assert writer.param("Izz_fore_arm") == r"\mathit{Izz}_{\mathrm{fore\_arm}}"


def test_the_symbolic_solvers_keep_option_takes_either_form():
    named, numbered = (bp.solve(str(ARM), solver="symbolic", solver_options={"keep": (name,)}).to_json()
                       for name in ("m_forearm", "m3"))
    assert named["base"] == numbered["base"] and "m_forearm" not in named["eliminated"]
    with pytest.raises(bp.InputError if hasattr(bp, "InputError") else Exception, match="not a parameter"):
        bp.solve(str(ARM), solver="symbolic", solver_options={"keep": ("m_palm",)})
