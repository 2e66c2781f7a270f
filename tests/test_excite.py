"""excite: the derivatives against independent computations, the form's exact rest, the
limits on the written file recomputed from its own expressions, the verb end to end on the
UR5 and on generated chains, bad input. The figures of docs/excite.md: benchmarks/bench_excite.py."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sympy
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.dynamics import codegen
from baseparams.dynamics.trajectory import T, values_at
from baseparams.excite import design
from baseparams.excite.criterion import Model, criterion
from baseparams.excite.fourier import FourierForm
from baseparams.excite.limits import drive_limits, limits_of
from baseparams.excite.plan import Settings, plan, problem_of
from baseparams.excite.tangent import tree_regressor_with_tangents
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify
from baseparams.dynamics.forces import standard_parameters
from baseparams.recordings.simulate import simulate
from baseparams.io.loader import load_mechanism, parse_mechanism, resolve
from baseparams.model import generate
from baseparams.numeric.backends import Float64
from baseparams.orchestrate.jobs import MechanismText

DATA = Path(__file__).parent / "data"
UR5 = DATA / "urdf" / "ur5.urdf"
TX40 = DATA / "tx40" / "tx40_mdh_modified.urdf"


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _base(mechanism, solver="dp", **options):
    return BaseModel.from_result(registry.solvers()[solver].item.solve(mechanism, **options), mechanism)


def _qr_base(mechanism):
    return _base(mechanism, pivoting="qr")


def _central(function, x, h=1e-6):
    out = []
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = h
        out.append((function(x + e) - function(x - e)) / (2 * h))
    return np.array(out)


# ----- forward-mode tangents of the generated regressor ------------------------------------------
@pytest.mark.parametrize("text", [generate.serial_chain(3, bodies=4), generate.serial_chain(8, bodies=3, types="RP"),
                                  generate.tree(5, bodies=4)])
def test_tangents_equal_the_derivatives_of_the_generated_regressor(text):
    mechanism = parse_mechanism(text)
    rng = np.random.default_rng(1)
    n = len(mechanism.coordinates)
    q, qd, qdd = (rng.uniform(-1, 1, (7, n)) for _ in range(3))
    K, dK = tree_regressor_with_tangents(mechanism, q, qd, qdd)
    np.testing.assert_allclose(K, codegen.tree_regressor(mechanism, list(q.T), list(qd.T), list(qdd.T)),
                               rtol=1e-12, atol=1e-12)
    for g in range(3):
        for i in range(n):
            def k_of(value, g=g, i=i):
                args = [q.copy(), qd.copy(), qdd.copy()]
                args[g][:, i] = value
                return codegen.tree_regressor(mechanism, *[list(a.T) for a in args])
            base = (q, qd, qdd)[g][:, i]
            numeric = (k_of(base + 1e-6) - k_of(base - 1e-6)) / 2e-6
            np.testing.assert_allclose(dK[g * n + i], numeric, rtol=1e-5, atol=1e-6)


def test_tangents_of_the_ur5_regressor_against_pinocchio_torques():
    """d(K phi)/dqdd is the mass matrix: Pinocchio's CRBA, an independent computation."""
    pinocchio = pytest.importorskip("pinocchio")
    mechanism = load_mechanism(UR5)
    model = pinocchio.buildModelFromUrdf(str(UR5))
    data = model.createData()
    rng = np.random.default_rng(2)
    q = rng.uniform(-2, 2, (1, 6))
    K, dK = tree_regressor_with_tangents(mechanism, q, np.zeros((1, 6)), np.zeros((1, 6)))
    phi = standard_parameters(mechanism)
    mass = np.array([dK[12 + i, 0] @ phi for i in range(6)]).T
    expected = pinocchio.crba(model, data, q[0])
    expected = np.triu(expected) + np.triu(expected, 1).T
    np.testing.assert_allclose(mass, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ["four_bar", "sla_suspension"])
