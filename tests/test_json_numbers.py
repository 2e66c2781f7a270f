"""Numbers in the solvers' JSON are JSON numbers (issue 47: ``diagnostics.untrusted[]
.estimated_error`` was written as the string ``"np.float64(...)"``; that key went with dp's
untrusted list, always empty since). Every string of dp's and vp's JSON on a chain beyond 80
parameters is checked for a Python repr of a number or array, and the JSON must survive a
strict round trip (no NaN or Infinity). A coefficient that is not exact is a JSON number, its
decimal string beside it (issue 45, "floats as floats")."""

import json
import re
from fractions import Fraction

import pytest

from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.solvers.run import run_solver

REPR = re.compile(r"np\.\w+\(|float(64|32)\(|int64\(|array\(|Decimal\(|Fraction\(|mpf\(")


def strings(value, path="$"):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from strings(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from strings(v, f"{path}[{i}]")
    elif isinstance(value, str):
        yield path, value


@pytest.mark.parametrize("solver", ["dp", "vp"])
def test_solver_json_has_no_python_reprs(solver):
    mech = parse_mechanism(generate.serial_chain(3, bodies=9), "chain9.toml")
    out = run_solver(solver, mech, {"recover": False} if solver == "vp" else {}).to_json()
    text = json.dumps(out, allow_nan=False)
    assert json.loads(text) == out
    bad = [(p, s) for p, s in strings(out) if REPR.search(s)]
    assert not bad, bad[:3]
    for item in out["diagnostics"].get("untrusted", []):
        assert isinstance(item, dict)
        for key, value in item.items():
            assert not (isinstance(value, str) and REPR.search(value)), (key, value)
    # floats as floats (issue 45): a coefficient is a number unless exact; its decimal beside it
    numbers = [(b["decimals"][p], v) for b in out["base"] for p, v in b["expression"].items() if not isinstance(v, str)]
    assert numbers and all(isinstance(v, float) and float(Fraction(d)) == v for d, v in numbers)


def test_identify_json_has_no_python_reprs(tmp_path):
    import baseparams as bp
    data = tmp_path / "d.csv"
    bp.simulate("planar_2r", output=data, noise=0.01, seed=2)
    out = bp.identify("planar_2r", data, solver="dp").to_json()
    assert json.loads(json.dumps(out, allow_nan=False)) == out
    bad = [(p, s) for p, s in strings(out) if REPR.search(s)]
    assert not bad, bad[:3]
    assert any(isinstance(v, float) for b in out["base"] for v in b["expression"].values())
