"""The Python builder, the reader hook and resolve() by suffix.

The pendulum and the four-bar are built in Python and compared, field by field and by
their float64 observation matrices, with the same mechanisms read from their TOML files
(two independent routes to the same Mechanism: the TOML reader's table walk against
hand-written calls). The pendulum's parameters are also checked against the values its
file derives by hand (m1 = 1.2, mx1 = 0.3, Izz1 = m L^2/3 = 0.1).
"""

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from baseparams import registry
from baseparams.dynamics.trajectory import observation_matrix
from baseparams.dynamics.transfers import transfer_generators
from baseparams.errors import InputError
from baseparams.hookspecs import hookimpl
from baseparams.formats import Reader
from baseparams.io.loader import check_mobility, load_mechanism, parse_mechanism, readers_by_suffix, resolve
from baseparams.model import generate
from baseparams.model.builder import MechanismBuilder, name_problem
from baseparams.model.consistency import Verdict, check_body
from baseparams.model.params import from_mass_properties
from baseparams.model.mechanism import Frame, Mechanism
from baseparams.numeric.backends import Float64

T = sympy.Symbol("t")
STRUCTURE = ("name", "bodies", "joints", "tree", "loops", "coordinates", "independent",
             "geometry", "gravity", "trajectory", "gruebler")


def pendulum() -> Mechanism:
    """mechanisms/pendulum.toml, written as calls (sympy values, ints and strings mixed)."""
    b = MechanismBuilder("pendulum")
    L = b.geometry("L", "0.5")
    b.gravity([0, 0, "-9.81"])
    m = sympy.Rational(6, 5)
    b.body(1, "rod", mass=m, com=[L / 2, 0, 0],
           inertia_com=[Fraction(6, 100000), 0, 0, m * L**2 / 12, 0, "1.2*L**2/12"])
    b.joint("R", 0, 1, name="pivot", coordinates=["theta"],
            parent_frame=Frame(point=(0, 0, 0), axis=(0, -1, 0), ref=(0, 0, -1)),
            child_frame={"point": ["0", "0", "0"], "axis": ["0", "0", "1"], "ref": ["1", "0", "0"]})
    b.independent(["theta"])
    b.trajectory({"theta": sympy.Rational(4, 5) * sympy.sin(sympy.Rational(13, 10) * T)
                  + sympy.Rational(2, 5) * sympy.sin(sympy.Rational(31, 10) * T)},
                 t_start=0, t_end=10, samples=100)
    return b.build()


def bar(b, label, name, length, mass, ixx):
    """A uniform bar along body x, origin at one end (the four-bar file's bodies)."""
    b.body(label, name, mass=mass, com=[f"{length}/2", 0, 0],
           inertia_com=[ixx, 0, 0, f"{mass}*{length}**2/12", 0, f"{mass}*{length}**2/12"])


def four_bar(independent=True) -> Mechanism:
    """mechanisms/four_bar.toml, written as calls."""
    b = MechanismBuilder("four_bar")
    for name, value in (("L0", "0.4"), ("L1", "0.1"), ("L2", "0.36"), ("L3", "0.3")):
        b.geometry(name, value)
    bar(b, 1, "crank", "L1", "0.3", "0.000015")
    bar(b, 2, "coupler", "L2", "0.9", "0.000045")
    bar(b, 3, "rocker", "L3", "0.75", "0.0000375")
    body_frame = Frame(point=(0, 0, 0), axis=(0, 0, 1), ref=(1, 0, 0))
    b.joint("R", 0, 1, name="JA", coordinates=["q1"], child_frame=body_frame,
            parent_frame=Frame((0, 0, 0), (0, -1, 0), (1, 0, 0)))
    b.joint("R", 1, 2, name="JB", coordinates=["q2"], child_frame=body_frame,
            parent_frame=Frame(("L1", 0, 0), (0, 0, 1), ("0.6", "0.8", 0)))
    b.joint("R", 0, 3, name="JD", coordinates=["q3"], child_frame=body_frame,
            parent_frame=Frame(("L0", 0, 0), (0, -1, 0), ("-0.28", 0, "0.96")))
    b.joint("R", 2, 3, name="JC", coordinates=["q4"], loop=True,
            parent_frame=Frame(("L2", 0, 0), (0, 0, 1), ("0.6", "0.8", 0)),
            child_frame=Frame(("L3", 0, 0), (0, 0, 1), (1, 0, 0)))
    if independent:
        b.independent(["q1"])
    b.trajectory({"q1": "0.6*sin(2*t) + 0.2*sin(5*t)"}, t_start="0", t_end="10", samples=200)
    return b.build()


