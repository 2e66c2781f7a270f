"""Proven enclosures of the loop-closure solution contain the exact positions."""

from fractions import Fraction

import pytest
from flint import arb, fmpq

from baseparams.numeric.backends import Arb
from baseparams.dynamics.evaluator import Evaluator
from baseparams.io.loader import resolve
from baseparams.dynamics.trajectory import Trajectory


@pytest.mark.parametrize("name", ["sla_suspension", "four_bar", "stewart_platform"])
def test_30_digit_enclosures_contain_the_100_digit_solution(name):
    mech = resolve(name)
    trajectory = Trajectory.default(mech)
    coarse, fine = Arb(30), Arb(100)
    enclosing = Evaluator(mech, coarse, certify=True)
    reference = Evaluator(mech, fine)
    for tk in (Fraction(37, 10), Fraction(131, 10)):
        with fine.activate():
            z, _, _ = trajectory.independent_values(mech, fine, arb(fmpq(tk.numerator, tk.denominator)))
            exact = reference.assemble(z)
            exact_str = [arb(v).mid().str(90, radius=False) for v in exact]
        with coarse.activate():
            z, _, _ = trajectory.independent_values(mech, coarse, arb(fmpq(tk.numerator, tk.denominator)))
            balls = enclosing.assemble(z)
            for j in enclosing.structure.dependent:
                assert balls[j].rad() > 0                      # a ball, not a point
                assert balls[j].rad() < arb(10) ** -20         # and a tight one
        with fine.activate():
            for j in enclosing.structure.dependent:
                assert arb(balls[j]).contains(arb(exact_str[j])), (name, mech.coordinates[j], float(tk))
