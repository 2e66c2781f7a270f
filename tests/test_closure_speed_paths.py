"""The fast float64 paths (issue 12) against the paths they replace.

- Closed loops: the batched continuation (tangent-predicted stages, Newton on the samples
  not yet converged, evaluator._assemble_batch) gives the same positions -- hence the
  same assembly mode -- and the same W as the general per-stage Newton
  (evaluator.BATCHED_NEWTON = False) on every built-in closed loop and on generated
  four-bars; errors read as before.
- Trajectory derivatives by forward-mode jets against sympy's symbolic derivatives, in
  float64, arb (balls overlap), rationals (equal) and sympy (identical after simplify).
- One state at a time (arb, and float64 single states such as the excitation check's
  draws): the generated scalar closure code (evaluator.SCALAR_CLOSURE) against the generic
  kinematics -- arb balls overlap, W's balls overlap, the draws land where they did.
- Cached kinematics frames and the evenly spaced exact sample times.
"""

import re
from fractions import Fraction

import numpy as np
import pytest
import sympy
from flint import arb, fmpq

from baseparams.dynamics import codegen, evaluator, trajectory
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix as build
from baseparams.dynamics.trajectory import Trajectory, even_times, observation_matrix, samples_float64, values_at
from baseparams.errors import KinematicsError
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.kinematics.tree import TreeKinematics
from baseparams.model import generate
from baseparams.model.expressions import parse_expression
from baseparams.numeric.backends import Arb, Exact, Float64, Symbolic

CLOSED = ["sla_suspension", "four_bar", "slider_crank", "stewart_platform"]
FOUR_BAR_SEEDS = range(8)


def _positions_and_w(mech, batched, monkeypatch):
    """Tree coordinates (n, samples) along the default trajectory and W, by one path."""
    monkeypatch.setattr(evaluator, "BATCHED_NEWTON", batched)
    traj = Trajectory.default(mech)
    sample, t = samples_float64(mech, traj)
    q = np.array([np.broadcast_to(np.asarray(v, dtype=float), t.shape) for v in sample.q])
    w, _ = observation_matrix(mech, Float64(), traj)
    return q, w


def _mechanisms():
    return [pytest.param(lambda name=name: resolve(name), id=name) for name in CLOSED] + [
        pytest.param(lambda seed=seed: parse_mechanism(generate.four_bar(seed)), id=f"four_bar({seed})")
        for seed in FOUR_BAR_SEEDS]


def _count_batched(monkeypatch) -> list:
    """Records, per call of the batched assembly, whether it finished (True) or handed over."""
    calls = []
    original = Evaluator._assemble_batch

    def counted(self, z, guess):
        result = original(self, z, guess)
        calls.append(result is not None)
        return result

    monkeypatch.setattr(Evaluator, "_assemble_batch", counted)
    return calls


@pytest.mark.parametrize("make", _mechanisms())
def test_batched_continuation_keeps_the_branch_and_w(make, monkeypatch):
    mech = make()
    calls = _count_batched(monkeypatch)
    q_new, w_new = _positions_and_w(mech, True, monkeypatch)
    assert calls and all(calls)                       # the batched path ran, no fallback
    q_old, w_old = _positions_and_w(mech, False, monkeypatch)
    # same assembly mode: the same positions to rounding (another branch differs by O(1))
    assert np.abs(q_new - q_old).max() <= 1e-10
    assert np.abs(w_new - w_old).max() <= 1e-10 * np.abs(w_old).max()
    traj = Trajectory.default(mech)
    ev = Evaluator(mech, Float64())
    z, _, _ = traj.independent_values(mech, Float64(), np.array([float(t) for t in traj.times]))
    q = ev.assemble(z)
    values, _ = ev.closure(q)
    assert max(np.abs(v).max() for v in values) <= 1e-12       # the closure tolerance still holds


