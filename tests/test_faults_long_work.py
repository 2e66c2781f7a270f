"""Long work says what it will cost before it starts, and refuses work above the memory
budget (``BASEPARAMS_MAX_MEMORY``) before allocating it (issue 24, item 9): exact with
--samples 1000000 grew to 727 MB in 60 s, unfinished; vp on a 100-body chain to 2.6 GB in
120 s, unfinished; neither said anything up front."""

import time

import pytest
from click.testing import CliRunner

from baseparams.cli.commands import main
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model.generate import serial_chain
from baseparams.plugins.solvers.exact.solver import exact_cost
from baseparams.plugins.solvers.vp.solver import ball_bytes


def cli(*args, env=None):
    return CliRunner(env=env).invoke(main, list(args))


def test_exact_prints_its_estimate_first():
    result = cli("solve", "pendulum", "--solver", "exact")
    assert result.exit_code == 0
    first = result.stderr.splitlines()[0]
    assert first.startswith("exact: W at ") and "MiB of memory and " in first


def test_exact_with_a_million_states_is_refused_up_front_under_a_small_budget():
    start = time.process_time()             # CPU spent before refusing (wall time is the machine's load)
    result = cli("solve", "pendulum", "--solver", "exact", "--samples", "1000000",
                 env={"BASEPARAMS_MAX_MEMORY": "100M"})
    assert result.exit_code == 2 and result.stdout == ""
    assert "needs about 9" in result.stderr and "above the limit of 100 MiB" in result.stderr
    assert "BASEPARAMS_MAX_MEMORY" in result.stderr and time.process_time() - start < 10


def test_vp_on_a_100_body_chain_is_refused_up_front(tmp_path):
    path = tmp_path / "chain100.toml"
    path.write_text(serial_chain(1, bodies=100, types="R"))
    start = time.process_time()             # CPU spent before refusing (wall time is the machine's load)
    # samples given (vp's default since issue 47 takes 2 rows per estimated rank: 1,400 rows, which fit)
    result = cli("solve", str(path), "--solver", "vp", "-O", "samples=30")
    assert result.exit_code == 2, result.output
    assert "vp: W (3,000 x 1000) in balls" in result.stderr and "above the limit of 2.0 GiB" in result.stderr
    assert time.process_time() - start < 30


def test_vp_prints_its_estimate_and_runs_within_the_budget():
    result = cli("solve", "planar_2r", "--solver", "vp")
    assert result.exit_code == 0
    assert result.stderr.splitlines()[0].startswith("vp: W is ") and "of memory at 30, 60 digits" in result.stderr


def test_the_estimates_match_measured_memory_within_a_factor_of_two():
    """Peaks measured on this machine (ru_maxrss growth of the solve): vp on a 40-body R
    chain at 30 and 60 digits 451 MB; exact on pendulum at 40,000 states 38 MB and on a
    6-body chain at 2,000 states 180 MB."""
    chain40 = parse_mechanism(serial_chain(1, bodies=40, types="R"), "c40.toml")
    assert 0.5 < ball_bytes(1200, len(chain40.parameters), (30, 60)) / 451e6 < 2
    assert 0.5 < exact_cost(resolve("pendulum"), 40000)[0] / 38e6 < 2
    chain6 = parse_mechanism(serial_chain(1, bodies=6, types="R"), "c6.toml")
    assert 0.5 < exact_cost(chain6, 2000)[0] / 180e6 < 2