def test_closed_loop_tangents_equal_central_differences_of_the_evaluated_regressor(name):
    """K = R^T K_tree along the closure, and the singularity margin: their derivatives in z,
    zd, zdd against central differences of the evaluator's own Newton-solved samples."""
    from baseparams.excite.loops import regressor_with_tangents
    from baseparams.dynamics.forces import Motion, evaluate, inertial_columns
    from baseparams.recordings.simulate import trajectory_motion
    mechanism = resolve(name)
    f = len(mechanism.independent)
    rng = np.random.default_rng(7)
    motion = trajectory_motion(mechanism)
    rows = rng.choice(motion.count, 4)
    z, zd, zdd = motion.q[rows], rng.uniform(-1, 1, (4, f)), rng.uniform(-1, 1, (4, f))

    def at(z, zd, zdd):
        sample = evaluate(mechanism, Motion(np.arange(4.0), z, zd, zdd))
        return inertial_columns(sample, 4), design.singularity_margin(mechanism, sample), sample

    K0, margin0, sample = at(z, zd, zdd)
    K, dK, margin, dmargin = regressor_with_tangents(mechanism, sample, zd, zdd)
    np.testing.assert_allclose(K, K0, atol=1e-12)
    np.testing.assert_allclose(margin, margin0, atol=1e-12)
    for g in range(3):
        for k in range(f):
            plus, minus = [z.copy(), zd.copy(), zdd.copy()], [z.copy(), zd.copy(), zdd.copy()]
            plus[g][:, k] += 1e-6
            minus[g][:, k] -= 1e-6
            (Kp, mp, _), (Km, mm, _) = at(*plus), at(*minus)
            scale = max(1.0, np.abs(Kp - Km).max() / 2e-6)
            np.testing.assert_allclose(dK[g * f + k], (Kp - Km) / 2e-6, atol=1e-6 * scale)
            np.testing.assert_allclose(dmargin[g * f + k], (mp - mm) / 2e-6, atol=1e-7)


# ----- the criteria's gradients ------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["condition", "d-optimal", "separation"])
def test_criterion_gradients_against_central_differences(kind):
    rng = np.random.default_rng(3)
    matrix = rng.standard_normal((20, 2, 5))
    weights = np.array([1.0, 2.5])
    separate = (3, 4) if kind == "separation" else ()
    value = criterion(kind, matrix, weights, separate, gradient=True)
    flat = matrix.reshape(-1)
    numeric = _central(lambda v: np.array(criterion(kind, v.reshape(matrix.shape), weights, separate).value), flat)
    np.testing.assert_allclose(value.gradient.reshape(-1), numeric, rtol=1e-5, atol=1e-7)


def test_separation_angle_is_the_angle_to_the_span_of_the_others():
    rng = np.random.default_rng(4)
    matrix = rng.standard_normal((30, 1, 4))
    value = criterion("separation", matrix, None, (3,))
    A = matrix[:, 0, :]
    others, column = A[:, :3], A[:, 3]
    residual = column - others @ np.linalg.lstsq(others, column, rcond=None)[0]
    expected = math.degrees(math.asin(np.linalg.norm(residual) / np.linalg.norm(column)))
    assert value.smallest_angle_deg == pytest.approx(expected, rel=1e-9)


def test_condition_number_is_identifys_on_simulated_data():
    """Same matrix, same figure: identify's condition number with equal noise weights."""
    mechanism = load_mechanism(UR5)
    base = _base(mechanism)
    data, _ = simulate(mechanism, noise_sd=1e-3, seed=0, samples=120)
    result = identify(mechanism, data, base=base)
    model = Model(mechanism, base, weights=1 / result.noise_sd)
    columns = model.columns(data.motion.q, data.motion.qd, data.motion.qdd)
    assert criterion("condition", columns.matrix, model.weights).condition == pytest.approx(
        result.condition_number, rel=1e-8)


