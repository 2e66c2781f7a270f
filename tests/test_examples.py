"""Every script in examples/ runs as a user would run it (a fresh interpreter) and prints
what it claims; the TX40 run of identify_recording.py reads tests/data, never ../shared."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

import baseparams as bp

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
TX40 = Path(__file__).parent / "data" / "tx40"


def run(script: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, timeout=600,
                          cwd=ROOT)


def test_every_example_is_covered():
    assert {p.name for p in EXAMPLES} == {"solve_urdf.py", "identify_recording.py", "third_party_joint.py"}


def test_solve_urdf_prints_the_rank_a_second_solver_finds():
    result = run(ROOT / "examples" / "solve_urdf.py")
    assert result.returncode == 0, result.stderr
    rank = int(re.search(r"rank (\d+)", result.stdout).group(1))
    # dp, an independent method (SVD in floats), on the same file the script falls back to
    assert rank == bp.solve(ROOT / "examples" / "data" / "ur5.urdf", "dp").rank == 36
    assert "(certified)" in result.stdout and "phi_b01 = " in result.stdout


def test_identify_recording_names_the_hidden_friction(tmp_path):
    data = tmp_path / "data.csv"
    bp.simulate("planar_2r", output=data, effects=["viscous_friction:q1=0.5"], noise=0.01, seed=1)
    result = run(ROOT / "examples" / "identify_recording.py", "planar_2r", str(data))
    assert result.returncode == 0, result.stderr
    fv = float(re.search(r"fv_q1\s+(\S+)\s+(\S+)", result.stdout).group(1))
    std = float(re.search(r"fv_q1\s+(\S+)\s+(\S+)", result.stdout).group(2))
    assert abs(fv - 0.5) < 4 * std
    assert "verdict: EXPLAINED" in result.stdout and "viscous_friction on q1" in result.stdout
    assert "phi_b01 = " in result.stdout                  # the legend of the base parameters


@pytest.mark.slow
def test_identify_recording_on_the_tx40_test_subset():
    result = run(ROOT / "examples" / "identify_recording.py", str(TX40 / "tx40_mdh_modified.urdf"),
                 str(TX40 / "recording.toml"))
    assert result.returncode == 0, result.stderr
    assert "36 base parameters (dp)" in result.stdout and "verdict: " in result.stdout


def test_third_party_joint_validates():
    result = run(ROOT / "examples" / "third_party_joint.py")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "all agree: 1 mechanism(s), 4 solver(s)" in result.stdout
    assert "puck: exact solver, 20 parameters, rank 11 (certified)" in result.stdout
