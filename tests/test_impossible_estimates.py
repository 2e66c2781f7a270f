"""Estimates no robot has (issue 42, part 3): `identify` names a negative friction or rotor
inertia, a base parameter that must be positive (a mass, a moment of inertia) and comes out
negative, a body that is no mass distribution, each with its value and std; `diagnose
--params` says which held values are such before it runs, and runs on a URDF whose
inertias are not physical (issue 48) instead of refusing it. Why: on a real arm identify
returned a viscous friction of -0.18 and on the Panda negative rotor inertias, said
nothing, and diagnose then "corrected" them as if they were physical."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.identify.impossible import IMPOSSIBLE_STD, judge, nonnegative_on_bodies, pseudo_inertia

from test_urdf_inertia import BAD_ARM


def run(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code in (0, 1), (args, result.stdout, result.stderr)
    return result


def simulated(tmp_path, mech, *effects, noise="0.02", seed=1):
    path = tmp_path / f"{Path(mech).name.replace('.', '_')}_{seed}.csv"
    run("simulate", mech, "-o", path, "--noise", noise, "--seed", seed, *[a for e in effects for a in ("--effect", e)])
    return path


def identified(mech, data, *effects, out=None):
    result = run("identify", mech, data, "--format", "json", *[a for e in effects for a in ("--effect", e)],
                 *(["-o", out] if out else []))
    return json.loads(out.read_text() if out else result.stdout)


def test_a_negative_viscous_friction_in_the_data_is_named_with_its_value_and_std(tmp_path):
    """A viscous friction of -0.2 hidden in the data: identified at -0.2 with a std far
    smaller, flagged impossible; the other joint's friction (truth 0) is not impossible."""
    data = simulated(tmp_path, "planar_2r", "viscous_friction:q1=-0.2", "coulomb_friction:q2=0.3")
    report = identified("planar_2r", data, "viscous_friction:*", "coulomb_friction:*")
    flags = {f["name"]: f for f in report["impossible"]}
    assert list(flags) == ["fv_q1"]
    fv = flags["fv_q1"]
    assert abs(fv["value"] + 0.2) < 5 * fv["std"] and fv["std"] > 0
    assert fv["std_below_zero"] == pytest.approx(-fv["value"] / fv["std"]) and fv["std_below_zero"] > IMPOSSIBLE_STD
    assert "viscous friction must be positive" in fv["reason"]
    assert all(f["name"] != "fv_q1" and f["std_below_zero"] <= IMPOSSIBLE_STD for f in report["consistent_with_zero"])
    text = run("identify", "planar_2r", data, "--effect", "viscous_friction:*", "--effect", "coulomb_friction:*").stdout
    line = next(l for l in text.splitlines() if l.strip().startswith("fv_q1 =") and "std below 0" in l)
    assert "IMPOSSIBLE" in text and "viscous friction must be positive" in line
    assert "--physical does not constrain effect coefficients" in text


def test_a_negative_rotor_inertia_is_named(tmp_path):
    """The Panda's case: a rotor inertia that comes out negative (here hidden as such)."""
    data = simulated(tmp_path, "planar_2r", "rotor_inertia:q2=-0.05", seed=4)
    report = identified("planar_2r", data, "rotor_inertia:q2")
    flags = {f["name"]: f for f in report["impossible"]}
    assert "Ia_q2" in flags and abs(flags["Ia_q2"]["value"] + 0.05) < 5 * flags["Ia_q2"]["std"]
    assert "rotor inertia must be positive" in flags["Ia_q2"]["reason"]


def test_a_base_parameter_that_must_be_positive_is_judged_with_what_is_absorbed_into_it(tmp_path):
    """The SCARA's phi_b01 = Izz1 + 0.105625 m2 is >= 0 for every physical body; a rotor
    inertia of -2 on q1 (the same column) makes it about -1.1: impossible. Identified with
    the rotor inertia, Ia_q1 is absorbed into it (a positive coefficient with factor 1): the
    sum must still be positive. First moments and Ixx - Iyy are never judged."""
    data = simulated(tmp_path, "scara", "rotor_inertia:q1=-2", seed=2)
    for effects in ((), ("rotor_inertia:q1",)):
        report = identified("scara", data, *effects)
        flags = {f["name"]: f for f in report["impossible"]}
        assert list(flags) == ["phi_b01"], effects
        assert "Izz1" in flags["phi_b01"]["reason"] and flags["phi_b01"]["value"] < -1
        assert ("Ia_q1 absorbed" in flags["phi_b01"]["reason"]) == bool(effects)