# ----- the same Mechanism as from the TOML files -------------------------------------------
@pytest.mark.parametrize("name, build", [("pendulum", pendulum), ("four_bar", four_bar)])
def test_python_build_equals_the_toml_file(name, build):
    built, read = build(), resolve(name)
    for field in STRUCTURE:
        assert getattr(built, field) == getattr(read, field), field
    assert built.parameters == read.parameters
    assert [j.limits for j in built.joints] == [j.limits for j in read.joints]
    assert built.path is None and read.path.endswith(f"{name}.toml")
    check_mobility(built)
    w_built, _ = observation_matrix(built, Float64())
    w_read, _ = observation_matrix(read, Float64())
    assert w_built.shape == w_read.shape and w_built.shape[1] == 10 * len(read.bodies)
    assert np.array_equal(w_built, w_read)


def test_pendulum_parameters_are_the_files_hand_values():
    p = dict(zip(pendulum().parameters, pendulum().body(1).inertia))
    assert (p["m1"], p["mx1"], p["my1"], p["Izz1"]) == (Fraction(6, 5), Fraction(3, 10), 0, Fraction(1, 10))
    assert all(isinstance(v, Fraction) for v in p.values())


def test_four_bar_loop_and_coordinates():
    mech = four_bar()
    assert [j.name for j in mech.loops] == ["JC"]
    assert mech.coordinates == ("q1", "q2", "q3") and mech.independent == ("q1",)
    assert mech.geometry["L2"] == Fraction(9, 25)


# ----- errors name the key -----------------------------------------------------------------
def expect(key, words, call):
    with pytest.raises(InputError) as info:
        call()
    assert info.value.key == key, info.value.message
    for word in words:
        assert word in info.value.reason


def test_errors_name_the_default_key_paths():
    b = MechanismBuilder("probe", path="probe.py")
    b.geometry("L", "0.5")
    b.body(1)
    frame = Frame((0, 0, 0))
    expect("mechanism.name", ["lower-case"], lambda: MechanismBuilder("Probe"))
    expect("geometry.M", ["binary float"], lambda: b.geometry("M", 0.5))
    expect("geometry.L", ["already used"], lambda: b.geometry("L", "1"))
    expect("bodies[1].mass", ["binary float"], lambda: b.body(2, mass=1.2, com=[0, 0, 0], inertia_com=[0] * 6))
    expect("bodies[1].label", ["duplicate body label 1"], lambda: b.body(1))
    expect("joints[0].type", ["unknown joint type 'Q'", "known:", "R"],
           lambda: b.joint("Q", 0, 1, parent_frame=frame, child_frame=frame))
    expect("joints[0].child", ["unknown body 5"], lambda: b.joint("R", 0, 5, parent_frame=frame, child_frame=frame))
    expect("joints[0].parent_frame.point[0]", ["unknown name 'Lx'", "geometry names: L"],
           lambda: b.joint("R", 0, 1, parent_frame=Frame(("Lx", 0, 0)), child_frame=frame))
    expect("joints[0].child_frame.axis", ["zero-length axis"],
           lambda: b.joint("R", 0, 1, parent_frame=frame, child_frame=Frame((0, 0, 0), (0, 0, 0))))
    expect("joints[0].parent_frame", ["required"], lambda: b.joint("R", 0, 1, child_frame=frame))
    expect("joints[0].parent_frame.point[1]", ["not a rational expression"],
           lambda: b.joint("R", 0, 1, parent_frame=Frame((0, sympy.sqrt(2), 0)), child_frame=frame))
    b.joint("R", 0, 1, name="pivot", parent_frame=frame, child_frame=frame)
    expect("joints[1].coordinates", ["'pivot' is already used"],
           lambda: b.joint("R", 1, 0, name="other", coordinates=["pivot"], parent_frame=frame, child_frame=frame))
    b.independent(["swing"])
    expect("coordinates.independent", ["'swing' is not a tree coordinate"], b.build)
    with pytest.raises(InputError) as info:
        b.build()
    assert info.value.message.startswith("probe.py: coordinates.independent: ")


