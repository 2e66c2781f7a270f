"""Issue 47's cheaper W in balls, checked against what it replaced: ``Arb.matrix`` hands rows
to arb_mat whole (ints and floats exact, anything else converted first) and gives the
entries the per-entry conversion gave; a sample's body states, now computed when first read
in every arithmetic, equal the tree's forward kinematics at that state."""

from fractions import Fraction

from flint import arb, fmpq

from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric.backends import Arb


def same(a: arb, b: arb) -> bool:
    return a.mid() == b.mid() and a.rad() == b.rad()


def test_matrix_entries_as_converted_one_by_one():
    backend = Arb(30)
    with backend.activate():
        third = arb(1) / 3
        rows = [[0, 3, 2 ** 80, 0.1], [third, -0.25, 7, third * third]]
        W = backend.matrix(rows, 4)
        assert all(same(W[i, j], v if type(v) is arb else arb(v)) for i, row in enumerate(rows)
                   for j, v in enumerate(row))
        mixed = backend.matrix([[fmpq(1, 3), "0.1"], [2, 0.5]], 2)        # a decimal string: converted first
        assert same(mixed[0, 0], backend.rational(Fraction(1, 3))) and same(mixed[0, 1], arb("0.1"))
        assert backend.matrix([], 3).ncols() == 3


def test_states_read_later_are_the_forward_kinematics():
    mech = parse_mechanism(generate.serial_chain(2, bodies=4, spherical=0.3), "chain.toml")
    backend = Arb(30)
    trajectory = Trajectory.default(mech, samples=3)
    ev = Evaluator(mech, backend, certify=True)
    with backend.activate():
        z, zd, zdd = trajectory.values(mech, backend, 1)
        sample = ev.sample(z, zd, zdd)
        assert sample._states is None                       # not computed for the regressor
        sample.regressor()
        assert sample._states is None
        eager = ev.kin.forward(sample.q, sample.qd)
    lazy = sample.states                                    # read outside the precision: it sets its own
    assert lazy.keys() == eager.keys()
    for label, state in eager.items():
        other = lazy[label]
        for name in ("rot", "pos", "w", "v", "bw", "ba"):
            mine, theirs = getattr(state, name), getattr(other, name)
            flat = [x for row in mine for x in row] if name == "rot" else list(mine or [])
            again = [x for row in theirs for x in row] if name == "rot" else list(theirs or [])
            assert len(flat) == len(again) and all(same(arb(a), arb(b)) for a, b in zip(flat, again)), (label, name)
