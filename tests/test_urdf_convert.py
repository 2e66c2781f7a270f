"""`baseparams convert` and the writers (docs/urdf.md): TOML <-> URDF round trips give the same
base parameters, identified parameters go back into a URDF's <inertial> elements, and
`solve --format csv`."""

import csv
import io
import json
import re
import xml.etree.ElementTree as ET
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.dynamics.evaluator import Evaluator
from baseparams.io.loader import load_mechanism, parse_mechanism, resolve
from baseparams.io.toml_writer import mechanism_toml
from baseparams.model import generate
from baseparams.numeric.backends import Float64
from baseparams.plugins.urdf.parse import transform_parameters
from baseparams.plugins.urdf.rotations import IDENTITY

DATA = Path(__file__).parent / "data" / "urdf"
TREES = [name for name in registry.mechanisms() if not resolve(name).loops]


def run(*args, code=0):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == code, (result.stdout, result.stderr)
    return result


def solve(mech, solver, **options):
    return registry.solvers()[solver].item.solve(mech, **options)


def test_every_builtin_tree_is_tried():
    assert {"pendulum", "planar_2r", "puma560", "scara"} <= set(TREES)


@pytest.mark.parametrize("name", TREES)
def test_builtin_tree_toml_urdf_toml_same_exact_base_parameters(tmp_path, name):
    """Rational geometry, body origins on the joint axes: the same bodies come back exactly, so
    the exact solver gives the same base parameters, expression for expression."""
    urdf, toml = tmp_path / f"{name}.urdf", tmp_path / f"{name}.toml"
    run("convert", name, "-o", urdf)
    run("convert", urdf, "-o", toml)
    before, after = resolve(name), load_mechanism(toml)
    assert [b.inertia for b in after.bodies] == [b.inertia for b in before.bodies]
    a, b = solve(before, "exact"), solve(after, "exact")
    assert a.rank == b.rank
    assert a.base == b.base


def regressor(mech, z, zd, zdd):
    return Evaluator(mech, Float64()).sample(z, zd, zdd).regressor_array()


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5, 6])
def test_generated_tree_round_trip_same_regressor_up_to_the_frame_shift(tmp_path, seed):
    """Random trees (R, P; random rational frames, bodies off their axes, gravity along any
    axis): URDF moves a body's origin onto its revolute axis, so phi_urdf = T phi exactly
    (a shift); then K = K_urdf T at every state, and the dp ranks agree."""
    text = generate.tree(seed, bodies=4) if seed % 2 else generate.serial_chain(seed, bodies=4)
    g = ["0", "0", "-9.81"] if seed < 4 else [["9.81", "0", "0"], ["0", "-9.81", "0"], ["0", "0", "9.81"]][seed - 4]
    text = re.sub(r"gravity = \[.*\]", "gravity = [" + ", ".join(f'"{v}"' for v in g) + "]", text)
    mech = parse_mechanism(text)
    urdf = tmp_path / "g.urdf"
    notes = registry.writers()["urdf"].item.write(mech, urdf)
    back = load_mechanism(urdf)
    assert back.coordinates == mech.coordinates
    # T: each body's parameters shifted to its link origin (the writer's notes give the shifts)
    shifts = {b.label: (Fraction(0),) * 3 for b in mech.bodies}
    for note in notes:
        found = re.match(r"link (\S+): origin shifted by \(([^)]*)\) from body (\d+)", note)
        if found:
            shifts[int(found.group(3))] = tuple(Fraction(v) for v in found.group(2).split(", "))
    blocks = []
    for body in mech.bodies:
        cols = [transform_parameters(tuple(Fraction(int(i == k)) for i in range(10)), IDENTITY,
                                     tuple(-v for v in shifts[body.label])) for k in range(10)]
        blocks.append(np.array(cols, dtype=float).T)
    t_map = np.zeros((10 * len(blocks),) * 2)
    for k, block in enumerate(blocks):
        t_map[10 * k:10 * k + 10, 10 * k:10 * k + 10] = block
    phi = np.array([float(v) for b in mech.bodies for v in b.inertia])
    phi_back = np.array([float(v) for b in back.bodies for v in b.inertia])
    assert np.allclose(t_map @ phi, phi_back, rtol=1e-14, atol=1e-14)
    rng = np.random.default_rng(seed)
    n = len(mech.coordinates)
    z, zd, zdd = ([rng.uniform(-0.5, 0.5, 8) for _ in range(n)] for _ in range(3))
    k_before, k_after = regressor(mech, z, zd, zdd), regressor(back, z, zd, zdd)
    assert np.max(np.abs(k_before - k_after @ t_map)) <= 1e-12 * np.max(np.abs(k_before))
    assert solve(mech, "dp", samples=80).rank == solve(back, "dp", samples=80).rank


