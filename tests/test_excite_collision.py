"""excite, issue 43: plans a real robot can run. The collision scene against independent
computations (Pinocchio's own placements of the mesh vertices, central differences, dense
sampling between samples); the output by suffix; --check; progress; never worse than the
start. The slow tests are the issue's acceptance: the UR5 (example-robot-data, its SRDF)
and the TX40 default plans checked by Pinocchio + coal on the original meshes at ten times
finer sampling, independently of the optimiser."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.dynamics.forces import independent_names
from baseparams.dynamics.trajectory import values_at
from baseparams.io.loader import load_mechanism
from baseparams.numeric.backends import Float64

DATA = Path(__file__).parent / "data"
UR5_PLAIN = DATA / "urdf" / "ur5.urdf"                   # no <collision>: the skeleton and the floor only
TX40 = DATA / "tx40" / "tx40_mdh_modified.urdf"


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _robots() -> Path:
    pinocchio = pytest.importorskip("pinocchio")
    pytest.importorskip("coal")
    robots = Path(pinocchio.__file__).parents[4] / "share" / "example-robot-data" / "robots"
    if not (robots / "ur_description" / "urdf" / "ur5_robot.urdf").is_file():
        pytest.skip("example-robot-data's UR5 is not installed (pip install pin ships it)")
    return robots


def _ur5():
    robots = _robots()
    return (robots / "ur_description" / "urdf" / "ur5_robot.urdf",
            robots / "ur_description" / "srdf" / "ur5.srdf")


def _scene(urdf, srdf=None, **spec):
    from baseparams.excite.collision import SceneSpec, build
    mechanism = load_mechanism(urdf)
    names = independent_names(mechanism)
    return build(SceneSpec(str(urdf), None if srdf is None else str(srdf), **spec), mechanism, names,
                 np.zeros(len(names))), names


def _written_motion(path, t):
    mechanism = load_mechanism(path)
    values = [values_at(mechanism.trajectory.expressions[n], Float64(), t) for n in mechanism.independent]
    return [np.stack([np.broadcast_to(np.asarray(v[k], float), t.shape) for v in values], axis=1) for k in range(3)]


# ----- the scene against independent computations -------------------------------------------------
def test_floor_distance_is_the_lowest_mesh_vertex_by_pinocchios_own_placements():
    """A hull's lowest point is a vertex of its mesh: the scene's height above the floor of
    every moving link equals the lowest of the original mesh's vertices placed by Pinocchio."""
    import pinocchio as pin
    urdf, srdf = _ur5()
    scene, names = _scene(urdf, srdf)
    model = pin.buildModelFromUrdf(str(urdf))
    from baseparams.excite.collision import package_dirs
    geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, package_dirs=list(package_dirs(str(urdf))))
    data, gdata = model.createData(), pin.GeometryData(geometry)
    rng = np.random.default_rng(3)
    pairs = len(scene.pair_names)
    for q in rng.uniform(-3, 3, (5, 6)):
        at, _, labels = scene.distances(q[None])
        pin.updateGeometryPlacements(model, data, geometry, gdata, q)
        for k, (p, g) in enumerate(scene.plane_items):
            name = scene.geometry.geometryObjects[g].name
            obj = geometry.getGeometryId(name)
            shape = geometry.geometryObjects[obj].geometry
            if not hasattr(shape, "vertices"):
                continue
            placed = np.asarray(shape.vertices()) @ gdata.oMg[obj].rotation.T + gdata.oMg[obj].translation
            assert at[0, pairs + k] == pytest.approx(placed[:, 2].min(), abs=1e-9), name


def test_distance_gradients_equal_central_differences():
    urdf, srdf = _ur5()
    scene, names = _scene(urdf, srdf)
    rng = np.random.default_rng(5)
    checked = 0
    for q in rng.uniform(-2.5, 2.5, (40, 6)):
        at, grad, _ = scene.distances(q[None], gradient=True)
        if np.min(at) < 0.01:                       # penetration depths: EPA's, not differentiated here
            continue
        numeric = []
        for i in range(6):
            e = np.zeros(6)
            e[i] = 1e-6
            plus = np.min(scene.distances((q + e)[None])[0] - scene.required)
            minus = np.min(scene.distances((q - e)[None])[0] - scene.required)
            numeric.append((plus - minus) / 2e-6)
        np.testing.assert_allclose(grad[0], numeric, atol=2e-5)
        checked += 1
    assert checked >= 5