def test_errors_name_the_key_path_a_reader_passes():
    b = MechanismBuilder("probe", path="robot.urdf")
    expect("robot/link[@name='arm']/inertial.mass", ["binary float"],
           lambda: b.body(1, mass=2.0, com=[0, 0, 0], inertia_com=[0] * 6, key="robot/link[@name='arm']/inertial"))
    b.body(1)
    b.body(2)
    frame = Frame((0, 0, 0))
    b.joint("R", 0, 1, parent_frame=frame, child_frame=frame, key="robot/joint[@name='j1']")
    expect("joints", ["body 2 is not connected to ground"], b.build)


def test_a_mechanism_with_loops_needs_independent_coordinates():
    mech = four_bar(independent=False)
    assert mech.independent == ()
    with pytest.raises(InputError, match="coordinates.independent: required for a mechanism with loops"):
        check_mobility(mech)


# ----- transfer rules are passed in, not looked up by the dynamics -------------------------
def test_transfer_generators_use_the_rules_they_are_given():
    mech = four_bar()
    gens, missing = transfer_generators(mech, registry.transfer_rules)
    assert gens and not missing
    asked = []
    none, missing = transfer_generators(mech, lambda name: asked.append(name))
    assert none == [] and list(missing) == list(mech.joints) and asked == ["R"] * 4


# ----- the reader hook -----------------------------------------------------------------------
class PendReader:
    """A toy format: ``.pend`` files, one ``key value`` a line (length, mass)."""

    name = "pend"
    suffixes = (".pend",)

    def read(self, path):
        path = Path(path)
        b = MechanismBuilder(path.stem, path)
        values = {}
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            key, _, value = line.partition(" ")
            if key not in ("length", "mass"):
                raise b.error(f"line {number}", f"unknown key {key!r}")
            values[key] = (value.strip(), f"line {number}")
        (length, length_key), (mass, mass_key) = values["length"], values["mass"]
        b.geometry("L", length, key=length_key)
        b.body(1, mass=mass, com=["L/2", 0, 0], inertia_com=[0] * 6, key=mass_key)
        b.joint("R", 0, 1, name="theta", parent_frame=Frame((0, 0, 0), (0, 1, 0)),
                child_frame=Frame((0, 0, 0), (0, 1, 0)))
        return b.build()


class PendPlugin:
    @hookimpl
    def baseparams_readers(self):
        return [PendReader()]


class TomlClaimer:
    @hookimpl
    def baseparams_readers(self):
        return [type("Claimer", (), {"name": "claimer", "suffixes": (".TOML",), "read": None})()]


def test_the_toml_reader_is_a_builtin_plugin():
    readers = registry.readers()
    assert readers["toml"].distribution == "baseparams"
    assert readers_by_suffix()[".toml"] is readers["toml"].item