@pytest.mark.parametrize("name", ["four_bar", "sla_suspension"])
def test_batched_sample_states_and_projection(name, monkeypatch):
    """Sample.states (computed when read) and R from the batched path equal the general ones."""
    mech = resolve(name)
    traj = Trajectory.default(mech)
    samples = {}
    for batched in (True, False):
        monkeypatch.setattr(evaluator, "BATCHED_NEWTON", batched)
        samples[batched], _ = samples_float64(mech, traj)
    new, old = samples[True], samples[False]
    assert new._states is None                               # not computed until read
    for body, state in old.states.items():
        assert np.allclose(np.asarray(new.states[body].pos, dtype=float), np.asarray(state.pos, dtype=float),
                           atol=1e-12)
    for row_new, row_old in zip(new.projection, old.projection):
        for a, b in zip(row_new, row_old):
            assert np.allclose(a, b, rtol=1e-10, atol=1e-10)
    for a, b in zip(new.qdd, old.qdd):
        assert np.allclose(a, b, rtol=1e-10, atol=1e-10)


def test_random_batch_with_starts_takes_the_batched_path(monkeypatch):
    """dp's excitation check: states given with float starts (one Newton stage, no continuation)."""
    mech = parse_mechanism(generate.four_bar(3, samples=60))
    batch = random_batch(mech, Trajectory.default(mech), seed=5)
    calls = _count_batched(monkeypatch)
    results = {}
    for batched in (True, False):
        monkeypatch.setattr(evaluator, "BATCHED_NEWTON", batched)
        evaluator.codegen.compiled(mech, "closure")          # batches this small use generated code once compiled
        results[batched], _ = build(mech, Float64(), batch)
    assert calls == [True]
    assert np.abs(results[True] - results[False]).max() <= 1e-10 * np.abs(results[False]).max()


def test_batched_path_follows_the_homotopy_where_four_stages_jump(monkeypatch):
    """An SLA state near the edge of the reachable range (dp's excitation draw 18, seed 2):
    four plain Newton stages landed on another assembly mode; the predicted stages agree
    with a 64-stage continuation (50, 100 and 400 stages agree too). Since issue 49 the
    general path (a single state) predicts its stages along the tangent as well, and
    follows the same path (before: more than 0.1 apart; a generated parallelogram with a
    short coupler folded onto its crossed branch at 0.7 rad of crank)."""
    mech = resolve("sla_suspension")
    evaluator.codegen.compiled(mech, "closure")
    z = [float(Fraction(2327712038408277079, 2814749767106560000)),
         float(Fraction(4827662654627915749, 11258999068426240000))]
    ev = Evaluator(mech, Float64())
    batched = np.array(ev.assemble([np.array([v]) for v in z]), dtype=float)[:, 0]
    q = [0.0] * ev.n
    for k in range(1, 65):
        q = ev._newton(q, [k / 64 * v for v in z], -12, "")
    assert np.abs(batched - np.array(q, dtype=float)).max() <= 1e-10
    single = np.array(ev.assemble(z), dtype=float)             # a scalar state: the general path
    assert np.abs(single - batched).max() <= 1e-10


def test_unreachable_trajectory_reports_as_before(monkeypatch):
    """A batch the fast path cannot finish falls back to the general path and its message."""
    mech = resolve("sla_suspension")
    t = sympy.Symbol("t")
    traj = Trajectory({"theta1": 3 * sympy.sin(t), "theta2": 0 * t}, even_times(Fraction(0), Fraction(19, 10), 60))
    messages = {}
    for batched in (True, False):
        monkeypatch.setattr(evaluator, "BATCHED_NEWTON", batched)
        with pytest.raises(KinematicsError) as info:
            observation_matrix(mech, Float64(), traj)
        messages[batched] = str(info.value)
    # the same time, coordinates and reason; the residual after 60 diverging Newton steps
    # depends on the last bit of the previous sample's solution it started from
    assert re.sub(r"residual [^ ]+", "residual *", messages[True]) == re.sub(r"residual [^ ]+", "residual *",
                                                                             messages[False])
    assert "at t = " in messages[True]