def test_the_bound_between_samples_holds_on_dense_sampling():
    """Per interval of a coarse grid the guaranteed distance is below every distance sampled
    densely inside it (the bound is a bound, not an estimate)."""
    from baseparams.excite.collision import guaranteed
    from baseparams.excite.fourier import FourierForm
    urdf, srdf = _ur5()
    scene, names = _scene(urdf, srdf)
    form = FourierForm(tuple(names), 3, 6.0)
    coefficients = np.zeros((6, 7))
    coefficients[:, 0] = [0.0, -1.6, 1.2, -1.2, -1.5, 0.0]
    coefficients[:, 1:] = np.random.default_rng(2).normal(0, 0.25, (6, 6))
    x = form.variables(coefficients)
    t = np.linspace(0, 6, 31)
    q, qd, qdd = form.motion(x, t)
    at, _, low = guaranteed(scene, t, q, qd, qdd)
    for k in range(len(t) - 1):
        inside = np.linspace(t[k], t[k + 1], 41)
        dense = scene.distances(form.motion(x, inside)[0])[0]
        assert np.all(low[k] <= dense.min(axis=0) + 1e-9)
    at2, _, refined = guaranteed(scene, t, q, qd, qdd, lambda times: form.motion(x, times))
    assert np.all(refined >= low - 1e-12) or np.all(refined <= at[:-1] + 1e-12)


def test_no_collision_geometry_is_said_and_the_frames_keep_off_the_floor():
    pytest.importorskip("pinocchio")
    scene, names = _scene(TX40)
    assert not scene.self_checked and not scene.pair_names
    assert any("no collision geometry" in n for n in scene.notes)
    assert scene.plane_items                                  # the frames' origins against the floor


def test_box_distance_is_the_point_to_box_distance_of_each_frame_origin():
    """TX40 (no meshes): its links are their frames' origins; coal's distance to a keep-out box
    equals the analytic distance from Pinocchio's placed origin to the box."""
    import pinocchio as pin
    from baseparams.excite.collision import parse_keep_out
    planes, boxes = parse_keep_out(["box:0.3,0.1,0.2,0.1,0.2,0.05"], floor=False)
    scene, names = _scene(TX40, planes=planes, boxes=boxes)
    model = pin.buildModelFromUrdf(str(TX40))
    data = model.createData()
    centre, half = np.array([0.3, 0.1, 0.2]), np.array([0.1, 0.2, 0.05])
    rng = np.random.default_rng(11)
    for q in rng.uniform(-1.5, 1.5, (4, 6)):
        at, _, labels = scene.distances(q[None])
        pin.framesForwardKinematics(model, data, q)
        for k, (a, b) in enumerate(scene.pair_names):
            frame = model.getFrameId(a.removesuffix(" (origin)"))
            p = data.oMf[frame].translation
            outside = np.maximum(np.abs(p - centre) - half, 0)
            expected = np.linalg.norm(outside) if np.any(outside > 0) else -np.min(half - np.abs(p - centre))
            assert at[0, k] == pytest.approx(expected, abs=1e-6), (a, b)
    assert len(scene.pair_names) >= 10


def test_collision_required_but_unavailable_is_an_input_error(monkeypatch):
    from baseparams.api.planning import scene_spec
    from baseparams.errors import InputError
    from baseparams.excite import collision
    monkeypatch.setattr(collision, "available", lambda: "collision checking needs Pinocchio and coal")
    mechanism = load_mechanism(TX40)
    options = dict(collision_model=None, srdf=None, package_dirs=(), clearance=0.02, keep_out=(), floor=True)
    with pytest.raises(InputError, match="Pinocchio"):
        scene_spec(mechanism, collision=True, notes=[], **options)
    notes: list[str] = []
    assert scene_spec(mechanism, collision=None, notes=notes, **options) is None
    assert any("not checked" in n for n in notes)


def test_the_srdf_beside_the_urdf_is_found():
    from baseparams.excite.collision import find_srdf
    urdf, srdf = _ur5()
    assert find_srdf(str(urdf)) == str(srdf)
    assert find_srdf(str(TX40)) is None


def test_keep_out_and_options_errors_are_exit_2(tmp_path):
    cases = [("--keep-out", "plane:0,0,0,1"), ("--keep-out", "box:0,0,0,1,-1,1"), ("--keep-out", "cube:1"),
             ("--srdf", tmp_path / "missing.srdf"), ("-o", tmp_path / "plan.txt")]
    for option, value in cases:
        result = _run("excite", UR5_PLAIN, option, value, "--iterations", "2", "--quiet")
        assert result.exit_code == 2, (option, value, result.output, result.stderr)
        assert "error:" in result.stderr and "Traceback" not in result.stderr + result.output
    assert not (tmp_path / "plan.txt").exists()


# ----- output, check, progress ---------------------------------------------------------------------
QUICK = ("--harmonics", "2", "--samples", "20", "--iterations", "15", "--starts", "1", "--quiet")