def test_objective_gradient_through_the_motion():
    """d(criterion)/d(Fourier variables), torque constraint Jacobian: against central differences."""
    mechanism = parse_mechanism(generate.serial_chain(11, bodies=3))
    limits = limits_of(mechanism, torque="50")
    problem = problem_of(mechanism, _base(mechanism), limits, Settings(harmonics=3, samples=30))
    x = design.random_start(problem, np.random.default_rng(0))
    rows = problem.form.rows(problem.times())

    def value(v):
        q, qd, qdd = problem.form.motion(v, problem.times())
        return criterion("condition", problem.model.columns(q, qd, qdd, tangents=True).matrix, None).value

    q, qd, qdd = problem.form.motion(x, problem.times())
    columns = problem.model.columns(q, qd, qdd, tangents=True)
    result = criterion("condition", columns.matrix, None, gradient=True)
    inputs = np.einsum("nfm,dnfm->dn", result.gradient, columns.tangents)
    np.testing.assert_allclose(design._chain(problem, inputs, rows), _central(value, x), rtol=1e-4, atol=1e-7)

    def torque(v):
        q, qd, qdd = problem.form.motion(v, problem.times())
        return problem.model.columns(q, qd, qdd, tangents=True).torque.reshape(-1)

    analytic = design._per_sample(problem, columns.torque_tangents, rows).reshape(-1, x.size)
    np.testing.assert_allclose(analytic, _central(torque, x).T, rtol=1e-5, atol=1e-6)


