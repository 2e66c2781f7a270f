"""The command line: list, show, plugins, plot mechanism, --help, --version, exit codes
(solve's options and solver contract: tests/test_solver_protocol.py).

Expected structure numbers come from the seed paper (SLA: 2 dof, 3 loops, 70 inertial
parameters) and from mobility formulas (a planar four-bar and slider-crank: 3(n-1) - 2j
= 1), and the JSON is compared field by field with the mechanism loaded by the library.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.io.loader import resolve


def run(*args, code=0):
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == code, result.output
    return result


def run_json(*args):
    return json.loads(run(*args, "--format", "json").stdout)


def test_version():
    assert "baseparams, version 0.1.0" in run("--version").stdout


# ----- list -----------------------------------------------------------------------
def test_list_json_matches_the_registry():
    data = run_json("list")
    known = registry.mechanisms()
    assert [m["name"] for m in data["mechanisms"]] == list(known)
    for m in data["mechanisms"]:
        assert m["source"] == known[m["name"]].distribution == "baseparams"
        assert m["title"] == resolve(m["name"]).title
        assert "error" not in m


def test_list_text_has_one_line_per_mechanism():
    lines = run("list").stdout.splitlines()
    assert len(lines) == len(registry.mechanisms())
    sla = next(line for line in lines if line.startswith("sla_suspension "))
    assert "baseparams" in sla and resolve("sla_suspension").title in sla


# ----- show -----------------------------------------------------------------------
def test_show_sla_matches_the_seed_paper():
    info = run_json("show", "sla_suspension")
    assert (info["dof"], info["loops"], info["parameter_count"]) == (2, 3, 70)
    assert info["independent"] == ["theta1", "theta2"]
    assert info["bodies"] == [1, 2, 3, 4, 5, 6, 7]
    # docs/design.md's SLA joint list: 0-1 R, 0-2 R, 1-3 S, 2-3 S, 0-4 U, 4-3 S, 3-5 R, 0-6 U, 6-7 P, 7-1 S
    assert [(j["parent"], j["child"], j["type"]) for j in info["joints"]] == [
        (0, 1, "R"), (0, 2, "R"), (1, 3, "S"), (2, 3, "S"), (0, 4, "U"), (4, 3, "S"), (3, 5, "R"),
        (0, 6, "U"), (6, 7, "P"), (7, 1, "S")]
    assert sum(j["role"] == "loop" for j in info["joints"]) == 3
    assert info["geometry"]["D12"] == "0.3196" and info["geometry"]["L7"] == "0.427"


@pytest.mark.parametrize("name", ["sla_suspension", "four_bar", "pendulum"])
def test_show_json_agrees_with_the_loaded_mechanism(name):
    mech = resolve(name)
    info = run_json("show", name)
    assert set(info) >= {"name", "bodies", "joints", "coordinates", "independent", "dof", "loops", "parameters"}
    assert info["name"] == mech.name
    assert info["bodies"] == [b.label for b in mech.bodies]
    assert info["body_names"] == [b.name for b in mech.bodies]
    assert info["coordinates"] == list(mech.coordinates)
    assert info["parameters"] == list(mech.parameters)
    assert info["parameter_count"] == 10 * len(mech.bodies)
    assert info["loops"] == len(mech.loops)
    loop_names = {j.name for j in mech.loops}
    for shown, joint in zip(info["joints"], mech.joints, strict=True):
        assert (shown["name"], shown["type"], shown["parent"], shown["child"]) == \
            (joint.name, joint.type.name, joint.parent, joint.child)
        assert shown["role"] == ("loop" if joint.name in loop_names else "tree")
    # Gruebler: 6 per moving body minus the constraints of every joint
    assert info["gruebler"] == 6 * len(mech.bodies) - sum(6 - j.type.dof for j in mech.joints)
    # dof = tree coordinates - independent closure equations
    rank = info["closure_equations"] - info["redundant_closure_equations"]
    assert info["dof"] == len(info["coordinates"]) - rank == len(info["independent"])


@pytest.mark.parametrize("name, dof", [("pendulum", 1), ("four_bar", 1), ("slider_crank", 1), ("planar_2r", 2)])
def test_show_dof_of_planar_mechanisms(name, dof):
    """Planar mobility 3(n-1) - 2j (n links with the ground, j one-dof joints)."""
    mech = resolve(name)
    planar = 3 * len(mech.bodies) - 2 * len(mech.joints)
    info = run_json("show", name)
    assert info["dof"] == planar == dof
    # in the plane each closing one-dof joint imposes 2 of its 5 equations: 3 are redundant
    assert info["redundant_closure_equations"] == 3 * len(mech.loops)


def test_show_text_and_path():
    path = resolve("four_bar").path
    text = run("show", path).stdout
    assert text.startswith("four_bar: ")
    assert "degrees of freedom: 1 (Gruebler count -2)" in text
    assert "loops: 1 (5 closure equations, 3 redundant)" in text
    assert "JC " in text and "(closes a loop)" in text
    assert "m3 mx3 my3 mz3 Ixx3 Ixy3 Ixz3 Iyy3 Iyz3 Izz3" in text


# ----- plugins --------------------------------------------------------------------
def test_plugins_json_lists_builtins_with_their_distribution():
    data = run_json("plugins")
    assert set(data) >= {"joints", "solvers", "mechanisms", "effects"}
    joints = {j["name"]: j for j in data["joints"]}
    assert set(joints) == set(registry.joint_types()) >= {"R", "P", "S", "U", "Fixed"}
    for name in ("R", "P", "S", "U", "Fixed"):
        assert joints[name]["distribution"] == "baseparams"
        assert joints[name]["transfer_rules"] is True
    assert (joints["S"]["dof"], joints["S"]["suffixes"]) == (3, ["a", "b", "c"])
    assert [m["name"] for m in data["mechanisms"]] == list(registry.mechanisms())
    for kind, found in (("solvers", registry.solvers()), ("effects", registry.effects())):
        assert {(i["name"], i["distribution"]) for i in data[kind]} == \
            {(n, r.distribution) for n, r in found.items()}


def test_plugins_text():
    text = run("plugins").stdout
    for heading in ("joints (", "solvers (", "mechanisms (", "effects ("):
        assert heading in text
    assert any(line.split()[:2] == ["U", "baseparams"] for line in text.splitlines())


# ----- help -----------------------------------------------------------------------
@pytest.mark.parametrize("verb, words", [
    ([], ["list", "show", "plugins", "plot", "Exit codes"]),
    (["list"], ["registered mechanisms", "--format"]),
    (["show"], ["MECH", "Gruebler", "--format"]),
    (["plugins"], ["entry-point group", "--format"]),
    (["plot"], ["mechanism"]),
    (["plot", "mechanism"], ["--instants", "--output", "png|pdf|svg"]),
    (["solve"], ["--solver", "--option NAME=VALUE", "Registered solvers", "  dp ", "  vp ", "  exact ",
                 "  symbolic ", "-O recover", "not applicable"]),
    (["report"], ["--solver", "derivation", "--keep"]),
])
def test_help(verb, words):
    text = run(*verb, "--help").stdout
    assert text.startswith("Usage: ")
    for w in words:
        assert w in text


def test_usage_error_exits_2():
    result = run("show", code=2)
    assert "Missing argument 'MECH'" in result.stderr
    run("list", "--format", "yaml", code=2)


# ----- plot mechanism -------------------------------------------------------------
def test_plot_mechanism_writes_a_png(tmp_path):
    import matplotlib.image

    out = tmp_path / "four_bar.png"
    result = run("plot", "mechanism", "four_bar", "-o", str(out), "--instants", "3")
    assert result.stdout.strip() == f"wrote {out}"
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = matplotlib.image.imread(out)
    # not blank: the crank's colour (tab10 blue, #1f77b4) is drawn
    blue = np.all(np.abs(image[..., :3] - np.array([0x1F, 0x77, 0xB4]) / 255) < 0.02, axis=-1)
    assert blue.sum() > 100


def test_plot_mechanism_formats(tmp_path):
    out = tmp_path / "figure.out"
    run("plot", "mechanism", "pendulum", "-o", str(out), "--format", "svg", "--instants", "1")
    assert b"<svg" in out.read_bytes()[:1000]


def test_kinematics_error_exits_2(tmp_path):
    """A trajectory that leaves a coordinate's range is bad input: one line, exit code 2."""
    text = open(resolve("pendulum").path, encoding="utf-8").read()
    text = text.replace('coordinates = ["theta"]', 'coordinates = ["theta"]\nlimits = { theta = ["-0.5", "0.5"] }')
    path = tmp_path / "limited.toml"
    path.write_text(text, encoding="utf-8")
    result = run("plot", "mechanism", str(path), "-o", str(tmp_path / "x.png"), code=2)
    assert result.stderr.startswith("error: at t = ") and "coordinate theta" in result.stderr
    assert "leaves its range [-0.5, 0.5]" in result.stderr and "Traceback" not in result.output
    assert isinstance(result.exception, SystemExit)


def test_show_gives_the_files_citation():
    from baseparams.io.loader import resolve
    info = json.loads(CliRunner().invoke(main, ["show", "puma560", "--format", "json"]).stdout)
    assert info["citation"] == resolve("puma560").source and "Armstrong" in info["citation"]


def test_an_internal_error_is_one_line_and_exit_3(monkeypatch):
    """A bug (here: the registry raising) is reported in one line, exit code 3; --debug
    lets the traceback through."""
    def broken():
        raise RuntimeError("boom")

    monkeypatch.setattr(registry, "mechanisms", broken)
    result = CliRunner().invoke(main, ["list"])
    assert result.exit_code == 3
    assert result.stderr.startswith("internal error: RuntimeError: boom") and "Traceback" not in result.stderr
    result = CliRunner().invoke(main, ["--debug", "list"])
    assert isinstance(result.exception, RuntimeError)
