"""Every multipole-transfer rule of every joint type, as a null vector of the regressor.

For each built-in mechanism and each joint (tree or loop-closing) whose type has rules,
the rule is mapped into both bodies' frames (baseparams.dynamics.transfers), the geometry
substituted exactly, and K n is evaluated at 60 digits on random states: a rule is a
null direction when |K n| / (|K| |n|) < 1e-40. The seed's condition 3 (a dipole along a
prismatic joint's sliding axis) is shown NOT to be one, with the Lagrangian change
predicted in docs/symbolic.md.
"""

import random
from fractions import Fraction

import numpy as np
import pytest
from flint import arb, fmpq

from baseparams import registry
from baseparams.numeric.backends import Arb, Float64
from baseparams.dynamics.evaluator import Evaluator
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.transfers import dipole_params, joint_frames, numeric_vector, rule_generators

DIGITS = 60
STATES = 3

# A rigid (Fixed) connection is used by no built-in mechanism: this arm welds body 3 to
# body 2 with a rotated frame and an offset, under a tilted gravity.
FIXED_ARM = """
[mechanism]
name = "fixed_arm"
gravity = ["1", "-2", "-9"]
[geometry]
L1 = "0.7"
A = "0.2"
B = "0.3"
[[bodies]]
label = 1
[[bodies]]
label = 2
[[bodies]]
label = 3
[[joints]]
name = "J1"
type = "R"
parent = 0
child = 1
coordinates = ["q1"]
parent_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }
[[joints]]
name = "J2"
type = "U"
parent = 1
child = 2
coordinates = ["q2", "q3"]
parent_frame = { point = ["L1", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }
child_frame = { point = ["0", "A", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }
[[joints]]
name = "W"
type = "Fixed"
parent = 2
child = 3
parent_frame = { point = ["A", "B", "0"], axis = ["3", "4", "0"], ref = ["0", "0", "1"] }
child_frame = { point = ["0", "-B", "A"], axis = ["0", "0", "1"], ref = ["0", "1", "0"] }
"""


def mechanisms():
    mechs = [resolve(name) for name in registry.mechanisms()]
    return mechs + [parse_mechanism(FIXED_ARM, "fixed_arm.toml")]


MECHANISMS = {m.name: m for m in mechanisms()}


def random_regressors(mech, count=STATES, digits=DIGITS, seed=7):
    """Regressors (lists of rows, arb) at random rational states on the constraint manifold."""
    rng = random.Random(seed)
    names = mech.independent or mech.coordinates
    f = len(names)
    backend = Arb(digits)
    ev = Evaluator(mech, backend)
    out = []
    if mech.loops:                      # stay on the trajectory's branch: its positions, random times
        traj = Trajectory.default(mech)
        t0, t1 = float(traj.times[0]), float(traj.times[-1])
        times = np.array([t0 + (t1 - t0) * rng.random() for _ in range(count)])
        z, _, _ = traj.independent_values(mech, Float64(), times)
        zs = [[Fraction(float(np.atleast_1d(v)[k])).limit_denominator(10 ** 8) for v in z] for k in range(count)]
        guess = Evaluator(mech, Float64()).assemble([np.array([float(zs[k][j]) for k in range(count)])
                                                     for j in range(f)])
    else:
        zs = [[Fraction(rng.randint(-900, 900), 1000) for _ in range(f)] for _ in range(count)]
    with backend.activate():
        for k in range(count):
            r = lambda v: arb(fmpq(v.numerator, v.denominator))  # noqa: E731
            z = [r(v) for v in zs[k]]
            zd = [r(Fraction(rng.randint(-1000, 1000), 500)) for _ in range(f)]
            zdd = [r(Fraction(rng.randint(-1000, 1000), 500)) for _ in range(f)]
            g = None
            if mech.loops:
                g = [r(Fraction(float(np.atleast_1d(v)[k]))) for v in guess]
            sample = ev.sample(z, zd, zdd, g)
            out.append((sample, sample.regressor()))
    return out


_CACHE = {}


def regressors(name):
    if name not in _CACHE:
        _CACHE[name] = random_regressors(MECHANISMS[name])
    return _CACHE[name]


