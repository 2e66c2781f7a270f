"""One observation-matrix builder for every arithmetic, and precision as an explicit context.

The same states must give the same W in Float64, Arb and Exact (each checked against
another arithmetic, never against itself), every source of states (trajectory, random
batch, random rational states) goes through the one builder, and no public function
that computes in arb may depend on, or leave behind, a process-wide precision.
"""

from fractions import Fraction

import numpy as np
import pytest
from flint import arb, arb_mat, ctx, fmpq, fmpq_mat

from baseparams.dynamics import observation
from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.plugins.solvers.exact.states import exact_observation_matrix, random_rational_states
from baseparams.dynamics.excitation import RandomBatch, random_batch
from baseparams.dynamics.observation import RationalStates, evaluate_states, observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.trajectory import observation_matrix as trajectory_matrix
from baseparams.errors import KinematicsError
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.numeric import certify
from baseparams.plugins.solvers.vp import balls
from baseparams.numeric.backends import Arb, Exact, Float64, TanHalf

DIGITS = 40
ODD_PRECISION = 77          # bits: what a careless caller might have left set


def mids(W):
    return np.array([[float(W[i, j].mid()) for j in range(W.ncols())] for i in range(W.nrows())])


def assert_balls_hold_float64(w_arb, w64):
    """Every ball is tight and its midpoint agrees with float64 to 1e-9 of W's scale."""
    assert (w_arb.nrows(), w_arb.ncols()) == w64.shape
    scale = max(1.0, float(np.abs(w64).max()))
    for i in range(w_arb.nrows()):
        for j in range(w_arb.ncols()):
            x = w_arb[i, j]
            assert float(x.rad()) < 1e-25 * scale
            assert abs(float(x.mid()) - w64[i, j]) <= 1e-9 * scale, (i, j)


# ----- the same states in three arithmetics ------------------------------------------------
@pytest.mark.parametrize("name", ["planar_2r", "puma560"])
def test_open_chain_same_states_same_W_in_float64_arb_and_exact(name):
    mech = resolve(name)
    states = random_rational_states(mech, 3, seed=11)
    assert any(isinstance(v, TanHalf) for state in states.z for v in state)
    w64, info = observation_matrix(mech, Float64(), states)
    w_arb, arb_info = observation_matrix(mech, Arb(DIGITS), states)
    w_exact, _ = observation_matrix(mech, Exact(), states)
    f = len(mech.independent)
    assert isinstance(w64, np.ndarray) and isinstance(w_arb, arb_mat) and isinstance(w_exact, fmpq_mat)
    assert w64.shape == (3 * f, len(mech.parameters)) and info["samples"] == arb_info["samples"] == 3
    assert_balls_hold_float64(w_arb, w64)
    for i in range(w_exact.nrows()):
        for j in range(w_exact.ncols()):
            q = w_exact[i, j]
            assert balls.contains_rational(w_arb[i, j], Fraction(int(q.p), int(q.q))), (i, j)
    # the exact solver's own W is the builder's at its random states
    assert exact_observation_matrix(mech, 3, seed=11) == w_exact


def test_tan_half_angles_are_the_same_angle_in_every_backend():
    angle = TanHalf(Fraction(-3, 7))
    c, s = angle.cos_sin()
    assert np.isclose(np.cos(Float64().number(angle)), float(Fraction(int(c.p), int(c.q))), rtol=1e-15)
    with ctx.workdps(DIGITS):
        x = Arb(DIGITS).number(angle)
        assert x.cos().contains(arb(c)) and x.sin().contains(arb(s))
    assert Exact().number(angle) is angle


@pytest.mark.parametrize("source", ["trajectory", "batch"])
def test_closed_loop_same_states_same_W_in_float64_and_arb(source):
    mech = resolve("four_bar")
    trajectory = Trajectory.default(mech, samples=9)
    states = trajectory if source == "trajectory" else random_batch(mech, trajectory, seed=5)
    w64, _ = observation_matrix(mech, Float64(), states)
    w_arb, info = observation_matrix(mech, Arb(DIGITS), states)
    assert info["positions_enclosed"]
    if source == "trajectory":
        assert Fraction(info["closure_residual"]) < Fraction(1, 10 ** (DIGITS - 5))
    assert_balls_hold_float64(w_arb, w64)


# ----- every source goes through the one builder -----------------------------------------------
def test_vectorised_float64_equals_state_after_state():
    """The fast path (all states at once) against states evaluated one at a time."""
    mech = resolve("four_bar")
    batch = random_batch(mech, Trajectory.default(mech), seed=3)
    W, _ = observation_matrix(mech, Float64(), batch)
    one_by_one = Float64().stack(*(
        observation_matrix(mech, Float64(), RationalStates((batch.z[k],), (batch.zd[k],), (batch.zdd[k],),
                                                            (batch.start[k],)))[0]
        for k in range(batch.count)))
    assert np.allclose(W, one_by_one, rtol=1e-12, atol=1e-12 * np.abs(W).max())


