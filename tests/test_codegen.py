"""The generated regressor (baseparams.dynamics.codegen) against the generic recursion it is
traced from, against Pinocchio, and in every arithmetic it runs in.

The generic code (:mod:`baseparams.dynamics.regressor` on :mod:`baseparams.kinematics.tree`)
is the definition; the generated code must give the same K: float64 to 1e-12 relative (it
skips exact multiplications by 0 and 1 and rounds each constant once), arb balls that
overlap the generic ones, rationals exactly equal. Pinocchio's regressor is an independent
implementation (spatial algebra, C++).
"""

import importlib.util
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy
from flint import fmpq

from baseparams.dynamics import codegen
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.regressor import generic_tree_regressor, tree_regressor_array
from baseparams.dynamics.trajectory import Trajectory, observation_matrix, samples_float64
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.numeric.backends import Arb, Exact, Float64, TanHalf

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_regressor.py"


def open_mechanisms():
    return ([("puma560", resolve("puma560"))]
            + [(f"chain {s}", parse_mechanism(generate.serial_chain(s, bodies=5, spherical=0.2))) for s in (1, 2, 3)]
            + [(f"tree {s}", parse_mechanism(generate.tree(s, bodies=6))) for s in (1, 4)])


def closed_mechanisms():
    return ([(f"four-bar {s}", parse_mechanism(generate.four_bar(s, samples=20))) for s in (1, 2)]
            + [("sla_suspension", resolve("sla_suspension"))])


def random_states(n, count, seed):
    rng = np.random.default_rng(seed)
    return [list(rng.uniform(-2.0, 2.0, (n, count))) for _ in range(3)]


def assert_close(a, b):
    scale = max(1.0, float(np.abs(b).max()))
    assert a.shape == b.shape
    assert np.abs(a - b).max() <= 1e-12 * scale


@pytest.mark.parametrize("label,mech", open_mechanisms(), ids=lambda x: x if isinstance(x, str) else "")
def test_float64_tree_regressor_equals_the_generic_one(label, mech):
    ev = Evaluator(mech, Float64())
    q, qd, qdd = random_states(len(mech.coordinates), 300, seed=len(label))
    sample = ev.sample(q, qd, qdd)
    generic = tree_regressor_array(ev.kin, sample.states, sample.qdd)
    generated = codegen.tree_regressor(mech, q, qd, qdd)
    assert_close(generated, generic)
    # scalars and a batch shape of two axes broadcast like the generic code
    one = codegen.tree_regressor(mech, [v[0] for v in q], [v[0] for v in qd], [v[0] for v in qdd])
    assert_close(one, generic[0])


@pytest.mark.parametrize("label,mech", closed_mechanisms(), ids=lambda x: x if isinstance(x, str) else "")
def test_closed_loop_terms_and_projected_regressor(label, mech):
    traj = Trajectory.default(mech, samples=40)
    sample, _ = samples_float64(mech, traj)
    kin = sample.kin
    # closure values, Jacobian and bias: the generated ones against TreeKinematics.closure
    values, rows, _ = kin.closure(kin.forward(sample.q))
    _, _, bias = kin.closure(kin.forward(sample.q, sample.qd), want_bias=True)
    g_values, g_rows = codegen.closure(mech, sample.q)
    g_bias = codegen.closure_bias(mech, sample.q, sample.qd)
    stack = lambda xs: np.array([np.broadcast_to(x, (40,)) for x in xs])  # noqa: E731
    assert_close(stack(g_values), stack(values))
    assert_close(np.array([stack(r) for r in g_rows]), np.array([stack(r) for r in rows]))
    assert_close(stack(g_bias), stack(bias))
    # K_tree, and K = R^T K_tree as Sample.regressor_array builds it from the generated code
    generic = tree_regressor_array(kin, sample.states, sample.qdd)
    assert_close(codegen.tree_regressor(mech, sample.q, sample.qd, sample.qdd), generic)
    r = np.stack([np.stack([np.broadcast_to(v, (40,)) for v in row], axis=-1) for row in sample.projection], axis=-2)
    codegen.compiled(mech, "regressor")          # compiled: regressor_array now uses it
    assert_close(sample.regressor_array(), np.einsum("...kf,...kp->...fp", r, generic))


def test_arb_balls_overlap_the_generic_ones_and_stay_tight():
    mech = parse_mechanism(generate.tree(5, bodies=5, irrational=0.5))
    backend = Arb(40)
    ev = Evaluator(mech, backend)
    with backend.activate():
        z = [backend.rational(Fraction(k + 1, 7)) for k in range(len(mech.coordinates))]
        sample = ev.sample(z, [-v for v in z], [v * 3 for v in z])
        generic = generic_tree_regressor(ev.kin, sample.states, sample.qdd)
        generated = codegen.scalar_tree_regressor(mech, backend, sample.q, sample.qd, sample.qdd)
        for row_a, row_b in zip(generated, generic):
            for a, b in zip(row_a, row_b):
                assert a.overlaps(b)
                assert float(a.rad()) <= 1e-30 * max(1.0, float(abs(b.mid())))


def test_rational_regressor_is_exactly_the_generic_one():
    mech = parse_mechanism(generate.serial_chain(6, bodies=5))
    backend = Exact()
    ev = Evaluator(mech, backend)
    coords = mech.coordinates
    kinds = {c: mech.joint_of_coordinate(c).type.name for c in coords}
    z = [TanHalf(Fraction(k + 1, 5)) if kinds[c] == "R" else fmpq(k + 1, 9) for k, c in enumerate(coords)]
    zd = [fmpq(2 * k - 3, 4) for k in range(len(coords))]
    zdd = [fmpq(5 - k, 3) for k in range(len(coords))]
    sample = ev.sample(z, zd, zdd)
    generic = generic_tree_regressor(ev.kin, sample.states, sample.qdd)
    generated = codegen.scalar_tree_regressor(mech, backend, sample.q, sample.qd, sample.qdd)
    assert generated == generic
    assert sample.regressor() == generic                # the solvers' path is the generated one


