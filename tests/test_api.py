"""The Python front door (baseparams.api, re-exported at the package top): each function
returns the object the command line prints, its to_json() is the CLI's JSON, and
`import baseparams` stays light."""

import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

import baseparams as bp
from baseparams.api import DEFAULT_SOLVER
from baseparams.cli import main
from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism


def _untimed(value):
    """``value`` without what varies from run to run (seconds, peak memory)."""
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if k not in ("seconds", "elapsed_s", "peak_memory_mb")}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def _cli_json(*args: str) -> dict:
    result = CliRunner().invoke(main, [*args, "--format", "json"])
    assert result.exit_code in (0, 1), result.output
    return json.loads(result.stdout)


def test_import_is_light_and_lists_the_functions():
    code = ("import sys, baseparams as bp; print(sorted(m for m in ('sympy', 'flint', 'scipy', 'numpy', "
            "'baseparams.api') if m in sys.modules)); print(callable(bp.solve), callable(bp.identify), "
            "callable(bp.excite))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "[]"                       # nothing heavy until a function runs
    assert out[1] == "True True True"
    assert set(bp.__all__) >= {"load", "solve", "validate", "simulate", "identify", "diagnose", "export",
                               "convert", "excite"}


def test_import_sets_one_blas_thread_unless_the_user_chose():
    code = "import os, baseparams; print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])"
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.split() == ["1", "1"]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**env, "OPENBLAS_NUM_THREADS": "4"})
    assert out.stdout.split() == ["4", "1"]


def test_identify_and_excite_stay_packages_too():
    import baseparams.excite.plan as plan
    import baseparams.identify.fit as fit
    assert bp.identify.fit is fit and bp.excite.plan is plan


def test_load_takes_names_paths_and_mechanisms():
    mech = bp.load("pendulum")
    assert isinstance(mech, Mechanism) and bp.load(mech) is mech
    assert bp.load(mech.path).parameters == mech.parameters
    with pytest.raises(InputError, match="unknown mechanism 'no_such'"):
        bp.load("no_such")


@pytest.mark.parametrize("family", ["serial_chain", "tree", "four_bar"])
def test_generated_mechanisms_solve_from_their_toml_text(family):
    """Generated mechanisms (TOML text, not a file) load and solve; dp and vp agree on the rank."""
    from baseparams.model import generate
    text = getattr(generate, family)(3)
    mech = bp.load(text)
    assert isinstance(mech, Mechanism)
    assert bp.solve(text, "dp").rank == bp.solve(mech, "vp").rank > 0


@pytest.mark.parametrize("name, solver", [("pendulum", "dp"), ("planar_2r", "exact"), ("four_bar", "vp")])
def test_solve_json_is_the_cli_json(name, solver):
    api = bp.solve(name, solver).to_json()
    cli = _cli_json("solve", name, "--solver", solver)
    assert "elapsed_s" in api and _untimed(api) == _untimed(cli)


def test_solve_result_views():
    solution = bp.solve("planar_2r", "exact", solver_options={"samples": 20})
    assert solution.rank == 6 and solution.certified                # attributes of the solver's result
    frame = solution.to_frame()
    assert list(frame.columns) == ["name", "expression", *solution.parameters] and len(frame) == solution.rank
    assert (frame[solution.parameters].to_numpy() == solution.base_matrix()).all()   # float columns: B
    assert frame["name"].tolist() == [b["name"] for b in solution.base]
    assert "rank 6" in solution._repr_markdown_() and "phi_b01" in solution._repr_html_()
    assert str(solution) == solution.to_text()
    with pytest.raises(InputError, match="has no option 'nope'"):
        bp.solve("pendulum", "dp", solver_options={"nope": 1})
    with pytest.raises(InputError, match="unknown solver 'nope'"):
        bp.solve("pendulum", "nope")


def test_to_frame_without_pandas_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install pandas"):
        bp.solve("pendulum", "dp").to_frame()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("api") / "data.csv"
    result = bp.simulate("planar_2r", output=path, effects=["viscous_friction:q1=0.5"], noise=0.01, seed=1)
    assert result.output == str(path) and result.effects == 1
    return path


def test_simulate_frame_matches_the_csv(recording):
    again = bp.simulate("planar_2r", effects=["viscous_friction:q1=0.5"], noise=0.01, seed=1)
    frame = again.to_frame()
    header = recording.read_text().splitlines()[0].split(",")
    assert set(frame.columns) == set(header) and len(frame) == again.data.count
    assert "1 hidden effect)" in again.to_text()             # singular: one effect


def test_identify_json_is_the_cli_json_and_the_text_has_the_legend(recording):
    fit = bp.identify("planar_2r", recording, effects=["viscous_friction:*"], solver="dp")
    assert fit.to_json() == _cli_json("identify", "planar_2r", str(recording), "--effect", "viscous_friction:*",
                                      "--solver", "dp")
    estimate = fit.identification.value("fv_q1")
    assert abs(estimate - 0.5) < 4 * fit.identification.std[fit.identification.names.index("fv_q1")]
    text = fit.to_text()
    for entry in fit.to_json()["base"]:                       # every base parameter says what it is
        assert f"{entry['name']} = " in text
    frame = fit.to_frame()
    assert frame.set_index("name").loc["fv_q1", "estimate"] == pytest.approx(estimate)