@pytest.mark.parametrize("name", ["four_bar", "planar_2r"])
def test_a_subsets_float64_sample_is_the_sources_at_its_states(name):
    """Subset.float64_sample (the States protocol) against the whole source's rows."""
    mech = resolve(name)
    trajectory = Trajectory.default(mech, samples=12)
    picked = (1, 4, 9)
    whole = trajectory.float64_sample(mech).regressor_array()
    some = observation.Subset(trajectory, picked).float64_sample(mech).regressor_array()
    assert some.shape == (3,) + whole.shape[1:]
    assert np.allclose(some, whole[list(picked)], rtol=1e-12, atol=1e-12 * np.abs(whole).max())


def test_trajectory_and_batch_rows_stack_alike_in_every_arithmetic():
    mech = resolve("four_bar")
    trajectory = Trajectory.default(mech, samples=6)
    batch = random_batch(mech, trajectory, seed=7919)
    assert isinstance(batch, RandomBatch) and batch.states == batch.count
    stacked = {}
    for backend in (Float64(), Arb(DIGITS)):
        W = backend.stack(observation_matrix(mech, backend, trajectory)[0],
                          observation_matrix(mech, backend, batch)[0])
        stacked[backend.name] = W
    assert stacked["float64"].shape == ((6 + batch.count) * len(mech.independent), len(mech.parameters))
    assert_balls_hold_float64(stacked["arb"], stacked["float64"])


def test_trajectory_wrapper_is_the_builder():
    mech = resolve("planar_2r")
    trajectory = Trajectory.default(mech, samples=5)
    assert np.array_equal(trajectory_matrix(mech, Float64(), trajectory)[0],
                          observation_matrix(mech, Float64(), trajectory)[0])
    default = Trajectory.default(mech)
    assert trajectory_matrix(mech, Float64())[0].shape == (default.count * 2, len(mech.parameters))


def test_progress_reports_every_state():
    mech = resolve("planar_2r")
    seen = []
    observation_matrix(mech, Arb(20), Trajectory.default(mech, samples=4), progress=lambda *a: seen.append(a))
    assert seen == [(1, 4), (2, 4), (3, 4), (4, 4)]


def test_evaluate_states_gives_the_samples_of_W():
    mech = resolve("four_bar")
    batch = random_batch(mech, Trajectory.default(mech), seed=2)
    samples = evaluate_states(mech, Arb(DIGITS), batch)
    W, _ = observation_matrix(mech, Arb(DIGITS), batch)
    rows = [row for s in samples for row in s.regressor()]
    with ctx.workdps(DIGITS):
        for i, row in enumerate(rows):
            for j, v in enumerate(row):
                assert W[i, j].overlaps(arb(v))


def test_matrices_and_stacking_per_backend():
    rows = [[fmpq(1, 3), fmpq(2)], [fmpq(-5, 7), fmpq(0)]]
    E = Exact().matrix(rows)
    assert Exact().stack(E, E).nrows() == 4 and Exact().stack(E, E)[3, 0] == fmpq(-5, 7)
    assert Exact().matrix([], 3).ncols() == 3 and Arb(20).matrix([], 3).nrows() == 0
    assert Float64().matrix([], 3).shape == (0, 3)
    with ctx.workdps(30):
        A = Arb(30).matrix([[arb(1) / 3, arb(2)]])
    assert Arb(30).stack(A, A).nrows() == 2 and Arb(30).stack(A, A)[1, 0].rad() == A[0, 0].rad()


def limited_pendulum():
    """The pendulum with a range its trajectory leaves."""
    text = open(resolve("pendulum").path).read()
    limited = text.replace('coordinates = ["theta"]', 'coordinates = ["theta"]\nlimits = { theta = ["-0.01", "0.01"] }')
    assert limited != text
    return parse_mechanism(limited, "limited_pendulum.toml")


@pytest.mark.parametrize("backend", [Float64(), Arb(DIGITS)], ids=["float64", "arb"])
def test_a_trajectory_error_names_the_file_and_the_trajectory(backend):
    with pytest.raises(KinematicsError, match=r"limited_pendulum.toml: trajectory: .*leaves its range"):
        observation_matrix(limited_pendulum(), backend, Trajectory.default(limited_pendulum(), samples=5))