def test_a_reader_registered_at_run_time_is_used_by_suffix(registered, tmp_path):
    path = tmp_path / "toy.pend"
    path.write_text("length 0.8\nmass 2\n")
    with pytest.raises(InputError, match=r"no reader for files ending in '\.pend' \(known: [^)]*\.toml"):
        resolve(str(path))
    registered(PendPlugin())
    assert registry.readers()["pend"].distribution == "(registered at run time)"
    mech = resolve(str(path))
    assert mech.name == "toy" and mech.path == str(path) and mech.coordinates == ("theta",)
    assert mech.geometry == {"L": Fraction(4, 5)}
    assert mech.body(1).inertia[:2] == (2, Fraction(4, 5))          # m1, mx1 = m L/2
    assert load_mechanism(path).body(1).inertia == mech.body(1).inertia
    path.write_text("length 0.8\ncolour red\n")
    with pytest.raises(InputError) as info:
        resolve(str(path))
    assert info.value.message == f"{path}: line 2: unknown key 'colour'"


def test_a_reader_with_only_read_is_completed_to_the_reader_protocol(registered, tmp_path):
    """The hook's minimum (name, suffixes, read) reaches every caller as a full Reader."""
    registered(PendPlugin())
    reader = registry.readers()["pend"].item
    assert isinstance(reader, Reader) and reader.options == () and reader.suffixes == (".pend",)
    assert registry.readers()["toml"].item.options == ()
    path = tmp_path / "toy.pend"
    path.write_text("length 0.8\nmass 2\n")
    mech, notes = reader.read_notes(path)
    assert notes == [] and mech.geometry == {"L": Fraction(4, 5)}


class EffectsWrapper:
    """A hook wrapper on the effects hook: it sees every answer the registry collects."""

    def __init__(self):
        self.seen = []

    @hookimpl(wrapper=True)
    def baseparams_effects(self):
        answers = yield
        self.seen += [effect.name for answer in answers for effect in answer]
        return answers


def test_the_registry_calls_hooks_through_pluggy_so_wrappers_apply(registered):
    wrapper = EffectsWrapper()
    registered(wrapper)
    effects = registry.effects()
    assert sorted(wrapper.seen) == sorted(effects) and "viscous_friction" in effects
    assert {reg.distribution for reg in effects.values()} == {"baseparams"}      # the wrapper answers nothing


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"no reader for files ending in '\.sdf' \(known: [^)]*\.toml"):
        resolve("model.sdf")
    with pytest.raises(InputError) as info:
        resolve(str(tmp_path / "absent.toml"))
    assert info.value.reason == "no such file"


def test_two_readers_may_not_claim_one_suffix(registered):
    registered(TomlClaimer())
    with pytest.raises(InputError, match=r"'\.toml' is claimed by two readers"):
        resolve("pendulum.toml")


# ----- physical consistency, names, warnings (issue 13) ------------------------------