def test_known_effects_keep_the_files_decimals(tmp_path, recording):
    text = open(bp.load("planar_2r").path, encoding="utf-8").read()
    path = tmp_path / "with_offset.toml"
    path.write_text(text + '\n[[effects]]\nkind = "offset"\ncoordinate = "q2"\nvalues = { off = "0.25" }\n'
                    '\n[[effects]]\nkind = "viscous_friction"\ncoordinate = "q1"\nvalues = { fv = "0.1" }\n')
    known = bp.identify(path, recording, solver="dp").to_json()["known_effects"]
    assert {(k["kind"], k["coordinate"]): k["values"] for k in known} == {
        ("offset", "q2"): {"off": "0.25"}, ("viscous_friction", "q1"): {"fv": "0.1"}}


def test_diagnose_json_is_the_cli_json(recording):
    report = bp.diagnose("planar_2r", recording)
    assert report.closed and [(e["kind"], e["coordinate"]) for e in report.diagnosis.effects] == [
        ("viscous_friction", "q1")]
    assert report.to_json() == _cli_json("diagnose", "planar_2r", str(recording))
    assert report.to_frame()["kind"].tolist() == ["viscous_friction"]
    assert report.to_text().startswith("verdict: EXPLAINED")


def test_physical_fit_prints_its_status_and_keeps_cvxpy_quiet(recording):
    pytest.importorskip("cvxpy")
    result = CliRunner().invoke(main, ["identify", "planar_2r", str(recording), "--effect", "viscous_friction:*",
                                       "--solver", "dp", "--physical"])
    assert result.exit_code == 0, result.output
    status = bp.identify("planar_2r", recording, effects=["viscous_friction:*"], solver="dp",
                         physical=True).to_json()["physical_fit"]["status"]
    assert f"status {status}" in result.stdout
    assert "Warning" not in result.stderr and "warn(" not in result.stderr


def test_validate_export_convert(tmp_path):
    report = bp.validate(["pendulum"], solvers=["dp", "exact"])
    assert report.ok and _untimed(report.to_json()) == _untimed(_cli_json("validate", "pendulum", "--solver", "dp",
                                                                          "--solver", "exact"))
    assert {r["check"] for r in report.rows()} and report._repr_markdown_().startswith("| mechanism")
    exported = bp.export("pendulum", solver="dp", output=tmp_path / "pendulum_regressor.py")
    assert (tmp_path / "pendulum_regressor.py").read_text() == exported.source
    assert exported.to_json()["base_parameters"] == 3
    converted = bp.convert("planar_2r", tmp_path / "planar_2r.urdf")
    assert converted.writer == "urdf" and (tmp_path / "planar_2r.urdf").is_file()
    assert bp.solve(tmp_path / "planar_2r.urdf", "dp").rank == bp.solve("planar_2r", "dp").rank


def test_one_default_solver():
    import inspect
    for function in (bp.solve, bp.api.identify, bp.export, bp.api.excite):
        assert inspect.signature(function).parameters["solver"].default == DEFAULT_SOLVER
    for command in ("solve", "identify", "export", "excite"):
        param = next(p for p in main.commands[command].params if p.name == "solver_name")
        assert param.default == DEFAULT_SOLVER, command


def test_an_inaccurate_physical_fit_is_said_in_the_text_not_leaked(recording, monkeypatch):
    """cvxpy warns through `warnings` ("Solution may be inaccurate") and reports
    optimal_inaccurate: the text says both, stderr carries no raw warning."""
    pytest.importorskip("cvxpy")
    import dataclasses
    import warnings

    from baseparams.identify import physical

    real = physical.physical_fit

    def inaccurate(*args, **kwargs):
        warnings.warn("Solution may be inaccurate. Try another solver, adjusting the solver settings, "
                      "or solve with verbose=True for more information.", UserWarning)
        return dataclasses.replace(real(*args, **kwargs), status="optimal_inaccurate")

    monkeypatch.setattr(physical, "physical_fit", inaccurate)
    result = CliRunner().invoke(main, ["identify", "planar_2r", str(recording), "--solver", "dp", "--physical"])
    assert result.exit_code == 0, result.output
    assert "status optimal_inaccurate" in result.stdout
    assert "warning: Solution may be inaccurate." in result.stdout
    assert "UserWarning" not in result.stderr and "may be inaccurate" not in result.stderr
    fit = bp.identify("planar_2r", recording, solver="dp", physical=True).to_json()["physical_fit"]
    assert fit["status"] == "optimal_inaccurate" and fit["warnings"][0].startswith("Solution may be inaccurate.")


def test_solver_options_one_way_and_the_old_keywords_deprecated(tmp_path):
    """Issue 45: solver_options={...} on every function; solve/export's **options still read
    with a DeprecationWarning, and the two ways give the same result."""
    new = bp.solve("planar_2r", "exact", solver_options={"samples": 20, "seed": 5})
    with pytest.warns(DeprecationWarning, match="solver_options"):
        old = bp.solve("planar_2r", "exact", samples=20, seed=5)
    assert _untimed(old.to_json()) == _untimed(new.to_json())
    with pytest.raises(InputError, match="seed given both"):
        with pytest.warns(DeprecationWarning):
            bp.solve("planar_2r", "exact", solver_options={"seed": 5}, seed=6)
    exported = bp.export("pendulum", solver="exact", solver_options={"seed": 2})
    with pytest.warns(DeprecationWarning, match="export"):
        again = bp.export("pendulum", solver="exact", seed=2)
    assert again.source == exported.source
    with pytest.raises(InputError, match="has no option 'nope'"):
        bp.export("pendulum", solver="dp", solver_options={"nope": 1})
