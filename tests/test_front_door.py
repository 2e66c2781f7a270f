"""The Python front door as the docs show it. Every ``bp.NAME`` (and ``bp.NAME.ATTR``) that
README.md and docs/*.md use resolves after ``import baseparams as bp`` alone, in a fresh
interpreter (no other module imported first to make it work by accident); the base matrix and
the map from standard to base parameters; export's summary."""

import json
import pathlib
import re
import subprocess
import sys

import pytest

from baseparams.errors import InputError

ROOT = pathlib.Path(__file__).resolve().parents[1]
NAME = re.compile(r"\bbp\.([A-Za-z_][A-Za-z_0-9]*(?:\.[A-Za-z_][A-Za-z_0-9]*)*)")


def _names_in_docs() -> set[str]:
    names: set[str] = set()
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for match in NAME.finditer(path.read_text(encoding="utf-8")):
            dotted = match.group(1).rstrip(".")
            names.add(dotted)
    return names


def test_every_name_the_docs_use_is_reachable():
    names = sorted(_names_in_docs())
    assert "diagnose" in names and "api.DEFAULT_SOLVER" in names      # the walk finds what it should
    probe = ("import baseparams as bp, json, sys\n"
             "missing = []\n"
             "for dotted in json.loads(sys.argv[1]):\n"
             "    value = bp\n"
             "    for part in dotted.split('.'):\n"
             "        try:\n"
             "            value = getattr(value, part)\n"
             "        except AttributeError:\n"
             "            missing.append(dotted)\n"
             "            break\n"
             "print(json.dumps(missing))\n")
    out = subprocess.run([sys.executable, "-c", probe, json.dumps(names)], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert json.loads(out.stdout) == [], "names the docs use that `import baseparams as bp` does not give"


def test_standard_parameters_map_onto_the_base_parameters_an_identification_finds(tmp_path):
    """``Solution.to_base``: the file's standard parameters mapped onto the base parameters
    equal what identification recovers from noise-free data simulated with them (an
    independent path: the regressor, least squares on the base columns)."""
    import numpy as np
    import baseparams as bp
    from baseparams.dynamics.forces import standard_parameters
    from baseparams.io.loader import resolve
    mechanism = resolve("puma560")
    solution = bp.solve("puma560", "dp")
    truth = standard_parameters(mechanism)
    bp.simulate("puma560", output=tmp_path / "clean.csv", samples=600)
    fit = bp.identify("puma560", str(tmp_path / "clean.csv"), solver="dp")
    estimates = np.array([row["estimate"] for row in fit.rows() if row["kind"] == "base"])
    expected = solution.to_base(truth)
    assert solution.base_matrix().shape == (solution.rank, len(solution.parameters))
    assert np.allclose(estimates, expected, rtol=1e-6, atol=1e-8 * np.max(np.abs(expected)))
    by_name = dict(zip(solution.parameters, truth))
    assert np.allclose(solution.to_base(by_name), expected)
    with pytest.raises(InputError, match="not standard"):
        solution.to_base({"m99": 1.0})


def test_export_prints_a_summary_and_keeps_the_module_in_source():
    import baseparams as bp
    exported = bp.export("pendulum", solver="dp")
    assert "def regressor" in exported.source and "def regressor" not in str(exported)
    assert "base parameters" in str(exported) and len(str(exported).splitlines()) == 1