def test_csv_output_then_identify_on_torques_along_it(tmp_path):
    """-o plan.csv writes the motion; Pinocchio's inverse dynamics along it (a stand-in for the
    robot) added as tau_ columns, identify reads it and reports the plan's condition number."""
    pin = pytest.importorskip("pinocchio")
    plan, report = tmp_path / "plan.csv", tmp_path / "r.json"
    result = _run("excite", UR5_PLAIN, "-o", plan, "--rate", "20", "--report", report, *QUICK)
    assert result.exit_code == 0, result.output + result.stderr
    assert "[trajectory]" not in result.stdout and result.stdout.startswith("ur5:")      # the report, no TOML
    rows = list(csv.DictReader(plan.open()))
    names = independent_names(load_mechanism(UR5_PLAIN))
    model = pin.buildModelFromUrdf(str(UR5_PLAIN))
    data = model.createData()
    with_tau = tmp_path / "data.csv"
    with with_tau.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(list(rows[0]) + [f"tau_{n}" for n in names])
        for row in rows:
            q, qd, qdd = (np.array([float(row[f"{k}_{n}"]) for n in names]) for k in ("q", "qd", "qdd"))
            writer.writerow(list(row.values()) + list(pin.rnea(model, data, q, qd, qdd)))
    identified = _run("identify", UR5_PLAIN, with_tau, "--format", "json", "--quiet")
    assert identified.exit_code == 0, identified.output + identified.stderr
    figure = json.loads(identified.stdout)["condition_number"]
    planned = json.loads(report.read_text())
    assert planned["improved"] and planned["solver"] == "vp"
    assert figure == pytest.approx(planned["verified"]["condition_number"], rel=0.05)


def test_check_reports_a_plan_and_refuses_one_too_fast(tmp_path):
    plan = tmp_path / "plan.csv"
    assert _run("excite", UR5_PLAIN, "-o", plan, "--rate", "20", *QUICK).exit_code == 0
    good = _run("excite", UR5_PLAIN, "--check", plan, "--format", "json", "--quiet")
    assert good.exit_code == 0, good.output + good.stderr
    data = json.loads(good.stdout)
    assert data["ok"] and data["samples"] > 100 and data["condition_number"] > 1
    fast = tmp_path / "fast.csv"
    rows = list(csv.reader(plan.open()))
    header = rows[0]
    with fast.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for row in rows[1:]:
            writer.writerow([str(float(v) * (10 if h.startswith("qd_") else 1)) for h, v in zip(header, row)])
    bad = _run("excite", UR5_PLAIN, "--check", fast, "--format", "json", "--quiet")
    assert bad.exit_code == 1
    assert json.loads(bad.stdout)["margins"]["velocity"] < 0
    written = tmp_path / "plan.toml"
    assert _run("excite", UR5_PLAIN, "-o", written, *QUICK).exit_code in (0, 1)
    again = _run("excite", UR5_PLAIN, "--check", written, "--format", "json", "--quiet")
    assert again.exit_code == 0 and json.loads(again.stdout)["samples"] == 10 * (20 - 1) + 1
    broken = tmp_path / "broken.csv"
    broken.write_text("t,q_nothing\n0,1\n1,2\n")
    refused = _run("excite", UR5_PLAIN, "--check", broken, "--quiet")
    assert refused.exit_code == 2 and "q_shoulder_pan_joint" in refused.stderr


def test_api_progress_within_a_start_is_opt_in(tmp_path):
    import baseparams as bp
    messages: list[str] = []
    bp.excite(UR5_PLAIN, harmonics=2, samples=20, iterations=12, starts=1, say=messages.append)
    assert any("iteration 1/12" in m for m in messages) and any("iteration 10/12" in m for m in messages)


def test_never_worse_than_the_file_s_trajectory(tmp_path):
    """A file whose trajectory is already a good plan, planned again with two harmonics and two
    iterations: the new motion is worse, so the file's own is returned unchanged, exit 1."""
    from baseparams.model import generate
    chain, good, again, report = (tmp_path / n for n in ("chain.toml", "good.toml", "again.toml", "r.json"))
    chain.write_text(generate.serial_chain(2, bodies=3))
    first = _run("excite", chain, "-o", good, "--harmonics", "4", "--iterations", "80", "--starts", "1",
                 "--max-velocity", "2", "--quiet")
    assert first.exit_code == 0, first.stderr
    result = _run("excite", good, "-o", again, "--harmonics", "2", "--iterations", "2", "--starts", "1",
                  "--max-velocity", "2", "--report", report, "--quiet")
    data = json.loads(report.read_text())
    assert result.exit_code == 1 and "returned" in result.stderr, result.stderr
    assert not data["improved"] and data["kept"] == "the file's trajectory"
    assert data["after"]["criterion"] >= data["before"]["criterion"]
    assert load_mechanism(again).trajectory.expressions == load_mechanism(good).trajectory.expressions


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["vp", "dp", "symbolic"])
def test_closed_loops_never_worse_than_their_start_with_every_solver(tmp_path, solver):
    for mech in ("four_bar", "sla_suspension"):
        report = tmp_path / f"{mech}.json"
        result = _run("excite", mech, "--solver", solver, "--report", report, "--starts", "1", "--iterations", "60",
                      "--quiet")
        assert result.exit_code in (0, 1), result.stderr
        data = json.loads(report.read_text())
        returned = data["before"] if data["kept"] else data["after"]
        assert returned["criterion"] <= data["before"]["criterion"] + 1e-12
        assert (result.exit_code == 0) == data["improved"]