def test_a_clean_fit_flags_nothing(tmp_path):
    data = simulated(tmp_path, "planar_2r", "viscous_friction:q1=0.2", "viscous_friction:q2=0.1",
                     "coulomb_friction:q1=0.3", "coulomb_friction:q2=0.2", seed=5)
    report = identified("planar_2r", data, "viscous_friction:*", "coulomb_friction:*")
    assert report["impossible"] == [] and report["consistent_with_zero"] == []
    text = run("identify", "planar_2r", data, "--effect", "viscous_friction:*", "--effect", "coulomb_friction:*").stdout
    assert "IMPOSSIBLE" not in text and "consistent with zero" not in text


def test_diagnose_names_the_impossible_values_it_holds(tmp_path):
    """An identify result with a negative friction held by diagnose --params: the first
    note names it with value and std, before the diagnosis; it still runs."""
    data = simulated(tmp_path, "planar_2r", "viscous_friction:q1=-0.2", "coulomb_friction:q2=0.3")
    fit = tmp_path / "fit.json"
    identified("planar_2r", data, "viscous_friction:*", "coulomb_friction:*", out=fit)
    report = json.loads(run("diagnose", "planar_2r", data, "--params", fit, "--format", "json").stdout)
    first = report["notes"][0]
    assert "--params" in first and "no robot has" in first and "fv_q1 = -0.2" in first and "+-" in first
    assert "viscous friction must be positive" in first
    text = run("diagnose", "planar_2r", data, "--params", fit).stdout        # the short report says it too
    assert any(line.startswith("note: --params") and "fv_q1 = -0.2" in line for line in text.splitlines()), text
    # a result of an older version (no "impossible" key) is judged from its values alike
    older = json.loads(fit.read_text())
    del older["impossible"], older["consistent_with_zero"]
    fit.write_text(json.dumps(older))
    report = json.loads(run("diagnose", "planar_2r", data, "--params", fit, "--format", "json").stdout)
    assert "fv_q1 = -0.2" in report["notes"][0]


def test_diagnose_runs_on_a_urdf_whose_inertias_are_not_physical(tmp_path):
    """Issue 48: a CAD URDF whose inertia breaks the triangle inequality (and one not
    positive definite) is the user's model: held as given with a note naming the bodies."""
    urdf = tmp_path / "bad_arm.urdf"
    urdf.write_text(BAD_ARM)
    data = tmp_path / "bad.csv"
    run("simulate", urdf, "--random-inertia", "-o", data, "--noise", "0.01", "--seed", 3)
    result = run("diagnose", urdf, data, "--params", urdf, "--format", "json")
    note = json.loads(result.stdout)["notes"][0]
    assert "not physical" in note and "held as given" in note
    assert "sensor_mount" in note and "triangle inequality" in note and "upper" in note


def test_what_is_claimed_about_base_parameters():
    """A base parameter is judged only when it is >= 0 for every physical body (its dual
    matrix on each body is positive semidefinite): a mass, a moment of inertia, Izz1 + a m2;
    not a first moment, not Ixx - Iyy."""
    e = np.eye(20)
    assert nonnegative_on_bodies(e[0]) and nonnegative_on_bodies(e[9]) and nonnegative_on_bodies(e[9] + 0.1 * e[10])
    assert not nonnegative_on_bodies(e[1]) and not nonnegative_on_bodies(e[4] - e[7])
    assert not nonnegative_on_bodies(e[9] - 0.1 * e[10]) and not nonnegative_on_bodies(e[5])