@pytest.mark.parametrize("path", sorted(DATA.glob("*.urdf")), ids=lambda p: p.stem)
def test_urdf_toml_urdf_keeps_every_body_exactly(tmp_path, path):
    toml, urdf = tmp_path / "r.toml", tmp_path / "r.urdf"
    run("convert", path, "-o", toml)
    first, second = load_mechanism(path), load_mechanism(toml)
    assert [b.inertia for b in first.bodies] == [b.inertia for b in second.bodies]
    assert [j.parent_frame for j in first.joints] == [j.parent_frame for j in second.joints]
    assert {(e.kind, e.coordinate) for e in first.effects} == {(e.kind, e.coordinate) for e in second.effects}
    run("convert", toml, "-o", urdf)
    third = load_mechanism(urdf)                     # generated anew: the same coordinates and bodies
    assert third.coordinates == first.coordinates
    rng = np.random.default_rng(7)
    z, zd, zdd = ([rng.uniform(-0.5, 0.5, 8) for _ in first.coordinates] for _ in range(3))
    k_first, k_third = regressor(first, z, zd, zdd), regressor(third, z, zd, zdd)
    assert np.max(np.abs(k_first - k_third)) <= 1e-12 * np.max(np.abs(k_first))
    assert {(e.kind, e.coordinate): e.values for e in third.effects} == {(e.kind, e.coordinate): e.values
                                                                        for e in first.effects}


def test_toml_writer_round_trips_every_builtin_mechanism():
    for name in registry.mechanisms():
        mech = resolve(name)
        back = parse_mechanism(mechanism_toml(mech))
        assert [b.inertia for b in back.bodies] == [b.inertia for b in mech.bodies]
        assert [(j.parent_frame, j.child_frame, j.loop) for j in back.joints] == \
               [(j.parent_frame, j.child_frame, j.loop) for j in mech.joints]
        assert back.independent == mech.independent and back.trajectory.expressions == mech.trajectory.expressions


def test_merge_fixed_through_convert(tmp_path):
    out = tmp_path / "merged.toml"
    result = run("convert", DATA / "ur5.urdf", "--merge-fixed", "-o", out)
    assert "merged into the ground" in result.stderr
    assert len(load_mechanism(out).bodies) == 6


def test_reader_options_other_readers_do_not_have(tmp_path):
    result = run("convert", "pendulum", "--merge-fixed", "-o", tmp_path / "p.toml", code=2)
    assert "has no --merge-fixed option" in result.stderr or "no reader" in result.stderr
    toml = tmp_path / "p.toml"
    run("convert", "pendulum", "-o", toml)
    result = run("convert", toml, "--merge-fixed", "-o", tmp_path / "q.toml", code=2)
    assert "the toml reader has no --merge-fixed option" in result.stderr


def test_urdf_writer_refusals(tmp_path):
    result = run("convert", "four_bar", "-o", tmp_path / "x.urdf", code=2)
    assert "URDF describes trees" in result.stderr
    result = run("convert", "pendulum", "-o", tmp_path / "x.sdf", code=2)
    assert "no writer for files ending in '.sdf'" in result.stderr


# ----- identified parameters back into <inertial> ---------------------------------------------------
def identified(mech, scale=Fraction(11, 10)):
    """A hand-made identify JSON: every body's parameters scaled (still physical)."""
    physical = {f"{k}{b.label}": str(float(v * scale)) for b in mech.bodies
                for k, v in zip(("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz"), b.inertia)}
    return {"mechanism": mech.name, "physical": physical, "fv_iiwa_joint_1": "0.5"}


