"""The whole robot workflow on a URDF: simulate -> identify --physical -> convert --inertia.

The identified URDF must load (every body physical, checked exactly by the reader) and
reproduce the base-parameter estimates it was made from: its standard parameters, pushed
through the same base model, equal the identified base parameters within their std.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.identify.base import BaseModel
from baseparams.io.loader import resolve
from baseparams.dynamics.forces import standard_parameters

pytest.importorskip("cvxpy", reason="identify --physical needs cvxpy (the 'physical' extra)")

UR5 = Path(__file__).parent / "data" / "urdf" / "ur5.urdf"


def _ok(args):
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output + (result.stderr if result.stderr_bytes else "")
    return result


def test_identified_physical_parameters_go_back_into_the_urdf(tmp_path):
    data, identified, out = tmp_path / "d.csv", tmp_path / "id.json", tmp_path / "ur5_id.urdf"
    _ok(["simulate", str(UR5), "-o", str(data), "--samples", "300", "--noise", "0.05", "--seed", "3"])
    _ok(["identify", str(UR5), str(data), "--solver", "dp", "--physical", "--format", "json",
         "-o", str(identified)])
    _ok(["convert", str(UR5), "--inertia", str(identified), "-o", str(out)])
    report = json.loads(identified.read_text())
    mech, written = resolve(str(UR5)), resolve(str(out))
    assert written.parameters == mech.parameters
    phi = standard_parameters(written)
    physical = np.array([float(report["physical"][name]) for name in mech.parameters])
    np.testing.assert_allclose(phi, physical, rtol=1e-9, atol=1e-12)
    # the written parameters reproduce the estimates, through the solver's base model
    result = registry.solvers()["dp"].item.solve(mech)
    base = BaseModel.from_result(result, mech)
    estimates = {row["name"]: (float(row["value"]), float(row["std"])) for row in report["base"]}
    for name, value in zip(base.names, base.B @ phi):
        estimate, std = estimates[name]
        assert abs(value - estimate) <= 3 * std + 1e-6 * max(1.0, abs(estimate)), name
