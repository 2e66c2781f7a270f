"""The examples carry their data (issue 45, item 4): each script run without arguments from a
copy of examples/ alone, with no ``../shared`` beside it, and saying which file it uses.
(tests/test_examples.py checks what the scripts print, from the checkout.)"""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def run_copy(tmp_path: Path, script: str) -> subprocess.CompletedProcess:
    examples = tmp_path / "project" / "examples"
    shutil.copytree(ROOT / "examples", examples, ignore=shutil.ignore_patterns("__pycache__"))
    assert not (tmp_path / "shared").exists()
    return subprocess.run([sys.executable, str(examples / script)], capture_output=True, text=True,
                          timeout=900, cwd=tmp_path / "project")


def test_solve_urdf_says_which_file_it_solves(tmp_path):
    result = run_copy(tmp_path, "solve_urdf.py")
    assert result.returncode == 0, result.stderr
    first, second = result.stdout.splitlines()[:2]
    path = Path(re.fullmatch(r"URDF: (.+)", first).group(1))
    assert path.is_file() and second.startswith(f"{path.name}: ") and "rank 36" in second
    try:
        from importlib import metadata
        metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:        # without it: the bundled copy, in the copied folder
        assert path == tmp_path / "project" / "examples" / "data" / "ur5.urdf"
    else:                                        # with it: its own UR5, not the bundled copy
        assert path.name == "ur5_robot.urdf" and "example-robot-data" in str(path)


@pytest.mark.slow
def test_identify_recording_runs_on_the_carried_tx40(tmp_path):
    """About 7 CPU s (13 s of wall at load 3)."""
    result = run_copy(tmp_path, "identify_recording.py")
    assert result.returncode == 0, result.stderr
    assert "staubli_tx40: 819 samples x 6 coordinates, 36 base parameters (dp)" in result.stdout
    assert "verdict: " in result.stdout
