"""A trajectory that holds a coordinate still must not yield a certified low rank.

The excitation check draws positions, velocities and accelerations independently of the
trajectory (core/excitation.py), so a coordinate the trajectory never moves still moves
in the check batch, and the missing base parameters show up.
"""

import re

import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.io.loader import parse_mechanism, resolve


def with_trajectory(name, replacements):
    text = open(resolve(name).path).read()
    for pattern, new in replacements:
        text, count = re.subn(pattern, new, text)
        assert count == 1, pattern
    return parse_mechanism(text, f"{name}_still.toml")


STILL = [
    ("pendulum", [(r'theta = "[^"]*"', 'theta = "0"')], 3),
    ("planar_2r", [(r'q1 = "[^"]*"', 'q1 = "0.5"')], 6),
    ("four_bar", [(r'q = \{ *q1 = "[^"]*"', 'q = { q1 = "0.4"')], 8),
]


@pytest.mark.parametrize("name,replacements,true_rank", STILL, ids=[s[0] for s in STILL])
def test_vp_finds_the_true_rank_when_a_coordinate_never_moves(name, replacements, true_rank):
    mech = with_trajectory(name, replacements)
    result = registry.solvers()["vp"].item.solve(mech)
    assert result.rank == true_rank
    assert any("does not excite" in w for w in result.warnings)


@pytest.mark.parametrize("name,replacements,true_rank", STILL[:2], ids=[s[0] for s in STILL[:2]])
def test_dp_finds_the_true_rank_when_a_coordinate_never_moves(name, replacements, true_rank):
    mech = with_trajectory(name, replacements)
    result = registry.solvers()["dp"].item.solve(mech)
    assert result.rank == true_rank and not result.certified
    assert any("does not excite" in w for w in result.warnings)


def test_non_finite_trajectory_is_an_input_error(tmp_path):
    text = open(resolve("pendulum").path).read()
    text = re.sub(r'theta = "[^"]*"', 'theta = "0.01/t"', text)
    path = tmp_path / "bad_trajectory.toml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["solve", str(path), "--solver", "dp"])
    assert result.exit_code == 2
    assert "bad_trajectory.toml" in result.stderr and "not finite at t = 0" in result.stderr
    assert "Traceback" not in result.stderr