# ----- precision is an explicit context --------------------------------------------------------
def _public_arb_calls():
    """(name, call) for every public function that computes in arb."""
    mech = resolve("four_bar")
    trajectory = Trajectory.default(mech, samples=8)
    batch = random_batch(mech, trajectory, seed=1)
    W, _ = observation_matrix(mech, Arb(DIGITS), trajectory)
    Wc, _ = observation_matrix(mech, Arb(DIGITS), batch)
    a = certify.analyse(W, DIGITS)
    x, y = a.beta[0, 0], a.beta[0, 1] if a.beta.ncols() > 1 else a.beta[0, 0]
    return [
        ("trajectory W", lambda: observation_matrix(mech, Arb(DIGITS), trajectory)),
        ("batch W", lambda: observation_matrix(mech, Arb(DIGITS), batch)),
        ("exact W", lambda: observation_matrix(resolve("planar_2r"), Exact(),
                                               random_rational_states(resolve("planar_2r"), 2))),
        ("evaluate_states", lambda: evaluate_states(mech, Arb(DIGITS), batch)),
        ("evaluator", lambda: Evaluator(mech, Arb(DIGITS))),
        ("sample and regressor", lambda: _one_sample_rows(mech, batch)),
        ("backend numbers", lambda: [Arb(DIGITS).rational(Fraction(1, 3)), Arb(DIGITS).pi(),
                                     Arb(DIGITS).number(TanHalf(Fraction(2, 9)))]),
        ("analyse", lambda: certify.analyse(W, DIGITS)),
        ("analyse imposed", lambda: certify.analyse(W, DIGITS, kept=a.kept)),
        ("excitation_check", lambda: balls.excitation_check(Wc, a)),
        ("tail_singular_values", lambda: balls.tail_singular_values(W, a)),
        ("log10", lambda: certify.log10(x)),
        ("radius_digits", lambda: balls.radius_digits(x)),
        ("agreement_digits", lambda: balls.agreement_digits(x, y)),
        ("decimal_string", lambda: certify.decimal_string(x, 20)),
        ("recover_rational", lambda: balls.recover_rational(x, 20)),
        ("contains_rational", lambda: balls.contains_rational(x, Fraction(1, 3))),
        ("ridge_log10", lambda: a.ridge_log10),
    ]


def _one_sample_rows(mech, batch):
    """Evaluator.sample and Sample.regressor called directly, with no precision entered."""
    backend = Arb(DIGITS)
    z, zd, zdd = batch.values(mech, backend, 0)
    sample = Evaluator(mech, backend, certify=True).sample(z, zd, zdd, [backend.number(v) for v in batch.start[0]])
    return [arb_mat([row]) for row in sample.regressor()]


def test_every_public_arb_function_restores_the_precision():
    for name, call in _public_arb_calls():
        saved = ctx.prec
        try:
            ctx.prec = ODD_PRECISION
            call()
            assert ctx.prec == ODD_PRECISION, name
        finally:
            ctx.prec = saved


def test_results_do_not_depend_on_the_callers_precision():
    """The same call under a low and a high leftover precision gives identical balls."""
    def text(result):
        if isinstance(result, tuple):
            return tuple(text(r) for r in result)
        if isinstance(result, arb_mat):
            return [[result[i, j].str(60) for j in range(result.ncols())] for i in range(result.nrows())]
        if isinstance(result, certify.BallAnalysis):
            return (result.rank, result.kept, text(result.beta), result.tail_bound.str(30),
                    result.sigma_r_lower.str(30), result.ridge_log10)
        if isinstance(result, arb):
            return result.str(60)
        if isinstance(result, Sample):
            return text(result.q), text(result.qdd), text(result.regressor())
        if isinstance(result, dict):
            return {k: text(v) for k, v in result.items()}
        if isinstance(result, list):
            return [text(v) for v in result]
        return result

    saved = ctx.prec
    try:
        outcomes = []
        for leftover in (20, 2000):
            ctx.prec = leftover
            outcomes.append({name: text(call()) for name, call in _public_arb_calls() if name != "evaluator"})
    finally:
        ctx.prec = saved
    assert outcomes[0] == outcomes[1]
    try:
        ctx.prec = 20
        third = Arb(DIGITS).rational(Fraction(1, 3))
    finally:
        ctx.prec = saved
    assert 0 < third.rad() < arb(10) ** -(DIGITS - 1)          # born at 40 digits, not at 20 bits


def test_precision_is_restored_after_an_error():
    mech = limited_pendulum()
    saved = ctx.prec
    try:
        ctx.prec = ODD_PRECISION
        with pytest.raises(KinematicsError):
            observation_matrix(mech, Arb(DIGITS), Trajectory.default(mech, samples=5))
        assert ctx.prec == ODD_PRECISION
        with pytest.raises(RuntimeError):
            with ctx.workdps(DIGITS):
                raise RuntimeError
        assert ctx.prec == ODD_PRECISION
    finally:
        ctx.prec = saved


def test_precision_context_nests_and_takes_bits():
    saved = ctx.prec
    with ctx.workdps(50):
        outer = ctx.prec
        with ctx.workprec(300):
            assert ctx.prec == 300
        assert ctx.prec == outer
    assert ctx.prec == saved
    with Arb(100).activate():
        assert ctx.dps == 100
    assert ctx.prec == saved


def test_no_module_reexports_the_removed_builders():
    from baseparams.dynamics import excitation, trajectory
    assert not hasattr(excitation, "batch_matrix") and not hasattr(excitation, "stack_rows")
    assert observation.observation_matrix is not None and hasattr(trajectory, "samples_float64")
