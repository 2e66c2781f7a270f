"""The planar-loop generator (condition 7, plugins/solvers/symbolic/loop_transfers.py).

A cycle of R joints with parallel axes b whose bodies all move (its base rotates in
space) has a null vector that is neither a body condition nor a sum of joint transfers:
the quadrupoles ``b (b x a_k)^T + (b x a_k) b^T`` on every body k of the loop (a_k the
link vector between the body's two loop joints), null by the loop closure
(docs/symbolic.md, "Planar loops on a moving base"). Without it the symbolic count on
ladders of four-bars (``baseparams.model.generate.ladder``) was one too high per four-bar
mounted on a moving body: an honest upper bound, not a certificate.

Checked here: the generator is a null vector of W at 60 digits on random states,
independently of the solver's certificate, and is not in the span of the other
generators; with it the solver is certified on ladders of several seeds with vp's rank
and row space; without it the result is still an upper bound (never a false
certificate); loops through ground add nothing (their vectors are body conditions) and
no built-in mechanism has a planar loop off ground, so their results are unchanged;
a planar loop with a prismatic joint is not covered and stays an upper bound.
"""

from fractions import Fraction

import pytest
from flint import arb, arb_mat, fmpq

from baseparams import registry
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model.generate import ladder
from baseparams.numeric.backends import Arb
from baseparams.plugins.solvers.symbolic import elimination, loop_transfers
from baseparams.solvers.compare import same_row_space


BUILT_IN = ("pendulum", "planar_2r", "four_bar", "slider_crank", "scara", "puma560", "sla_suspension",
            "stewart_platform")


def _ladder(n, seed=1):
    return parse_mechanism(ladder(n, seed), f"ladder_{n}_{seed}.toml")


def _solve(name, mech):
    return registry.solvers()[name].item.solve(mech)


def _same_row_space_as_vp(sym, vp):
    """vp's recovered rationals exactly, else its trusted decimals (large denominators)."""
    rows = sym.coefficient_matrix(values=True)
    rec = vp.diagnostics["rational_recovery"]
    if rec.get("succeeded"):
        return same_row_space(rows, [[Fraction(row["expression"].get(p, "0")) for p in vp.parameters]
                                     for row in rec["base"]])
    return same_row_space(vp.coefficient_matrix(), rows, tol=1e-12)


def test_the_ladders_cycles_are_found():
    mech = _ladder(3, 2)
    gens = loop_transfers.planar_loop_generators(mech)
    # four-bar 0 stands on ground (skipped); four-bars 1 and 2 stand on moving rockers
    assert [sorted(g.bodies) for g in gens] == [[3, 4, 5, 6], [6, 7, 8, 9]]
    assert [g.joint.name for g in gens] == ["JC1", "JC2"]
    assert all(g.condition == loop_transfers.CONDITION == 7 for g in gens)
    # only products of inertia with the axis: no mass, no first moment
    assert all(p[0] == "I" for g in gens for p in g.vector)


def test_the_loop_generator_is_a_null_vector_outside_the_other_generators_span():
    mech = _ladder(2)
    (gen,) = loop_transfers.planar_loop_generators(mech)
    params = list(mech.parameters)
    backend = Arb(60)
    batch = random_batch(mech, Trajectory.default(mech), seed=11)
    W, _ = observation_matrix(mech, backend, batch)
    with backend.activate():
        n = arb_mat(len(params), 1)
        for p, v in gen.vector.items():
            n[params.index(p), 0] = arb(fmpq(int(v.p), int(v.q)))
        res = (W * n).entries()
        wmax = max(abs(float(x.mid())) for x in W.entries())
        assert all(x.contains(0) for x in res)
        assert max(float(x.abs_upper()) for x in res) < 1e-50 * wmax
    # not implied by the body conditions and joint transfers: the derivation keeps it
    der = elimination.eliminate(mech)
    (step,) = [s for s in der.steps if s.generator.condition == loop_transfers.CONDITION]
    assert step.generator.vector == gen.vector and step.vector


@pytest.mark.parametrize("n, seed", [(2, 1), (2, 2), (2, 3), (3, 2)])
def test_ladders_are_certified_with_vps_rank_and_row_space(n, seed):
    mech = _ladder(n, seed)
    sym, vp = _solve("symbolic", mech), _solve("vp", mech)
    assert vp.certified
    assert sym.certified and not sym.rank_is_upper_bound, sym.warnings
    assert sym.rank == vp.rank == 8 + 18 * (n - 1)
    assert _same_row_space_as_vp(sym, vp)


def test_without_the_loop_generator_the_count_is_an_upper_bound(monkeypatch):
    """The behaviour before condition 7 (and of loops it does not cover, e.g. with
    prismatic joints): one too many per planar loop on a moving base, never certified."""
    monkeypatch.setattr(elimination, "planar_loop_generators", lambda mechanism: [])
    res = _solve("symbolic", _ladder(2))
    assert res.rank == 27 and not res.certified and res.rank_is_upper_bound
    assert res.diagnostics["certificate"]["rank_lower_bound"] == 26


def test_loops_through_ground_and_the_built_ins_add_nothing():
    assert loop_transfers.planar_loop_generators(_ladder(1)) == []
    for name in BUILT_IN:
        assert loop_transfers.planar_loop_generators(resolve(name)) == [], name