# ----- the acceptance (slow) ---------------------------------------------------------------
def _independent_checks(written, urdf, srdf, limits_urdf):
    """On ten times the written file's samples, with Pinocchio + coal on the original meshes:
    no self-collision (SRDF pairs removed), no link below the base plane, every URDF limit."""
    import pinocchio as pin
    from baseparams.excite.collision import package_dirs
    mechanism = load_mechanism(written)
    spec = mechanism.trajectory
    t = np.linspace(0, float(spec.t_end), 10 * (spec.samples - 1) + 1)
    q, qd, qdd = _written_motion(written, t)
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    order = [model.getJointId(n) for n in mechanism.independent]
    assert [model.joints[j].idx_q for j in order] == list(range(6))
    lowest = np.inf
    try:
        geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION,
                                         package_dirs=list(package_dirs(str(urdf))))
    except Exception:
        geometry = None                      # meshes missing: the frames' origins only
    if geometry is not None:
        geometry.addAllCollisionPairs()
        if srdf is not None:
            pin.removeCollisionPairs(model, geometry, str(srdf))
        gdata = pin.GeometryData(geometry)
    for k in range(len(t)):
        pin.framesForwardKinematics(model, data, q[k])
        moving = [f for f in range(model.nframes) if model.frames[f].parentJoint > 0]
        lowest = min(lowest, min(data.oMf[f].translation[2] for f in moving))
        if geometry is not None:
            pin.updateGeometryPlacements(model, data, geometry, gdata)
            assert not pin.computeCollisions(geometry, gdata, False), f"self-collision at t = {t[k]}"
            for g, obj in enumerate(geometry.geometryObjects):
                if obj.parentJoint > 0 and hasattr(obj.geometry, "vertices"):
                    placed = np.asarray(obj.geometry.vertices()) @ gdata.oMg[g].rotation.T + gdata.oMg[g].translation
                    lowest = min(lowest, placed[:, 2].min())
        tau = pin.rnea(model, data, q[k], qd[k], qdd[k])
        assert np.all(np.abs(tau) <= model.effortLimit + 1e-9), (t[k], tau)
    assert lowest > 0, lowest
    assert np.all(q >= model.lowerPositionLimit - 1e-12) and np.all(q <= model.upperPositionLimit + 1e-12)
    assert np.all(np.abs(qd) <= model.velocityLimit * (1 + 1e-9))
    return lowest


@pytest.mark.slow
def test_ur5_default_plan_runs_on_the_robot(tmp_path):
    urdf, srdf = _ur5()
    out, report = tmp_path / "ur5.toml", tmp_path / "r.json"
    result = _run("excite", urdf, "--srdf", srdf, "-o", out, "--report", report, "--quiet")
    assert result.exit_code == 0, result.stderr
    data = json.loads(report.read_text())
    _independent_checks(out, urdf, srdf, urdf)
    assert data["verified"]["collision"]["self_collision_checked"]
    assert data["after"]["condition_number"] <= 1.5 * 2.64
    assert data["after"]["condition_number"] < data["before"]["condition_number"]


@pytest.mark.slow
def test_tx40_default_plan_runs_on_the_robot(tmp_path):
    pytest.importorskip("pinocchio")
    out, report = tmp_path / "tx40.toml", tmp_path / "r.json"
    result = _run("excite", TX40, "-o", out, "--report", report, "--quiet")
    assert result.exit_code == 0, result.stderr
    data = json.loads(report.read_text())
    _independent_checks(out, TX40, None, TX40)
    assert any("no collision geometry" in n for n in data["notes"])
    assert data["after"]["condition_number"] <= 1.5 * 2.20


def test_check_reads_a_recording_description_run_by_run():
    """The TX40's real recording (two runs) through its description: its joint_1 peaks at 5.04
    rad/s against the URDF's 5.009: a check that fails, exit 1."""
    result = _run("excite", TX40, "--check", DATA / "tx40" / "recording.toml", "--format", "json", "--quiet")
    assert result.exit_code == 1, result.output
    data = json.loads(result.stdout)
    assert data["margins"]["velocity"] < 0 and data["margins"]["position"] > 0
    assert data["peaks"]["joint_1"]["qd_peak"] > 5.009
    assert any("2 runs" in n for n in data["notes"])