def _physical_by_eigenvalues(params) -> bool:
    """Independent oracle: the principal moments at the COM are >= 0 and satisfy the triangle
    inequalities (float eigenvalues with a tolerance; cases near the boundary are skipped)."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in params)
    c = np.array([mx, my, mz]) / m
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    at_com = tensor - m * (c @ c * np.eye(3) - np.outer(c, c))
    lam = np.linalg.eigvalsh(at_com)
    return bool(lam.min() >= 0 and all(lam[i] + lam[j] >= lam[k] for i, j, k in ((0, 1, 2), (0, 2, 1), (1, 2, 0))))


def _margin(params) -> float:
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in params)
    c = np.array([mx, my, mz]) / m
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    lam = np.linalg.eigvalsh(tensor - m * (c @ c * np.eye(3) - np.outer(c, c)))
    return min(lam.min(), lam[0] + lam[1] - lam[2])


SMALL = st.integers(-40, 40).map(lambda n: Fraction(n, 10))


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(st.integers(1, 30).map(lambda n: Fraction(n, 10)), st.tuples(*[SMALL] * 9))
def test_exact_consistency_agrees_with_eigenvalues(mass, rest):
    params = (mass,) + rest
    assume(abs(_margin(params)) > 1e-9)
    assert (check_body(params).error is None) == _physical_by_eigenvalues(params)


def test_consistency_of_point_masses_and_rods_is_exact():
    """A point mass and a thin rod sit exactly on the boundary (zero principal moments,
    equality in the triangle inequality) and are physical; just past it they are not."""
    rod = from_mass_properties(Fraction(2), (Fraction(1), 0, 0), (0, 0, 0, Fraction(1, 6), 0, Fraction(1, 6)))
    assert check_body(from_mass_properties(Fraction(3), (1, 2, 3), (0,) * 6)) == Verdict()
    assert check_body(rod) == Verdict()
    past = from_mass_properties(Fraction(2), (Fraction(1), 0, 0),
                                (Fraction(-1, 10 ** 12), 0, 0, Fraction(1, 6), 0, Fraction(1, 6)))
    assert "not positive semi-definite" in check_body(past).error
    assert "negative mass" in check_body((Fraction(-1),) + (Fraction(0),) * 9).error
    assert "without mass" in check_body((0, 1, 0, 0, 0, 0, 0, 0, 0, 0)).error
    assert "zero mass" in check_body((0, 0, 0, 0, 0, 0, 0, 0, 0, Fraction(7, 20))).warning


@pytest.mark.parametrize("seed", range(6))
def test_generated_mechanisms_are_physical_without_warnings(seed):
    for text in (generate.serial_chain(seed), generate.tree(seed), generate.four_bar(seed)):
        assert parse_mechanism(text).warnings == ()


@pytest.mark.parametrize("name, words", [
    ("m2", "inertial parameter"), ("Izz12", "inertial parameter"), ("t", "reserved"), ("pi", "reserved"),
    ("lambda", "reserved"), ("nan", "reserved"), ("E", "sympy"), ("I", "sympy"), ("gamma", "sympy"),
    ("2L", "not an identifier"), ("L\u00e9", "not an identifier"), ("", "not an identifier"),
])
def test_unusable_names(name, words):
    assert words in name_problem(name)
    b = MechanismBuilder("probe")
    with pytest.raises(InputError, match=words):
        b.geometry(name, "1")


@pytest.mark.parametrize("name", ["L", "D12", "m", "mass2", "Ixx", "theta", "q1", "alpha", "x_1"])
def test_usable_names(name):
    assert name_problem(name) is None


def test_builder_warnings_reach_the_mechanism():
    b = MechanismBuilder("rotor")
    b.body(1, "rotor", mass=0, com=[0, 0, 0], inertia_com=[0, 0, 0, 0, 0, "0.35"])
    b.joint("R", 0, 1, parent_frame={"point": [0, 0, 0]}, child_frame={"point": [0, 0, 0]})
    mech = b.build()
    assert len(mech.warnings) == 1 and "bodies[0].inertia_com: body 1 (rotor): zero mass" in mech.warnings[0]


def test_a_tiny_or_huge_axis_is_the_same_direction():
    """An axis of (1e-300, 0, 0) or (1e200, 0, 0) gives the W of (1, 0, 0), to rounding: the
    direction is rescaled by an exact power of two before double precision sees it (its
    square would otherwise underflow to zero or overflow)."""
    def build(axis):
        b = MechanismBuilder("axis")
        b.body(1, mass="1.5", com=["0.2", "0.1", 0], inertia_com=["0.1", 0, 0, "0.2", 0, "0.25"])
        b.joint("R", 0, 1, name="q", parent_frame={"point": [0, 0, 0], "axis": axis},
                child_frame={"point": [0, 0, 0]})
        b.trajectory({"q": "sin(t)"}, samples=20)
        return b.build()
    reference, _ = observation_matrix(build(["1", "0", "0"]), Float64())
    for axis in (["1e-300", "0", "0"], ["1e200", "0", "0"]):
        w, _ = observation_matrix(build(axis), Float64())
        assert np.all(np.isfinite(w)) and np.allclose(w, reference, rtol=1e-14, atol=1e-14)