def test_generated_regressor_equals_pinocchio_on_the_puma():
    pin = pytest.importorskip("pinocchio")
    spec = importlib.util.spec_from_file_location("bench_regressor", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    mech = resolve("puma560")
    model = bench.pinocchio_model(mech)
    q, qd, qdd = bench.states(6, 50, seed=3)
    ours = bench.ours(mech, q, qd, qdd)[:, :, bench.pin_columns(6)]
    theirs = bench.pinocchio_batch(model, model.createData(), q, qd, qdd)
    assert pin is not None and np.abs(ours - theirs).max() <= 1e-10 * np.abs(theirs).max()


def test_float64_observation_matrix_uses_the_generated_code_once_compiled():
    mech = resolve("puma560")
    traj = Trajectory.default(mech, samples=30)
    codegen._CACHE.pop((mech, "regressor"), None)
    before, _ = observation_matrix(mech, Float64(), traj)      # 30 samples: the generic path
    assert (mech, "regressor") not in codegen._CACHE
    codegen.compiled(mech, "regressor")
    after, _ = observation_matrix(mech, Float64(), traj)
    assert_close(after, before)


# ----- the numpy flavour's form: rows written in place, chunks, no clobbered inputs ----------
def numpy_mechanisms():
    return ([(f"chain {s}", parse_mechanism(generate.serial_chain(s, bodies=6, spherical=0.3, zero_offset=0.5)))
             for s in (4, 5)]
            + [("prismatic chain", parse_mechanism(generate.serial_chain(8, bodies=4, types="P"))),
               ("tree 7", parse_mechanism(generate.tree(7, bodies=7, spherical=0.3)))])


@pytest.mark.parametrize("label,mech", numpy_mechanisms(), ids=lambda x: x if isinstance(x, str) else "")
def test_numpy_kernel_equals_the_scalar_kernel_in_python_floats(label, mech):
    """The numpy code (preallocated rows, outputs written in place, work rows reused) and the
    scalar code (one value per name, no aliasing) are written independently from one trace:
    the same float64 operations state by state, so they agree to rounding of cos/sin."""
    namespace, lays, values = codegen._scalar_module(mech, "regressor")
    constants = [float(sympy.N(v, 30)) for v in values]
    layout = lays["_tree_regressor"]["K"]
    n, p = layout.shape
    q, qd, qdd = (np.array(v) for v in random_states(n, 25, seed=11))
    generated = codegen.tree_regressor(mech, list(q), list(qd), list(qdd))
    for s in range(25):
        buffer = [None] * len(layout.slots)
        namespace["_tree_regressor"](list(q[:, s]), list(qd[:, s]), list(qdd[:, s]), constants,
                                     (math.cos, math.sin), buffer)
        flat = np.zeros(n * p)
        flat[list(layout.slots)] = buffer
        for slot, v in layout.constants:
            flat[slot] = float(v)
        assert_close(generated[s], flat.reshape(n, p))


@pytest.mark.parametrize("label,mech", numpy_mechanisms()[:2] + closed_mechanisms()[:1],
                         ids=lambda x: x if isinstance(x, str) else "")
def test_chunks_give_the_same_bits_and_leave_the_inputs_alone(label, mech):
    """A batch evaluated in several chunks (the last one partial) equals the one-chunk result
    exactly (elementwise operations, sample by sample) and the generic code to 1e-12; the
    kernels write only their own rows, never the caller's arrays."""
    n = len(mech.coordinates)
    x = np.random.default_rng(5).uniform(-2.0, 2.0, (3, n, 700))
    kept = x.copy()
    part = "closure" if mech.loops else "regressor"
    kernel = "_closure" if mech.loops else "_tree_regressor"
    module = codegen.compiled(mech, part)
    inputs = [x[0]] if mech.loops else list(x)
    whole = module["_evaluate"](kernel, inputs)
    budget = module["_BUDGET"]
    try:
        module["_BUDGET"] = 1            # every chunk the smallest: 256 samples, 3 passes
        chunked = module["_evaluate"](kernel, inputs)
    finally:
        module["_BUDGET"] = budget
    assert np.array_equal(x, kept)
    for a, b in zip(whole, chunked):
        assert np.array_equal(a, b)
    if mech.loops:
        kin = Evaluator(mech, Float64()).kin
        values, rows, _ = kin.closure(kin.forward(list(x[0])))
        assert_close(whole[0], np.stack([np.broadcast_to(v, (700,)) for v in values], axis=-1))
        assert_close(whole[1], np.stack([np.stack([np.broadcast_to(v, (700,)) for v in row], axis=-1)
                                         for row in rows], axis=-2))
    else:
        ev = Evaluator(mech, Float64())
        sample = ev.sample(*(list(v) for v in x))
        assert_close(whole[0], tree_regressor_array(ev.kin, sample.states, sample.qdd))


def test_work_rows_are_far_fewer_than_operations():
    """Work rows are reused once their value's last reader has run: a 12-body chain's
    temporaries stay a fraction of its operations (each row is chunk x 8 bytes)."""
    mech = parse_mechanism(generate.serial_chain(3, bodies=12))
    graph, kernels = codegen.trace(mech, ("regressor",))
    source, work = codegen._numpy_kernel(graph, kernels[0], codegen.Constants())
    operations = source.count("\n    _")
    assert 0 < work < operations / 4
    assert f"w{work - 1}" in source and f"w{work}," not in source
