"""One command-line grammar (docs/cli.md, "One grammar"): -o FILE is the output file on
every verb, one way to choose solvers, --seed and --samples alike everywhere, -O on the
verbs that run a solver, --image-format on plots, python -m baseparams, progress on stderr."""

import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.cli.options import Progress
from baseparams.model.mechanism import MAX_SAMPLES
from baseparams.solvers.protocol import MAX_SEED


def invoke(*args: str):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_line(result) -> str:
    """The one ``error:`` line of a bad-input run (exit 2, no traceback)."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in result.output, lines
    return lines[0]


def test_python_m_baseparams_is_the_command():
    run = subprocess.run([sys.executable, "-m", "baseparams", "solve", "pendulum", "--solver", "dp", "--format",
                          "json"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["rank"] == 3 and "Warning" not in run.stderr
    usage = subprocess.run([sys.executable, "-m", "baseparams", "--help"], capture_output=True, text=True)
    assert usage.returncode == 0 and usage.stdout.startswith("Usage: baseparams ")
    bad = subprocess.run([sys.executable, "-m", "baseparams", "solve", "no_such_thing"], capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.startswith("error: unknown mechanism 'no_such_thing'")


@pytest.mark.parametrize("verb", [["list"], ["show", "pendulum"], ["plugins"], ["solve", "pendulum", "--solver", "dp"],
                                  ["validate", "pendulum", "--solver", "dp"]])
@pytest.mark.parametrize("fmt", ["text", "json"])
def test_dash_o_is_the_output_file(tmp_path, verb, fmt):
    out = tmp_path / "out.txt"
    to_stdout = invoke(*verb, "--format", fmt)
    to_file = invoke(*verb, "--format", fmt, "-o", out)
    assert to_file.exit_code == to_stdout.exit_code == 0, to_file.output
    assert to_file.stdout == "" and f"wrote {out}" in to_file.stderr
    if fmt == "json":
        strip = lambda d: {k: v for k, v in d.items() if k not in ("elapsed_s", "diagnostics", "mechanisms")}  # noqa: E731
        assert strip(json.loads(out.read_text())) == strip(json.loads(to_stdout.stdout))
    else:
        assert out.read_text().splitlines()[0] == to_stdout.stdout.splitlines()[0]


def test_dash_o_into_a_missing_folder_is_bad_input(tmp_path):
    line = error_line(invoke("show", "pendulum", "-o", tmp_path / "no" / "such" / "out.txt"))
    assert "out.txt" in line


def test_simulate_without_dash_o_writes_the_csv_to_stdout(tmp_path):
    result = invoke("simulate", "pendulum", "--samples", "20", "--noise", "0.01")
    assert result.exit_code == 0, result.output
    rows = result.stdout.splitlines()
    assert rows[0].startswith("t,") and len(rows) == 21
    assert "20 samples" in result.stderr and "0 hidden effects" in result.stderr
    again = invoke("simulate", "pendulum", "--samples", "20", "--noise", "0.01", "-o", tmp_path / "d.csv")
    assert again.exit_code == 0 and (tmp_path / "d.csv").read_text() == result.stdout


def test_solvers_are_chosen_by_repeating_solver_and_the_old_spelling_still_works():
    new = invoke("validate", "pendulum", "--solver", "dp", "--solver", "exact", "--format", "json", "--quiet")
    old = invoke("validate", "pendulum", "--solvers", "dp,exact", "--format", "json", "--quiet")
    assert new.exit_code == old.exit_code == 0
    assert json.loads(new.stdout)["solvers"] == json.loads(old.stdout)["solvers"] == ["dp", "exact"]
    assert "deprecated" in old.stderr and "deprecated" not in new.stderr


@pytest.mark.parametrize("verb", [["solve", "pendulum", "--solver", "dp"], ["simulate", "pendulum"],
                                  ["excite", "pendulum", "--iterations", "1", "--starts", "1"]])
def test_seed_has_one_range(tmp_path, verb):
    assert MAX_SEED == 2 ** 32 - 1
    for bad in ("-1", str(MAX_SEED + 1)):
        result = invoke(*verb, "--seed", bad, "-o", tmp_path / "o")
        assert result.exit_code == 2 and "--seed" in result.output


@pytest.mark.parametrize("verb", [["solve", "pendulum"], ["simulate", "pendulum"], ["export", "pendulum", "--to", "python"],
                                  ["plot", "singular-values", "pendulum", "-o", "x.png"], ["excite", "pendulum"]])
def test_samples_has_one_range(verb):
    for bad in ("1", str(MAX_SAMPLES + 1)):
        result = invoke(*verb, "--samples", bad)
        assert result.exit_code == 2 and "--samples" in result.output and f"2<=x<={MAX_SAMPLES}" in result.output


def test_a_verb_that_needs_more_samples_says_so():
    line = error_line(invoke("excite", "pendulum", "--samples", "5", "-o", "never.toml"))
    assert "--samples" in line and "at least 10" in line


def test_identify_takes_solver_options(tmp_path):
    data = tmp_path / "d.csv"
    assert invoke("simulate", "pendulum", "-o", data, "--noise", "0.01", "--quiet").exit_code == 0
    ok = invoke("identify", "pendulum", data, "-O", "digits=40", "--format", "json")
    assert ok.exit_code == 0, ok.output
    assert json.loads(ok.stdout)["solver"] == "vp"
    line = error_line(invoke("identify", "pendulum", data, "--solver", "dp", "-O", "nope=1"))
    assert "solver 'dp' has no option 'nope'" in line
    line = error_line(invoke("identify", "pendulum", data, "-O", "digits=5"))
    assert "digits" in line


def test_identify_is_quiet_about_the_inner_solver(tmp_path):
    data = tmp_path / "d.csv"
    assert invoke("simulate", "pendulum", "-o", data, "--quiet").exit_code == 0
    result = invoke("identify", "pendulum", data)
    assert result.exit_code == 0 and not any(line.startswith("vp:") for line in result.stderr.splitlines())


def test_plots_take_image_format_and_read_the_old_format_with_a_note(tmp_path):
    new = invoke("plot", "mechanism", "pendulum", "-o", tmp_path / "m", "--image-format", "svg")
    assert new.exit_code == 0 and (tmp_path / "m").read_text().lstrip().startswith("<?xml")
    old = invoke("plot", "mechanism", "pendulum", "-o", tmp_path / "n", "--format", "svg")
    assert old.exit_code == 0 and "deprecated" in old.stderr
    assert (tmp_path / "n").read_text().lstrip().startswith("<?xml")
    figure = invoke("plot", "singular-values", "pendulum", "-o", tmp_path / "s.png", "--solver", "dp")
    assert figure.exit_code == 0 and (tmp_path / "s.png").stat().st_size > 1000


def test_help_texts_cite_no_docs_folder():
    for name, command in list(main.commands.items()) + list(main.commands["plot"].commands.items()):
        text = invoke(*(["plot"] if name in main.commands["plot"].commands else []), name, "--help").output
        assert "docs/" not in text, name


def test_progress_off_a_terminal_starts_after_its_delay(capsys, monkeypatch):
    monkeypatch.setattr(Progress, "AFTER", 0.0)
    with Progress("work", steps=2) as progress:
        progress("first")
        progress.counted(2, 2, "second")
    err = capsys.readouterr().err.splitlines()
    assert err[-2].startswith("work [1/2]: first (") and err[-1].startswith("work [2/2]: second (")
    monkeypatch.setattr(Progress, "AFTER", 60.0)
    with Progress("work", steps=1) as progress:
        progress("quick")
    with Progress("work", steps=1, quiet=True) as progress:
        progress("quiet")
    assert capsys.readouterr().err == ""


def test_excite_without_dash_o_prints_the_report_only(tmp_path):
    """Issue 43: no TOML on the terminal; -o chooses the writer by its suffix."""
    result = invoke("excite", "pendulum", "--iterations", "2", "--starts", "1", "--solver", "dp", "--quiet")
    assert result.exit_code in (0, 1), result.output
    assert "[trajectory]" not in result.stdout and result.stdout.startswith("pendulum:")
    assert "starts: 1" in result.stdout
    path = tmp_path / "planned.toml"
    assert invoke("excite", "pendulum", "--iterations", "2", "--starts", "1", "--solver", "dp", "--quiet",
                  "-o", path).exit_code in (0, 1)
    from baseparams.io.loader import load_mechanism
    planned = load_mechanism(path)
    assert planned.name == "pendulum" and planned.trajectory is not None


# ----- the grammar on every verb where it means something (issue 45 item 5) ------------------
def _verbs():
    verbs = {name: command for name, command in main.commands.items() if name != "plot"}
    verbs.update({f"plot {name}": command for name, command in main.commands["plot"].commands.items()})
    return verbs


def _flags(command) -> set[str]:
    """The options a verb shows (a hidden one is a deprecated spelling still read)."""
    return {flag for param in command.params if not getattr(param, "hidden", False) for flag in param.opts}


# Where each shared option means something. A verb not listed for an option has no work it
# would change: diagnose runs no solver (its inertial model is the regressor's column space,
# the same for every solver), only validate's jobs and excite's starts split into workers,
# and list, show, plugins and convert show no progress.
GRAMMAR = {
    "--solver": {"solve", "identify", "export", "excite", "report", "validate", "plot singular-values"},
    "-O": {"solve", "identify", "export", "excite", "report"},
    "--workers": {"validate", "excite"},
    "--scheduler": {"validate", "excite"},
    "--quiet": {"solve", "export", "simulate", "identify", "diagnose", "validate", "excite", "plot singular-values"},
    "--format": {"list", "show", "plugins", "solve", "validate", "simulate", "identify", "diagnose", "excite",
                 "report"},
    "-o": set(_verbs()),
}


@pytest.mark.parametrize("flag", sorted(GRAMMAR))
def test_each_shared_option_is_on_the_verbs_where_it_means_something(flag):
    having = {name for name, command in _verbs().items() if flag in _flags(command)}
    assert having == GRAMMAR[flag]


@pytest.mark.parametrize("flag", ["--workers", "--scheduler", "--quiet", "-O", "--solver"])
def test_a_shared_option_is_declared_once(flag):
    """The same type, range and metavar wherever the option is (core/cli/options.py); --solver
    is repeatable on the verbs that run several solvers."""
    def shape(command):
        [param] = [p for p in command.params if flag in p.opts]
        kind = param.type
        return (type(kind).__name__, getattr(kind, "min", None), getattr(kind, "max", None), param.metavar,
                getattr(param, "is_flag", None))
    shapes = {shape(command) for command in _verbs().values() if flag in _flags(command)}
    assert len(shapes) == 1, shapes


@pytest.mark.parametrize("verb", [["validate", "pendulum", "--solver", "dp"],
                                  ["excite", "pendulum", "--iterations", "1", "--starts", "1"]])
@pytest.mark.parametrize("bad", ["0", "257", "two"])
def test_workers_out_of_range_is_one_error_line(verb, bad):
    assert "--workers" in error_line(invoke(*verb, "--workers", bad))


def test_solve_quiet_drops_the_solvers_progress_and_keeps_the_result():
    loud = invoke("solve", "pendulum", "--solver", "vp")
    quiet = invoke("solve", "pendulum", "--solver", "vp", "--quiet")
    assert loud.exit_code == quiet.exit_code == 0
    assert any(line.startswith("vp:") for line in loud.stderr.splitlines())
    assert quiet.stderr == "" and quiet.stdout.splitlines()[:4] == loud.stdout.splitlines()[:4]


def test_export_writes_python_without_to(tmp_path):
    plain = invoke("export", "pendulum", "--solver", "dp", "--quiet")
    named = invoke("export", "pendulum", "--solver", "dp", "--to", "python", "--quiet")
    assert plain.exit_code == named.exit_code == 0 and plain.stdout == named.stdout
    assert "def base_regressor(" in plain.stdout and plain.stderr == ""
    loud = invoke("export", "pendulum", "--solver", "dp")
    assert any(line.startswith("dp:") for line in loud.stderr.splitlines())
    assert "--to" in error_line(invoke("export", "pendulum", "--to", "c"))


def test_report_takes_solver_options():
    named = invoke("report", "pendulum", "--no-certify")
    given = invoke("report", "pendulum", "-O", "certify=false")
    assert named.exit_code == given.exit_code == 0 and named.stdout == given.stdout
    assert "3 base parameters (not checked)" in given.stdout
    assert "has no option 'nope'" in error_line(invoke("report", "pendulum", "-O", "nope=1"))
    line = error_line(invoke("report", "pendulum", "--no-certify", "-O", "certify=false"))
    assert "--no-certify" in line and "give one" in line


def test_plot_singular_values_quiet(tmp_path):
    loud = invoke("plot", "singular-values", "pendulum", "-o", tmp_path / "a.png", "--solver", "vp")
    quiet = invoke("plot", "singular-values", "pendulum", "-o", tmp_path / "b.png", "--solver", "vp", "--quiet")
    assert loud.exit_code == quiet.exit_code == 0
    assert any(line.startswith("vp:") for line in loud.stderr.splitlines())
    assert not any(line.startswith("vp:") for line in quiet.stderr.splitlines())