def test_inertia_json_written_into_the_inertials_keeping_the_rest(tmp_path):
    source = DATA / "iiwa14.urdf"
    mech = load_mechanism(source)
    data = identified(mech)
    js, out = tmp_path / "identified.json", tmp_path / "iiwa14_identified.urdf"
    js.write_text(json.dumps(data))
    run("convert", source, "--inertia", js, "-o", out)
    root = ET.parse(out).getroot()
    assert root.find("link[@name='iiwa_link_0']/visual/geometry/mesh") is not None      # kept
    assert len(root.findall("joint")) == len(ET.parse(source).getroot().findall("joint"))
    back = load_mechanism(out)
    for body in back.bodies:
        expected = [Fraction(data["physical"][f"{k}{body.label}"]) for k in
                    ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")]
        assert np.allclose([float(v) for v in body.inertia], [float(v) for v in expected], rtol=1e-20, atol=1e-22)


def test_inertia_json_into_a_generated_urdf(tmp_path):
    js, out = tmp_path / "identified.json", tmp_path / "puma.urdf"
    mech = resolve("puma560")
    data = identified(mech)
    data["physical"].update({"m1": "0.5", "mx1": "0", "my1": "0", "mz1": "0", "Ixx1": "0.2", "Iyy1": "0.2"})
    js.write_text(json.dumps(data))
    run("convert", "puma560", "--inertia", js, "-o", out)
    back = load_mechanism(out)
    assert back.bodies[0].inertia[0] == Fraction("0.5") and back.bodies[1].inertia[0] == Fraction("19.14")


@pytest.mark.parametrize("change, message", [
    ({"m1": "-1"}, "physical.m1: body 1 is not physically consistent: negative mass"),
    ({"Ixx1": "-0.5"}, "physical.m1: body 1 is not physically consistent"),
    ({"m9": "1"}, "physical.m9: body 9 is not a body"),
    ({"Izz2": "abc"}, "physical.Izz2"),
])
def test_inertia_json_refusals(tmp_path, change, message):
    mech = resolve("planar_2r")
    data = identified(mech)
    data["physical"].update(change)
    js = tmp_path / "bad.json"
    js.write_text(json.dumps(data))
    result = run("convert", "planar_2r", "--inertia", js, "-o", tmp_path / "x.toml", code=2)
    assert message in result.stderr


def test_inertia_json_missing_parameter(tmp_path):
    data = identified(resolve("planar_2r"))
    del data["physical"]["Iyz2"]
    js = tmp_path / "bad.json"
    js.write_text(json.dumps(data))
    result = run("convert", "planar_2r", "--inertia", js, "-o", tmp_path / "x.toml", code=2)
    assert "physical.Iyz2: missing" in result.stderr
    js.write_text("{not json")
    assert "not a JSON file" in run("convert", "planar_2r", "--inertia", js, "-o", tmp_path / "x.toml", code=2).stderr


# ----- solve --format csv ---------------------------------------------------------------------------
@pytest.mark.parametrize("mech, solver", [("planar_2r", "exact"), ("pendulum", "symbolic"),
                                          ("four_bar", "symbolic"),   # -1/L3: a negative expression
                                          (str(DATA / "ur5.urdf"), "dp")])
def test_solve_csv_one_row_per_base_parameter(mech, solver):
    result = run("solve", mech, "--solver", solver, "--format", "csv")
    rows = list(csv.reader(io.StringIO(result.stdout)))
    data = json.loads(run("solve", mech, "--solver", solver, "--format", "json").stdout)
    assert rows[0] == ["name", "expression"] and len(rows) - 1 == data["rank"]
    symbols = {p: sympy.Symbol(p) for p in data["parameters"]} | {g: sympy.Symbol(g) for g in data["geometry"]}
    for (name, text), base in zip(rows[1:], data["base"]):
        assert name == base["name"]
        parsed = sympy.sympify(text, locals=symbols)
        for param, coeff in base["expression"].items():        # every coefficient, every digit
            assert sympy.simplify(parsed.coeff(symbols[param]) - sympy.sympify(coeff, locals=symbols)) == 0


def test_convert_write_errors_are_bad_input_not_internal(tmp_path):
    result = CliRunner().invoke(main, ["convert", "pendulum", "-o", str(tmp_path / "missing" / "p.toml")])
    assert result.exit_code == 2 and "cannot write" in result.stderr
