"""Joint transforms against hand-computed values, and the four backends against each other."""

import math
import random
from fractions import Fraction

import numpy as np
import pytest
import sympy
from flint import arb, fmpq

from baseparams import registry
from baseparams.numeric.backends import Arb, Exact, Float64, Symbolic, TanHalf
from baseparams.dynamics.evaluator import Evaluator
from baseparams.io.loader import resolve

F = Fraction
JOINTS = registry.joint_types()


def exact_transform(name, tans, lengths=()):
    """Transform of joint ``name`` in the Exact backend; angles as tan(theta/2)."""
    jt = JOINTS[name].item
    values, ti, li = [], iter(tans), iter(lengths)
    for kind in jt.coordinate_kinds:
        values.append(TanHalf(next(ti)) if kind == "angle" else Exact().rational(next(li)))
    return jt.transform(values, Exact())


def as_fractions(m):
    return [[F(int(v.p), int(v.q)) for v in row] for row in m]


def test_revolute_quarter_turn_by_hand():
    rot, pos = exact_transform("R", [F(1)])           # tan(45 deg) = 1: 90 degrees about z
    assert as_fractions(rot) == [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert [F(int(v.p), int(v.q)) for v in pos] == [0, 0, 0]


def test_prismatic_translates_along_z():
    rot, pos = exact_transform("P", [], [F(3, 7)])
    assert as_fractions(rot) == [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    assert [F(int(v.p), int(v.q)) for v in pos] == [0, 0, F(3, 7)]


def test_universal_by_hand():
    # tan(a/2) = 1/2: cos a = 3/5, sin a = 4/5 about z; tan(b/2) = 2/3: cos b = 5/13, sin b = 12/13 about x
    rot, _ = exact_transform("U", [F(1, 2), F(2, 3)])
    assert as_fractions(rot) == [[F(3, 5), F(-4, 13), F(48, 65)],
                                 [F(4, 5), F(3, 13), F(-36, 65)],
                                 [0, F(12, 13), F(5, 13)]]


def test_spherical_by_hand():
    # a = 90 deg about x, then b = 90 deg about y, then c = 0: x -> x, the new y is old z ...
    rot, _ = exact_transform("S", [F(1), F(1), F(0)])
    # Rx(90) Ry(90) = [[0,0,1],[1,0,0],[0,1,0]]
    assert as_fractions(rot) == [[0, 0, 1], [1, 0, 0], [0, 1, 0]]


def test_fixed_is_identity():
    rot, pos = exact_transform("Fixed", [])
    assert as_fractions(rot) == [[1, 0, 0], [0, 1, 0], [0, 0, 1]]


@pytest.mark.parametrize("name", sorted(JOINTS))
def test_backends_agree_on_joint_transforms(name):
    jt = JOINTS[name].item
    rng = random.Random(7)
    for _ in range(3):
        tans = [F(rng.randint(-90, 90), 37) for _ in range(jt.dof)]
        lengths = [F(rng.randint(-90, 90), 53) for _ in range(jt.dof)]
        angles = [2 * math.atan(float(t)) for t in tans]
        exact_vals = [TanHalf(t) if k == "angle" else fmpq(l.numerator, l.denominator)
                      for t, l, k in zip(tans, lengths, jt.coordinate_kinds)]
        ref_rot, ref_pos = jt.transform(exact_vals, Exact())
        ref = [float(int(v.p)) / float(int(v.q)) for row in ref_rot for v in row] + \
              [float(int(v.p)) / float(int(v.q)) for v in ref_pos]
        f_vals = [a if k == "angle" else float(l) for a, l, k in zip(angles, lengths, jt.coordinate_kinds)]
        rot, pos = jt.transform(f_vals, Float64())
        assert np.allclose([v for row in rot for v in row] + list(pos), ref, atol=1e-14)
        backend = Arb(50)
        with backend.activate():
            a_vals = [2 * arb(fmpq(t.numerator, t.denominator)).atan() if k == "angle"
                      else arb(fmpq(l.numerator, l.denominator))
                      for t, l, k in zip(tans, lengths, jt.coordinate_kinds)]
            rot, pos = jt.transform(a_vals, backend)
            for got, want in zip([v for row in rot for v in row] + list(pos),
                                 [v for row in ref_rot for v in row] + list(ref_pos)):
                assert abs(got - arb(want)) < arb(10) ** -45
        s_vals = [2 * sympy.atan(sympy.Rational(t.numerator, t.denominator)) if k == "angle"
                  else sympy.Rational(l.numerator, l.denominator)
                  for t, l, k in zip(tans, lengths, jt.coordinate_kinds)]
        rot, pos = jt.transform(s_vals, Symbolic())
        for got, want in zip([v for row in rot for v in row] + list(pos),
                             [v for row in ref_rot for v in row] + list(ref_pos)):
            assert sympy.simplify(got - sympy.Rational(int(want.p), int(want.q))) == 0


OPEN_CHAINS = ["pendulum", "planar_2r", "puma560", "scara"]


def random_exact_state(mech, rng):
    """Independent coordinates at rational points of the unit circle, rational rates."""
    z, z_float = [], []
    for name in mech.independent:
        joint = mech.joint_of_coordinate(name)
        kind = joint.type.coordinate_kinds[joint.coordinates.index(name)]
        t = F(rng.randint(-60, 60), 41)
        if kind == "angle":
            z.append(TanHalf(t))
            z_float.append(2 * math.atan(float(t)))
        else:
            z.append(fmpq(t.numerator, t.denominator))
            z_float.append(float(t))
    zd = [F(rng.randint(-50, 50), 17) for _ in mech.independent]
    zdd = [F(rng.randint(-50, 50), 19) for _ in mech.independent]
    return z, z_float, zd, zdd


@pytest.mark.parametrize("name", OPEN_CHAINS)
def test_regressor_agrees_in_all_backends(name):
    """K at one rational state: exact (fmpq) = sympy = arb(50) = float64, each to its precision."""
    mech = resolve(name)
    rng = random.Random(11)
    z, z_float, zd, zdd = random_exact_state(mech, rng)
    q = lambda b, vals: [b.rational(v) for v in vals]  # noqa: E731
    exact = Exact()
    k_exact = Evaluator(mech, exact).sample(z, q(exact, zd), q(exact, zdd)).regressor()
    ref = [[F(int(v.p), int(v.q)) for v in row] for row in k_exact]

    k_float = Evaluator(mech, Float64()).sample(z_float, [float(v) for v in zd], [float(v) for v in zdd]).regressor()
    scale = max(abs(float(v)) for row in ref for v in row)
    assert np.allclose(np.array(k_float, dtype=float), np.array(ref, dtype=float), atol=1e-12 * scale)

    backend = Arb(50)
    with backend.activate():
        z_arb = [2 * arb(v.t).atan() if isinstance(v, TanHalf) else arb(v) for v in z]
        k_arb = Evaluator(mech, backend).sample(z_arb, q(backend, zd), q(backend, zdd)).regressor()
        for row_a, row_r in zip(k_arb, ref):
            for a, r in zip(row_a, row_r):
                assert abs(a - arb(fmpq(r.numerator, r.denominator))) < arb(10) ** -44 * (1 + scale)

    sym = Symbolic()
    if len(mech.independent) <= 2:    # sympy is slow; the small chains are enough
        k_sym = Evaluator(mech, sym).sample(z, q(sym, zd), q(sym, zdd)).regressor()
        for row_s, row_r in zip(k_sym, ref):
            for s_, r in zip(row_s, row_r):
                assert sympy.nsimplify(sympy.expand(s_)) == sympy.Rational(r.numerator, r.denominator)