# ----- one state: the generated scalar closure -----------------------------------------------
def _random_state(mech, seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.4, 0.4, len(mech.coordinates)), rng.uniform(-1, 1, len(mech.coordinates))


@pytest.mark.parametrize("make", _mechanisms())
def test_scalar_closure_encloses_what_the_generic_kinematics_gives(make):
    """Closure values, Jacobian and bias at one state: arb balls overlap the generic
    kinematics' balls (both contain the exact values) and are as tight; on Python floats
    equal to the numpy code to rounding."""
    mech = make()
    backend = Arb(40)
    kin = TreeKinematics(mech, backend)
    q, qd = _random_state(mech, 3)
    with backend.activate():
        qa, qda = [arb(v) for v in q], [arb(v) for v in qd]
        values, rows, bias = kin.closure(kin.forward(qa, qda), want_bias=True)
        s_values, s_rows = codegen.scalar_closure(mech, backend, qa)
        s_bias = codegen.scalar_closure_bias(mech, backend, qa, qda)
        pairs = list(zip(values, s_values)) + list(zip(bias, s_bias)) + [
            (a, b) for r, t in zip(rows, s_rows) for a, b in zip(r, t)]
        for generic, generated in pairs:
            generic, generated = arb(generic), arb(generated)
            assert generic.overlaps(generated)
            assert generated.rad() <= 16 * generic.rad() + arb(10) ** -35
    codegen.compiled(mech, "closure")
    f_values, f_rows = codegen.scalar_closure(mech, Float64(), [float(v) for v in q])
    n_values, n_rows = codegen.closure(mech, [float(v) for v in q])
    scale = max(1.0, max(abs(float(v)) for row in n_rows for v in row))
    assert np.allclose(np.array(f_values, dtype=float), np.array(n_values, dtype=float), rtol=0, atol=1e-13 * scale)
    assert np.allclose(np.array(f_rows, dtype=float), np.array(n_rows, dtype=float), rtol=0, atol=1e-13 * scale)


@pytest.mark.parametrize("make", [pytest.param(lambda name=name: resolve(name), id=name)
                                  for name in ("sla_suspension", "four_bar", "stewart_platform")] + [
    pytest.param(lambda seed=seed: parse_mechanism(generate.four_bar(seed)), id=f"four_bar({seed})")
    for seed in range(3)])
def test_random_draws_and_arb_w_by_the_scalar_closure(make, monkeypatch):
    """The excitation check's draws (one float64 state each, continuation) land on the same
    positions with the generated scalar code as with the numpy code; W at 30 digits at those
    states, positions enclosed by Krawczyk's test, overlaps entry by entry."""
    mech = make()
    traj = Trajectory.default(mech)
    codegen.compiled(mech, "closure")
    results = {}
    for scalar in (True, False):
        monkeypatch.setattr(evaluator, "SCALAR_CLOSURE", scalar)
        batch = random_batch(mech, traj, seed=2)
        w, _ = build(mech, Arb(30), batch)
        results[scalar] = (np.array(batch.start, dtype=float), w)
    (start_new, w_new), (start_old, w_old) = results[True], results[False]
    assert np.abs(start_new - start_old).max() <= 1e-10
    assert w_new.nrows() == w_old.nrows() and w_new.ncols() == w_old.ncols()
    for a, b in zip(w_new.entries(), w_old.entries()):
        assert a.overlaps(b)


@pytest.mark.parametrize("make", _mechanisms())
def test_projection_skipping_exact_zeros_gives_the_same_balls(make):
    """R^T K_tree over the columns the generated code can fill equals the full product,
    ball for ball (what is skipped is exact zeros)."""
    mech = make()
    backend = Arb(30)
    ev = Evaluator(mech, backend, certify=True)
    traj = Trajectory.default(mech)
    index = len(traj.times) // 3
    with backend.activate():
        z, zd, zdd = traj.values(mech, backend, index)
        sample = ev.sample(z, zd, zdd, [backend.number(v) for v in traj.starts(mech)[index]])
        k_tree = codegen.regressor_rows(ev.kin, sample.q, sample.qd, sample.qdd, None)
        columns = codegen.regressor_columns(ev.kin)
        sparse = evaluator.project(sample.projection, k_tree, ev.kin.zero, columns)
        full = evaluator.project(sample.projection, k_tree, ev.kin.zero)
    assert sum(len(c) for c in columns) < len(k_tree) * len(k_tree[0])
    for a, b in zip((x for row in sparse for x in row), (x for row in full for x in row)):
        assert arb(a).mid() == arb(b).mid() and arb(a).rad() == arb(b).rad()