def test_a_body_determined_by_the_data_is_judged_as_a_mass_distribution():
    """Where the base parameters on one body determine all ten of its parameters, its
    pseudo-inertia's smallest eigenvalue is judged with its std; where they determine fewer,
    nothing is claimed. The body: 1 kg with principal moments 0.001, 0.001, 0.01 at its
    centre of mass (the triangle inequality broken, every diagonal entry positive)."""
    phi = np.array([1, 0, 0, 0, 0.001, 0, 0, 0.001, 0, 0.01])
    assert np.linalg.eigvalsh(pseudo_inertia(phi))[0] < 0
    parameters = [f"{k}1" for k in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")]
    names = [f"phi_b{k:02d}" for k in range(10)]
    common = dict(parameters=parameters, names=names, values=phi, effects={}, absorbed={}, bodies={1: "link"})
    flags = judge(base_map=np.eye(10), std=np.full(10, 1e-5), covariance=np.eye(10) * 1e-10, **common)
    assert [f.name for f in flags] == ["body 1 (link)"] and flags[0].impossible
    assert "not a mass distribution" in flags[0].reason
    noisy = judge(base_map=np.eye(10), std=np.full(10, 1e-2), covariance=np.eye(10) * 1e-4, **common)
    assert [f.name for f in noisy] == ["body 1 (link)"] and not noisy[0].impossible     # within its noise
    fewer = judge(base_map=np.eye(10)[:9], std=np.full(9, 1e-5), covariance=np.eye(9) * 1e-10,
                  **{**common, "names": names[:9], "values": phi[:9]})
    assert fewer == []


def test_body_scales_are_a_hundred_times_the_mechanisms_mass_and_reach():
    """S_i: 100 M for a mass, 100 M L for a first moment, 100 M L^2 for an inertia (M the bodies'
    total mass, L the frames' lengths added up, at least 1 m); a base parameter is beyond
    its scale when |value| or std exceeds sum |c_i| S_i."""
    from baseparams.identify.impossible import beyond_body_scale, body_scales
    S = body_scales(["m_a", "mx_a", "Izz_a", "m_b"], [2.0, 3.0], [1.5, 0.5, 1.0])
    assert np.allclose(S, [500.0, 1500.0, 4500.0, 500.0])
    assert body_scales(["m_a"], [0.0], [1.0]) is None            # no masses: nothing to scale by
    assert np.allclose(body_scales(["mx_a"], [1.0], [0.1]), [100.0])     # the reach is at least 1 m
    E = np.array([[0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 1.0, 0.0]])    # mx_a + 0.5 m_b, Izz_a: bounds 1750, 4500
    names = ["b1", "b2", "fv_q1"]
    flags = beyond_body_scale(["b1", "b2"], E, names, np.array([1800.0, 10.0, 1e9]), np.array([1.0, 4600.0, 1.0]), S)
    assert [(f.name, f.beyond) for f in flags] == [("b1", 1750.0), ("b2", 4500.0)]
    assert "its value" in flags[0].reason and "its standard deviation" in flags[1].reason
    assert beyond_body_scale(["b1", "b2"], E, names, np.array([1700.0, 10.0, 0.0]), np.ones(3), S) == []


def test_a_real_first_link_seen_through_a_sliver_of_its_axis_is_beyond_any_physical_scale(tmp_path):
    """The real Kinova repeat's first run (tests/data/kinova_gen3): the first link's first
    moments are seen only through its axis 3.7e-6 rad off vertical (rpy 1.5708 for pi/2), and
    the fit returns mx_shoulder_link = -7.2e4 kg m for an arm of about 8 kg. identify names it
    (JSON, text, a warning), and diagnose --params says so before it runs."""
    folder = Path(__file__).parent / "data" / "kinova_gen3"
    urdf, first = folder / "gen3.urdf", folder / "repeat_RunTrajectory1.toml"
    out = tmp_path / "first.json"
    report = identified(urdf, first, out=out)
    far = {f["name"]: f for f in report["beyond_physical_scale"]}
    assert "phi_b01" in far and abs(far["phi_b01"]["value"]) > 1e4, report["beyond_physical_scale"]
    assert all(name in ("phi_b01", "phi_b02") for name in far)          # the rest is within the scale
    result = run("identify", urdf, first)
    assert "BEYOND ANY PHYSICAL SCALE" in result.stdout and "phi_b01" in result.stderr
    report = json.loads(run("diagnose", urdf, folder / "repeat_Trajectory1.toml", "--params", out,
                            "--format", "json").stdout)
    assert any("beyond any physical scale" in n and "phi_b01" in n for n in report["notes"]), report["notes"]


def test_a_clean_fit_is_within_the_physical_scale(tmp_path):
    """A simulated UR5 (its URDF's masses) and the real TX40 (tests/data/tx40) identified: no
    base parameter beyond the mechanism's scale (the built-in mechanisms carry no masses:
    nothing is judged there)."""
    from baseparams.identify.impossible import mechanism_scales
    from baseparams.io.loader import resolve
    data = Path(__file__).parent / "data"
    ur5, tx40 = data / "urdf" / "ur5.urdf", data / "tx40" / "tx40_mdh_modified.urdf"
    for mech, recording in ((ur5, simulated(tmp_path, str(ur5), seed=3)), (tx40, data / "tx40" / "recording.toml")):
        mechanism = resolve(str(mech))
        assert mechanism_scales(mechanism, mechanism.parameters) is not None
        report = identified(mech, recording)
        assert report["beyond_physical_scale"] == [], (mech, report["beyond_physical_scale"])
    planar = resolve("planar_2r")
    assert mechanism_scales(planar, planar.parameters) is None