# a slider-crank (mechanisms/slider_crank.toml) on a turntable: a planar loop with a P joint
SLIDER_CRANK_ON_TURNTABLE = """[mechanism]
name = "slider_crank_on_turntable"
title = "slider-crank on a rotating base"
gravity = ["0", "0", "-9.81"]

[geometry]
R1 = "0.1"
L2 = "0.325"

[[bodies]]
label = 1
mass = "2"
com = ["0.05", "0.02", "0.1"]
inertia_com = ["0.01", "0", "0", "0.02", "0", "0.015"]

[[bodies]]
label = 2
mass = "1"
com = ["R1/2", "0", "0"]
inertia_com = ["0.00005", "0", "0", "R1**2/12", "0", "R1**2/12"]

[[bodies]]
label = 3
mass = "0.5"
com = ["0.35*L2", "0", "0"]
inertia_com = ["0.000025", "0", "0", "0.5*L2**2/12", "0", "0.5*L2**2/12"]

[[bodies]]
label = 4
mass = "1.5"
com = ["0", "0", "0"]
inertia_com = ["0.000625", "0", "0", "0.0011125", "0", "0.0011125"]

[[joints]]
name = "J0"
type = "R"
parent = 0
child = 1
coordinates = ["q0"]
parent_frame = { point = ["0", "0", "0"], axis = ["3", "4", "0"], ref = ["0", "0", "1"] }
child_frame  = { point = ["0.1", "-0.2", "0.05"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }

[[joints]]
name = "J1"
type = "R"
parent = 1
child = 2
coordinates = ["q1"]
parent_frame = { point = ["0", "0", "0"], axis = ["0", "-1", "0"], ref = ["0.6", "0", "0.8"] }
child_frame  = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }

[[joints]]
name = "J2"
type = "R"
parent = 2
child = 3
coordinates = ["q2"]
parent_frame = { point = ["R1", "0", "0"], axis = ["0", "0", "1"], ref = ["5/13", "-12/13", "0"] }
child_frame  = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }

[[joints]]
name = "J3"
type = "P"
parent = 1
child = 4
coordinates = ["s"]
parent_frame = { point = ["3*R1/5 + 63*L2/65", "0", "0"], axis = ["1", "0", "0"], ref = ["0", "0", "1"] }
child_frame  = { point = ["0", "0", "0"], axis = ["1", "0", "0"], ref = ["0", "0", "1"] }

[[joints]]
name = "J4"
type = "R"
parent = 3
child = 4
coordinates = ["q4"]
loop = true
parent_frame = { point = ["L2", "0", "0"], axis = ["0", "0", "1"], ref = ["63/65", "16/65", "0"] }
child_frame  = { point = ["0", "0", "0"], axis = ["0", "-1", "0"], ref = ["1", "0", "0"] }

[coordinates]
independent = ["q0", "q1"]

[trajectory]
t_start = "0"
t_end = "10"
samples = 100
q = { q0 = "0.7*sin(1.1*t) + 0.3*sin(2.9*t)", q1 = "0.9*sin(1.7*t) + 0.4*sin(4.3*t)" }
"""


def test_a_planar_loop_with_a_prismatic_joint_stays_an_upper_bound():
    """Known limit (docs/symbolic.md): loops with P joints have loop-level dependencies
    that are not generated (two here); the count is an upper bound, never certified."""
    mech = parse_mechanism(SLIDER_CRANK_ON_TURNTABLE, "slider_crank_on_turntable.toml")
    assert loop_transfers.planar_loop_generators(mech) == []
    sym, vp = _solve("symbolic", mech), _solve("vp", mech)
    assert vp.certified and vp.rank == 16
    assert sym.rank == 18 and not sym.certified and sym.rank_is_upper_bound
    assert sym.diagnostics["certificate"]["rank_lower_bound"] == 16


def test_the_cycle_basis_walks_each_loop_once():
    mech = _ladder(2)
    joints = [j for j in mech.joints if loop_transfers.is_revolute(j)]
    frames = {j.name: loop_transfers.joint_frames(mech, j) for j in joints}
    axes = {j.name: {b: loop_transfers.map_direction(frames[j.name][b], loop_transfers.Z)
                     for b in (j.parent, j.child)} for j in joints}
    groups = loop_transfers._groups(mech, joints, axes)
    cycles = [c for g in groups for c in loop_transfers._cycles(g)]
    assert len(cycles) == 2                       # one per four-bar (the first through ground)
    for closing, cycle in cycles:
        bodies = [b for b, _, _ in cycle]
        assert len(bodies) == len(set(bodies)) == 4
        # consecutive entries share the joint: out of one body, into the next
        for (b1, _, out), (b2, into, _) in zip(cycle, cycle[1:] + cycle[:1]):
            assert out is into and {b1, b2} == {out.parent, out.child}


def test_the_report_says_the_loop_step_is_spread_over_the_loop():
    from baseparams.cli.report import render
    text = render(elimination.solve(_ladder(2)), "text")
    (line,) = [ln for ln in text.splitlines() if "planar-loop" in ln]
    assert line.startswith("- Loop closed by joint") and "spread over its bodies" in line
    assert "moved from" not in line