def relative_residual(rows, n):
    """max |K n| / (max |K| * max |n|) as a float upper bound."""
    with Arb(DIGITS).activate():
        vec = [arb(fmpq(x.numerator, x.denominator)) for x in n]
        worst = 0.0
        kmax = max(float(abs(v).upper()) for row in rows for v in row)
        for row in rows:
            total = arb(0)
            for a, b in zip(row, vec):
                total += a * b
            worst = max(worst, float(abs(total).upper()))
    return worst / (kmax * float(max(abs(x) for x in n)))


def rule_cases():
    cases = []
    for name, mech in MECHANISMS.items():
        for joint in mech.joints:
            rules = registry.transfer_rules(joint.type.name) or []
            for k, rule in enumerate(rules):
                cases.append(pytest.param(name, joint.name, k, id=f"{name}-{joint.name}-{rule.multipole}{k}"))
    return cases


@pytest.mark.parametrize("name, joint_name, index", rule_cases())
def test_rule_is_a_null_vector(name, joint_name, index):
    mech = MECHANISMS[name]
    joint = next(j for j in mech.joints if j.name == joint_name)
    rule = registry.transfer_rules(joint.type.name)[index]
    gens = rule_generators(mech, joint, rule)
    assert gens and all(g.vector for g in gens)
    for gen in gens:
        n = numeric_vector(gen, mech)
        assert all(isinstance(x, Fraction) for x in n)
        for _, rows in regressors(name):
            assert relative_residual(rows, n) < 1e-40, (name, joint_name, gen.label)


def test_every_builtin_rule_is_exercised():
    """Each rule of R, P, S, U and Fixed appears at some joint of the mechanisms above."""
    used = {j.type.name for m in MECHANISMS.values() for j in m.joints}
    for type_name in ("R", "P", "S", "U", "Fixed"):
        assert type_name in used, type_name
        assert registry.transfer_rules(type_name), type_name


def test_loop_joints_get_rules_too():
    """Which bodies meet at loop-closing joints; their rules are generators like any other."""
    loops = {name: sorted((j.name, j.parent, j.child) for j in m.loops) for name, m in MECHANISMS.items()
             if m.loops}
    assert loops["sla_suspension"] == [("J23", 2, 3), ("J43", 4, 3), ("J71", 7, 1)]
    assert loops["four_bar"] == [("JC", 2, 3)]
    assert loops["slider_crank"] == [("J4", 2, 3)]
    for name, joints in loops.items():
        mech = MECHANISMS[name]
        for jname, _, _ in joints:
            joint = next(j for j in mech.joints if j.name == jname)
            assert registry.transfer_rules(joint.type.name), (name, jname)


def test_condition_3_dipole_along_a_prismatic_axis_is_not_null():
    """SLA damper J67 (P): a dipole along the sliding axis changes the Lagrangian by
    Delta L = -s |Omega x z|^2 d (docs/symbolic.md), so it is not a null direction."""
    mech = MECHANISMS["sla_suspension"]
    joint = next(j for j in mech.joints if j.name == "J67")
    frames = joint_frames(mech, joint)
    n_sym = {}
    for body, sign in ((joint.parent, 1), (joint.child, -1)):
        r, p = frames[body]
        values = dipole_params([p[i] for i in range(3)], [r[i][2] for i in range(3)])
        i = mech.body_labels.index(body)
        for k, v in enumerate(values):
            n_sym[mech.parameters[10 * i + k]] = sign * v
    import sympy
    subs = mech.geometry_subs
    n = []
    for p in mech.parameters:
        v = sympy.simplify(sympy.sympify(n_sym.get(p, 0)).subs(subs))
        n.append(Fraction(int(v.p), int(v.q)))
    s_index = mech.coordinates.index("damper_s")
    for sample, rows in regressors("sla_suspension"):
        assert relative_residual(rows, n) > 1e-4          # clearly not null
        with Arb(DIGITS).activate():
            t_form, v_form = sample.energies()
            vec = [arb(fmpq(x.numerator, x.denominator)) for x in n]
            delta = sum((t - v) * x for t, v, x in zip(t_form, v_form, vec))
            st = sample.states[joint.parent]
            z = [st.rot[i][2] for i in range(3)]
            w = st.w
            cross = [w[1] * z[2] - w[2] * z[1], w[2] * z[0] - w[0] * z[2], w[0] * z[1] - w[1] * z[0]]
            predicted = -sample.q[s_index] * sum(c * c for c in cross)
            assert abs(float((delta - predicted).mid())) < 1e-40 * max(1.0, abs(float(predicted.mid())))
            assert abs(float(predicted.mid())) > 1e-6
