"""W in balls as its entries (issue 47: vp's certified analysis reads each entry once, so its
W is no longer built as an arb_mat first): :func:`observation_matrix` with ``entries=True`` gives the
entries its arb_mat has, ball for ball, for trajectories, random batches and closed
loops; :class:`BallRows` answers as an arb_mat does, stacks, and converts what is not a ball
exactly; and the vp solver's results are those of the arb_mat it replaced."""

from flint import arb, ctx

import pytest

from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix
from baseparams.numeric.backends import Float64
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import KinematicsError
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.numeric import certify
from baseparams.numeric.backends import Arb, BallRows


def same(a: arb, b: arb) -> bool:
    return a.mid() == b.mid() and a.rad() == b.rad()


@pytest.mark.parametrize("name", ["puma560", "sla_suspension", "chain"])
def test_entries_are_the_matrix_entries(name):
    mech = (parse_mechanism(generate.serial_chain(3, bodies=5, spherical=0.3), "chain.toml") if name == "chain"
            else resolve(name))
    trajectory = Trajectory.default(mech, samples=4)
    for states in (trajectory, random_batch(mech, trajectory, 11)):
        for digits in (30, 60):
            W, info = observation_matrix(mech, Arb(digits), states)
            rows, info_rows = observation_matrix(mech, Arb(digits), states, entries=True)
            assert (rows.nrows(), rows.ncols()) == (W.nrows(), W.ncols()) and info_rows == info
            assert all(same(a, b) for a, b in zip(rows.entries(), W.entries()))
            assert len(rows.entries()) == W.nrows() * W.ncols()
            assert all(same(a, b) for a, b in zip(rows.matrix.entries(), W.entries()))


def test_ball_rows_convert_stack_and_check_their_size():
    with ctx.workdps(30):
        third = arb(1) / 3
        rows = BallRows(2, 2, [1, 0.5, third, 2 ** 80])
        assert all(type(v) is arb for v in rows.entries())
        assert same(rows.entries()[1], arb(0.5)) and same(rows.entries()[3], arb(2) ** 80)
        both = BallRows.stack(rows, BallRows(1, 2, [third, 7]))
        assert (both.nrows(), both.ncols()) == (3, 2) and same(both.entries()[4], third)
        assert both.matrix.nrows() == 3 and same(both.matrix[2, 1], arb(7))
        assert BallRows(0, 5, []).matrix.ncols() == 5
        with pytest.raises(ValueError, match="3 entries for a 2 x 2 matrix"):
            BallRows(2, 2, [1, 2, 3])


def test_analysis_of_the_entries_is_the_analysis_of_the_matrix():
    mech = resolve("puma560")
    trajectory = Trajectory.default(mech, samples=12)
    W, _ = observation_matrix(mech, Arb(30), trajectory)
    rows, _ = observation_matrix(mech, Arb(30), trajectory, entries=True)
    a, b = certify.analyse(W, 30), certify.analyse(rows, 30)
    assert (a.rank, a.kept, a.rows) == (b.rank, b.kept, b.rows)
    assert all(same(x, y) for x, y in zip(a.beta.entries(), b.beta.entries()))
    assert same(a.tail_bound, b.tail_bound) and same(a.sigma_r_lower, b.sigma_r_lower)


def test_a_trajectory_error_names_the_file_and_the_trajectory():
    """As observation_matrix's (tests/test_observation.py): the pendulum leaving its range."""
    text = open(resolve("pendulum").path).read()
    limited = parse_mechanism(text.replace('coordinates = ["theta"]',
                                           'coordinates = ["theta"]\nlimits = { theta = ["-0.01", "0.01"] }'),
                              "limited_pendulum.toml")
    with pytest.raises(KinematicsError, match=r"limited_pendulum.toml: trajectory: .*leaves its range"):
        observation_matrix(limited, Arb(30), Trajectory.default(limited, samples=5), entries=True)
    with pytest.raises(ValueError, match="entries=True is for arb, not Float64"):
        observation_matrix(limited, Float64(), Trajectory.default(limited, samples=5), entries=True)
