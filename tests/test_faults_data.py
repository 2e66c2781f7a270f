"""Bad measured data, second round (issue 24, items 6-8): numbers parsed strictly (ASCII
digits, no underscores), extreme values refused before they overflow a fit, files read under
a memory budget (a device or an endless stream is never read whole), bad recording
descriptions, and simulate's options; each is one `error:` line naming the file, the row
and column or key, and the reason, exit 2, never a traceback."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main

BAD_NUMBERS = ["1_0", "\u0663", "\uff11", "1e308", "-1e200", "1e151", "inf", "-inf", "nan", "NaN", "0x10",
               "1e", "--1", "1..2", "", " ", "1 2", "\u00bd", "\u2075", "1e+", "+-1", "1.5.", "e5", "one"]
COLUMNS = ["t", "q_theta", "tau_theta"]


def _pendulum_csv(path: Path, bad: str | None = None, column: str | None = None, row: int = 5) -> None:
    t = np.arange(40) * 0.05
    table = [[f"{v:.6g}" for v in r] for r in np.column_stack([t, 0.5 * np.sin(t), np.cos(3 * t)])]
    if bad is not None:
        table[row - 2][COLUMNS.index(column)] = bad
    path.write_text(",".join(COLUMNS) + "\n" + "".join(",".join(r) + "\n" for r in table), encoding="utf-8")


def _one_error_line(result, *parts):
    assert result.exit_code == 2, (result.exit_code, result.output)
    line = result.stderr.strip()
    assert line.startswith("error: ") and "\n" not in line and "Traceback" not in result.output, line
    for part in parts:
        assert part in line, (part, line)
    return line


@pytest.mark.parametrize("column", COLUMNS)
@pytest.mark.parametrize("bad", BAD_NUMBERS)
def test_bad_numbers_name_row_and_column(tmp_path, bad, column):
    path = tmp_path / "d.csv"
    _pendulum_csv(path, bad, column)
    result = CliRunner().invoke(main, ["identify", "pendulum", str(path), "--solver", "dp"])
    line = _one_error_line(result, str(path))
    assert "row 5" in line and (column in line or "fields" in line), line


def test_extreme_but_finite_numbers_are_refused_not_an_internal_error(tmp_path):
    path = tmp_path / "d.csv"
    _pendulum_csv(path, "1e300", "tau_theta")
    for verb in ("identify", "diagnose"):
        result = CliRunner().invoke(main, [verb, "pendulum", str(path)])
        _one_error_line(result, "row 5, column tau_theta", "out of range")


def test_a_device_is_never_read_whole():
    result = CliRunner().invoke(main, ["identify", "pendulum", "/dev/zero"])
    _one_error_line(result, "/dev/zero", "binary file")


def test_a_file_over_the_memory_budget_is_refused_before_parsing(tmp_path, monkeypatch):
    path = tmp_path / "d.csv"
    _pendulum_csv(path)
    assert path.stat().st_size > 1024 // 6              # PARSE_BYTES_PER_BYTE: the budget is 170 bytes
    monkeypatch.setenv("BASEPARAMS_MAX_MEMORY", "1K")
    result = CliRunner().invoke(main, ["identify", "pendulum", str(path)])
    _one_error_line(result, str(path), "BASEPARAMS_MAX_MEMORY", "bytes")


@pytest.mark.parametrize("args, part", [
    (["--seed", "-1"], "--seed"), (["--seed", "99999999999"], "--seed"), (["--noise", "1e308"], "--noise"),
    (["--noise", "nan"], "--noise"), (["--noise", "1_0"], "--noise"), (["--noise", "-1"], "--noise"),
    (["--noise", "\u0663"], "--noise"), (["--noise", "0.1,,0.2"], "--noise"),
])
def test_simulate_options(tmp_path, args, part):
    result = CliRunner().invoke(main, ["simulate", "pendulum", "-o", str(tmp_path / "x.csv"), *args])
    assert result.exit_code == 2, result.output
    assert part in result.output + result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "x.csv").exists()


GOOD = {"recording": '[recording]\ntime = "t"\n', "runs": '[[runs]]\nfile = "d.csv"\n',
        "position": '[position]\ntheta = "q_theta"\n', "torque": '[torque]\ntheta = "tau_theta"\n'}
BAD_DESCRIPTIONS = [
    ({"recording": '[recording]\nrate = 20\ntime = "t"\n'}, "recording", "exactly one of"),
    ({"recording": "[recording]\n"}, "recording", "exactly one of"),
    ({"recording": "[recording]\nrate = -5\n"}, "recording.rate", "positive"),
    ({"recording": '[recording]\ntime = "t"\ntime_unit = "fortnight"\n'}, "recording.time_unit", "unknown"),
    ({"recording": '[recording]\ntime = "t"\ndelimiter = "|"\n'}, "recording.delimiter", "unknown delimiter"),
    ({"runs": "[[runs]]\n"}, "runs[0]", "give file"),
    ({"runs": '[[runs]]\nfile = "missing.csv"\n'}, "missing.csv", "cannot read"),
    ({"runs": '[[runs]]\nfile = "d.csv"\nwindow = [50, 60]\n'}, "runs[0].window", "samples between"),
    ({"position": '[position]\nelbow = "q_theta"\n'}, "position.elbow", "not a joint coordinate"),
    ({"position": '[position]\ntheta = "nope"\n'}, "header", "no column 'nope'"),
    ({"position": '[position]\ntheta = { column = "q_theta", unit = "furlong" }\n'}, "position.theta.unit",
     "unknown unit"),
    ({"position": '[position]\ntheta = { column = "q_theta", scale = 0 }\n'}, "position.theta", "scale"),
    ({"position": '[position]\ntheta = { column = "q_theta", scale = "1e200" }\n'}, "position.theta",
     "range"),
    ({"position": '[position]\ntheta = { column = "q_theta", gain = 2 }\n'}, "position.theta.gain",
     "torque channels only"),
    ({"torque": '[torque]\ntheta = { column = "tau_theta", gain = "x" }\n'}, "torque.theta.gain", ""),
    ({"torque": '[torque]\ntheta = { colum = "tau_theta" }\n'}, "torque.theta", "colum"),
    ({"position": '[position]\ntheta = { column = "q_theta", offset = "pi/0" }\n'}, "position.theta.offset",
     "division by zero"),
    ({"torque": ""}, "torque", "missing"),
    ({"runs": '[[runs]]\nfile = "d.csv"\n[runs.payload]\nbody = "nobody"\nmass = 1\n'}, "runs[0].payload.body",
     "no body"),
    ({"runs": '[[runs]]\nfile = "d.csv"\n[runs.payload]\nbody = 1\nmass = -1\n'}, "runs[0].payload.mass",
     "positive"),
    ({"runs": '[[runs]]\nfile = "d.csv"\n[runs.payload]\nbody = 1\nmass = 1\ninertia = [1, 0, 0, 1, 0, 3]\n'},
     "runs[0].payload.inertia", "mass distribution"),
    ({"recording": '[recording]\ntime = "t"\n[filter]\ncutoff = 1000\n'}, "filter.cutoff", "Nyquist"),
    ({"recording": '[recording]\ntime = "t"\n[filter]\ndecimate = 0\n'}, "filter.decimate", "at least 1"),
]


@pytest.mark.parametrize("case", range(len(BAD_DESCRIPTIONS)))
def test_bad_descriptions_name_the_key(tmp_path, case):
    changes, key, reason = BAD_DESCRIPTIONS[case]
    _pendulum_csv(tmp_path / "d.csv")
    text = "".join(changes.get(k, v) for k, v in GOOD.items())
    (tmp_path / "r.toml").write_text(text)
    before = (tmp_path / "d.csv").read_bytes()
    result = CliRunner().invoke(main, ["identify", "pendulum", str(tmp_path / "r.toml"), "--solver", "dp"])
    _one_error_line(result, key, reason)
    assert (tmp_path / "d.csv").read_bytes() == before


def test_the_first_bad_field_is_named_by_row_then_column_in_any_batch(monkeypatch):
    """Fields are converted a batch of rows and a column at a time; the error still names the
    first bad field in the file's order (row, then column), and a row with the wrong number of
    fields after it comes first, as it did when every row was read before any number."""
    from baseparams.errors import InputError
    from baseparams.recordings import delimited
    text = "t,a,b\n" + "".join(f"{k},{k},{k}\n" for k in range(20))
    rows = text.splitlines()
    rows[9], rows[6] = "8,x,8", "5,5,y"                     # b on line 7 before a on line 10
    for batch in (1, 4, 1000):
        monkeypatch.setattr(delimited, "PARSE_BATCH_ROWS", batch)
        with pytest.raises(InputError) as error:
            delimited.read_columns("f.csv", "\n".join(rows) + "\n")
        assert error.value.key == "row 7, column b", (batch, error.value.key)
        with pytest.raises(InputError) as error:
            delimited.read_columns("f.csv", "\n".join(rows + ["1,2"]) + "\n")
        assert error.value.key == "row 22" and "2 fields" in str(error.value)