# ----- the form ----------------------------------------------------------------------------------
def test_written_motion_is_at_rest_exactly_and_equals_the_optimisers():
    form = FourierForm(("a", "b"), 4, 7.5)
    x = np.random.default_rng(5).standard_normal(form.size)
    expressions = form.expressions(x)
    for expression in expressions.values():
        for point in (0, sympy.Rational(15, 2)):
            assert sympy.simplify(sympy.diff(expression, T).subs(T, point)) == 0
            assert sympy.simplify(sympy.diff(expression, T, 2).subs(T, point)) == 0
    t = np.linspace(0, 7.5, 23)
    q, qd, qdd = form.motion(form.rounded(x), t)
    for j, name in enumerate(form.names):
        values = values_at(expressions[name], Float64(), t)
        for mine, exact in zip((q, qd, qdd), values):
            np.testing.assert_allclose(mine[:, j], exact, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(form.motion(form.rounded(x), t)[0], form.motion(x, t)[0], atol=1e-9)


def test_urdf_velocity_and_effort_limits_are_read():
    mechanism = load_mechanism(TX40)
    found = drive_limits(mechanism)
    assert found["joint_1"] == {"velocity": 5.009, "effort": 131.84}
    limits = limits_of(mechanism, acceleration="joint_2=3", velocity="1.5")
    assert limits.upper[4] == pytest.approx(2.33) and limits.lower[4] == pytest.approx(-2.09)
    assert list(limits.velocity) == [1.5] * 6
    assert limits.acceleration[1] == 3 and limits.acceleration[0] == np.inf      # no invented default
    assert limits.torque[5] == pytest.approx(30.72)
    assert any("no acceleration limit" in a and "joint_1" in a for a in limits.assumptions())
    assert "acceleration" not in " ".join(limits_of(mechanism, acceleration="2").assumptions())
    margin = limits_of(mechanism, velocity_margin=0.1)
    assert margin.velocity[0] == pytest.approx(0.9 * 5.009)


# ----- the verb ----------------------------------------------------------------------------------
def _limits_hold(mechanism, path_limits, samples=2000):
    """Every limit on a fine grid, from the written file's own expressions (values_at)."""
    spec = mechanism.trajectory
    t = np.linspace(float(spec.t_start), float(spec.t_end), samples)
    for k, name in enumerate(path_limits.names):
        q, qd, qdd = values_at(spec.expressions[name], Float64(), t)
        assert np.all(q >= path_limits.lower[k] - 1e-12) and np.all(q <= path_limits.upper[k] + 1e-12), name
        assert np.max(np.abs(qd)) <= path_limits.velocity[k] * (1 + 1e-9), name
        assert np.max(np.abs(qdd)) <= path_limits.acceleration[k] * (1 + 1e-9), name
        assert abs(float(q[0] - q[-1])) < 1e-12 and abs(float(qd[0])) < 1e-12 and abs(float(qdd[0])) < 1e-9


def test_excite_ur5_halves_the_condition_number_within_the_limits(tmp_path):
    out, report, table, figure = tmp_path / "ur5.toml", tmp_path / "r.json", tmp_path / "m.csv", tmp_path / "p.png"
    result = _run("excite", UR5, "-o", out, "--solver", "dp", "--harmonics", "3", "--samples", "40", "--iterations", "30",
                  "--starts", "1", "--max-acceleration", "6", "--report", report, "--csv", table,
                  "--rate", "50", "--plot", figure, "--format", "json", "--quiet")
    assert result.exit_code == 0, result.output
    data = json.loads(report.read_text())
    assert data["after"]["condition_number"] <= data["before"]["condition_number"] / 2
    assert data["verified"]["feasible"] and all(v >= 0 for v in data["verified"]["margins"].values())
    written = load_mechanism(out)
    limits = limits_of(load_mechanism(UR5), acceleration="6")
    _limits_hold(written, limits)
    # identify on data simulated along the written motion reports the same condition number
    base = _base(written)
    # (noise-free: identify's noise weights, estimated from 40 samples' residuals, move the
    # figure by 5-9 % with noise_sd=1e-3, by the base chosen)
    simulated, _ = simulate(written, noise_sd=0.0, seed=1)
    fitted = identify(written, simulated, base=base)
    assert fitted.condition_number == pytest.approx(data["after"]["condition_number"], rel=1e-6)
    rows = table.read_text().splitlines()
    assert rows[0].startswith("t,q_shoulder_pan_joint,qd_shoulder_pan_joint,qdd_shoulder_pan_joint")
    assert len(rows) == 1 + 501
    assert figure.stat().st_size > 1000


@pytest.mark.parametrize("seed", [2, 6])
def test_excite_on_generated_chains_beats_their_trajectory(tmp_path, seed):
    text = generate.serial_chain(seed, bodies=3)
    path = tmp_path / "chain.toml"
    path.write_text(text)
    mechanism = load_mechanism(path)
    limits = limits_of(mechanism, velocity="2", acceleration="8")
    settings = Settings(harmonics=3, samples=40, maxiter=60)
    # on dp's QR-pivoted base, on which this test was written: the condition number depends on
    # the base, and on seed 6's natural one (m1 kept: cond(V22) 62 against 2.7; vp's and, since
    # issue 45, dp's) the plan stays at 130 from 1 or 3 starts and 60 or 150 iterations, where
    # random states give 68 (reported in issue 45)
    found = plan(mechanism, MechanismText.read("chain", path), _qr_base(mechanism), limits, settings, starts=1,
                 rebase=_qr_base)
    assert found.finer.feasible
    assert found.after.condition < found.before.condition or found.before.condition < 3
    assert found.after.condition <= 1.5 * found.random_states.condition


def test_bad_input_is_an_error_line_and_exit_2(tmp_path):
    out = tmp_path / "o.toml"
    cases = [("--position-range", "shoulder_pan_joint=1:1"),
             ("--position-range", "shoulder_pan_joint=9:10"),
             ("--separate", "coulomb_friction:nowhere"),
             ("--separate", "teleport:shoulder_pan_joint"),
             ("--max-velocity", "-1"),
             ("--effect", "viscous_friction"),
             ("--noise", "0.1,0.2")]
    for option, value in cases:
        result = _run("excite", UR5, "-o", out, option, value, "--iterations", "2", "--quiet")
        assert result.exit_code == 2, (option, value, result.output)
        assert "error:" in result.output and "Traceback" not in result.output
    assert not out.exists()


def test_limits_no_motion_satisfies_are_refused(tmp_path):
    """Gravity alone needs more than 0.001 N m on the shoulder: no motion, not an infeasible one."""
    out = tmp_path / "o.toml"
    result = _run("excite", UR5, "-o", out, "--max-torque", "0.001", "--harmonics", "2", "--samples", "20",
                  "--iterations", "5", "--starts", "1", "--quiet")
    assert result.exit_code == 2, result.output
    assert "error:" in result.output and "limits" in result.output
    assert not out.exists()


def test_separate_reads_a_diagnose_report(tmp_path):
    report = tmp_path / "d.json"
    report.write_text(json.dumps({"ambiguous": [{"candidates": [
        {"kind": "viscous_friction", "coordinate": "shoulder_pan_joint"},
        {"kind": "coulomb_friction", "coordinate": "shoulder_pan_joint"}]}]}))
    from baseparams.cli.excite import parse_separate
    mechanism = load_mechanism(UR5)
    assert parse_separate(str(report), mechanism) == (("viscous_friction", "shoulder_pan_joint"),
                                                       ("coulomb_friction", "shoulder_pan_joint"))
    (tmp_path / "bad.json").write_text(json.dumps({"effects": []}))
    result = _run("excite", UR5, "-o", tmp_path / "o.toml", "--separate", tmp_path / "bad.json", "--quiet")
    assert result.exit_code == 2 and "ambiguous" in result.output


# ----- the figures (slow; the full table: benchmarks/bench_excite.py) ----------------------
@pytest.mark.slow
def test_tx40_planned_motion_beats_its_trajectory_and_its_recording(tmp_path):
    out, report = tmp_path / "tx40.toml", tmp_path / "r.json"
    result = _run("excite", TX40, "-o", out, "--starts", "2", "--report", report, "--quiet")
    assert result.exit_code == 0, result.output
    data = json.loads(report.read_text())
    from baseparams.recordings.recording import read_data
    mechanism = load_mechanism(TX40)
    recorded, model = read_data([str(DATA / "tx40" / "recording.toml")], mechanism)
    recorded_condition = identify(model, recorded, base=_base(mechanism)).condition_number
    after = data["after"]["condition_number"]
    assert after <= data["before"]["condition_number"] / 2
    assert after <= recorded_condition
    assert after <= 1.5 * data["random_states"]["condition_number"]
    _limits_hold(load_mechanism(out), limits_of(mechanism))


@pytest.mark.slow
def test_sla_planned_motion_keeps_the_margin_and_rank_41_certified(tmp_path):
    """The optimised motion (written, or returned beside the file's trajectory when it is not
    better: issue 43) keeps the singularity margin, and vp certifies rank 41 on it."""
    import baseparams as bp
    from baseparams.excite.plan import with_x
    out = tmp_path / "sla.toml"
    result = bp.excite("sla_suspension", output=str(out), starts=1, iterations=100)
    found = result.plan
    assert found.finer.feasible and found.finer.margins["singularity"] >= 0
    assert found.after.condition <= 10 * found.random_states.condition or not found.improved
    if not found.improved:                             # never worse than the start
        assert found.before.value <= found.after.value
        assert load_mechanism(out).trajectory.expressions == resolve("sla_suspension").trajectory.expressions
    written = with_x(result.mechanism, found.problem, found.x)
    solved = registry.solvers()["vp"].item.solve(written)
    assert solved.rank == 41 and solved.certified
    # the margin recomputed from the optimised motion's own expressions, ten times finer
    from baseparams.dynamics.forces import Motion, evaluate
    spec = written.trajectory
    t = np.linspace(0, float(spec.t_end), 10 * (spec.samples - 1) + 1)
    values = [values_at(spec.expressions[name], Float64(), t) for name in written.independent]
    q, qd, qdd = (np.stack([np.broadcast_to(v[k], t.shape) for v in values], axis=1) for k in range(3))
    sample = evaluate(written, Motion(t, q, qd, qdd))
    assert design.singularity_margin(written, sample).min() >= 0.03


@pytest.mark.slow
def test_multistart_on_two_worker_processes_finds_what_one_process_finds(tmp_path):
    from baseparams.orchestrate.runners import InProcess, Processes
    mechanism = load_mechanism(UR5)
    limits = limits_of(mechanism, acceleration="6")
    settings = Settings(harmonics=2, samples=30, maxiter=15)
    text = MechanismText.read("ur5", UR5)
    base = _base(mechanism)
    here = plan(mechanism, text, base, limits, settings, starts=3, runner=InProcess())
    there = plan(mechanism, text, base, limits, settings, starts=3, runner=Processes(2))
    assert [s["seed"] for s in there.starts] == [0, 1, 2]
    np.testing.assert_allclose([s["value"] for s in there.starts], [s["value"] for s in here.starts], rtol=1e-6)
    assert there.after.condition == pytest.approx(here.after.condition, rel=1e-6)