# ----- trajectory derivatives ----------------------------------------------------------------
EXPRESSIONS = ["3/10*sin(2*t + 1) - cos(t/3)**2 + 1/(2 + sin(t)) + sqrt(3 + t**2)*exp(-t/5)",
               "sqrt(1 + t)**3/(1 + t**2)**2 - 7", "5/4", "t**3/2 - 2*t + 1/(3 + t)", "exp(sin(pi*t))"]


def _generated_expressions():
    mech = parse_mechanism(generate.serial_chain(4, bodies=5))
    return [str(e) for e in mech.trajectory.expressions.values()]


@pytest.mark.parametrize("text", EXPRESSIONS + _generated_expressions())
def test_jets_match_symbolic_derivatives(text):
    expression = parse_expression(text, time=True)
    symbolic = trajectory._derivatives(expression)
    times = np.linspace(-0.7, 9.3, 41)
    got = values_at(expression, Float64(), times)
    for g, e in zip(got, symbolic):
        want = np.broadcast_to(Float64().evaluate(e, {"t": times}), times.shape)
        assert np.allclose(np.broadcast_to(g, times.shape), want, rtol=1e-13, atol=1e-13)
    backend = Arb(40)
    with backend.activate():
        point = arb(fmpq(17, 7))
        for g, e in zip(values_at(expression, backend, point), symbolic):
            assert g.overlaps(backend.evaluate(e, {"t": point}))
            assert g.rad() < 1e-30
    t = sympy.Symbol("t")
    for g, e in zip(values_at(expression, Symbolic(), t), symbolic):
        assert sympy.simplify(g - e) == 0


@pytest.mark.parametrize("text", ["t**3/2 - 2*t + 1/(3 + t)", "(1 + t**2)/(2 - t) + 7/3"])
def test_jets_are_exact_in_rationals(text):
    expression = parse_expression(text, time=True)
    for x in (fmpq(3, 7), fmpq(-5, 2)):
        got = values_at(expression, Exact(), x)
        want = [Exact().evaluate(e, {"t": x}) for e in trajectory._derivatives(expression)]
        assert list(got) == want


def test_even_times_are_the_exact_grid():
    for t0, t1, n in [(Fraction(0), Fraction(10), 200), (Fraction(-1, 3), Fraction(7, 5), 17),
                      (Fraction(1, 2), Fraction(1, 2) + Fraction(1, 10 ** 30), 3)]:
        assert even_times(t0, t1, n) == tuple(t0 + (t1 - t0) * k / (n - 1) for k in range(n))


# ----- cached frames -------------------------------------------------------------------------------
def test_frames_are_shared_per_backend_kind_and_precision():
    mech = parse_mechanism(generate.four_bar(11))
    a, b = TreeKinematics(mech, Float64()), TreeKinematics(mech, Float64())
    assert a.edges is b.edges
    low, high = TreeKinematics(mech, Arb(30)), TreeKinematics(mech, Arb(60))
    assert low.edges is not high.edges
    # an arb frame holds its exact value at its own precision
    r30 = low.edges[-1][4][0][0][0]
    r60 = high.edges[-1][4][0][0][0]
    assert r30.overlaps(r60) and r60.rad() < r30.rad()
    fresh = TreeKinematics.__new__(TreeKinematics)
    fresh._prepare(mech, Float64(), False, a.index)
    assert np.array_equal(np.array(fresh.edges[-1][4][0], dtype=float), np.array(a.edges[-1][4][0], dtype=float))
