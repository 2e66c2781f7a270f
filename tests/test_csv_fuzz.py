"""Broken measured-data files: every one is exit code 2 with one line naming the file (and the
row, column or header where there is one) and the reason, never a traceback.

At least 100 files, each a seeded mutation of a valid simulated file; run in-process through
click's CliRunner (``identify`` reads the data before solving, so no solver runs).
"""

import json
import random

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate
from baseparams.io.loader import resolve

MECH = "planar_2r"


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    """A valid file (with and without derivative columns), as lines."""
    root = tmp_path_factory.mktemp("valid")
    data, _ = simulate(resolve(MECH), samples=40, noise_sd=0.01)
    full, bare = root / "full.csv", root / "bare.csv"
    write_measured(full, data)
    write_measured(bare, data, derivatives=False)
    return full.read_text().splitlines(), bare.read_text().splitlines()


def _fields(lines):
    return [line.split(",") for line in lines]


def _join(rows):
    return "\n".join(",".join(r) for r in rows) + "\n"


# Each mutation: (rng, rows) -> (text or bytes, what the message must name: "row", "column",
# "header" or None for a file-level problem)
def bad_number(rng, rows):
    r, c = rng.randrange(1, len(rows)), rng.randrange(len(rows[0]))
    rows[r][c] = rng.choice(["abc", "", " ", "nan", "NaN", "inf", "-inf", "1e999", "0x1F", "1.2.3", "--1",
                             "1;5", "∞", "1e", "true"])
    return _join(rows), f"row {r + 1}, column {rows[0][c]}"


def short_row(rng, rows):
    r = rng.randrange(1, len(rows))
    rows[r] = rows[r][: rng.randrange(1, len(rows[r]))]
    return _join(rows), f"row {r + 1}"


def long_row(rng, rows):
    r = rng.randrange(1, len(rows))
    rows[r] = rows[r] + ["0"] * rng.randrange(1, 3)
    return _join(rows), f"row {r + 1}"


def swap_times(rng, rows):
    r = rng.randrange(2, len(rows))
    rows[r], rows[r - 1] = rows[r - 1], rows[r]
    return _join(rows), f"row {r + 1}, column t"


def repeat_row(rng, rows):
    r = rng.randrange(1, len(rows) - 1)
    rows.insert(r + 1, list(rows[r]))
    return _join(rows), f"row {r + 2}, column t"


def drop_column(rng, rows):
    name = rng.choice(["t", "q_q1", "q_q2", "tau_q1", "tau_q2"])
    c = rows[0].index(name)
    return _join([r[:c] + r[c + 1:] for r in rows]), "header"


def duplicate_column(rng, rows):
    c = rng.randrange(1, len(rows[0]))
    d = rng.choice([k for k in range(len(rows[0])) if k != c])
    rows[0][c] = rows[0][d]
    return _join(rows), "header"


def empty_name(rng, rows):
    rows[0][rng.randrange(len(rows[0]))] = ""
    return _join(rows), "header"


def partial_derivatives(rng, rows):
    name = rng.choice(["qd_q1", "qdd_q2", "qd_q2"])
    c = rows[0].index(name)
    return _join([r[:c] + r[c + 1:] for r in rows]), "header"


def too_few(rng, rows):
    return _join(rows[: rng.randrange(2, 8)]), None


def header_only(rng, rows):
    return _join(rows[:1]), None


def empty(rng, rows):
    return rng.choice(["", "\n\n", "   \n"]), None


def binary(rng, rows):
    raw = bytearray(_join(rows).encode())
    raw[rng.randrange(len(raw))] = 0
    return bytes(raw), None


def not_utf8(rng, rows):
    raw = bytearray(_join(rows).encode())
    raw[rng.randrange(len(raw))] = rng.choice([0xFF, 0xC3, 0x80])
    return bytes(raw), None


def random_bytes(rng, rows):
    return bytes(rng.randrange(256) for _ in range(rng.randrange(10, 400))) + b"\x00", None


def semicolons(rng, rows):
    return "\n".join(";".join(r) for r in rows) + "\n", "row 1"


def unterminated_quote(rng, rows):
    r = rng.randrange(1, len(rows))
    rows[r][1] = '"' + rows[r][1]
    return _join(rows), None


MUTATIONS = [bad_number, short_row, long_row, swap_times, repeat_row, drop_column, duplicate_column,
             empty_name, partial_derivatives, too_few, header_only, empty, binary, not_utf8,
             random_bytes, semicolons, unterminated_quote]


def non_uniform(rng, rows):
    """Without derivative columns, a jittered time step: no longer refused (issue 44: the file is
    read through the recording pipeline, resampled; tests/test_logs_round_two.py)."""
    r = rng.randrange(2, len(rows) - 1)
    t0, t1 = float(rows[r - 1][0]), float(rows[r][0])
    rows[r][0] = repr(t0 + (t1 - t0) * rng.uniform(0.3, 0.7))
    return _join(rows), f"row {r + 1}, column t"


CASES = [(m, seed, False) for m in MUTATIONS for seed in range(6)]


@pytest.mark.parametrize("seed", range(3))
def test_a_jittered_step_without_derivatives_is_read_as_a_recording(valid, tmp_path, seed):
    """Before issue 44 exit 2 ("qdd can only be estimated from uniformly sampled data")."""
    content, _ = non_uniform(random.Random(f"non_uniform-{seed}"), _fields(valid[1]))
    path = tmp_path / "jittered.csv"
    path.write_text(content)
    result = CliRunner().invoke(main, ["identify", MECH, str(path), "--solver", "dp", "--format", "json"])
    assert result.exit_code == 0, result.output
    assert any("irregular time stamps: read as a recording" in n for n in json.loads(result.stdout)["notes"])


@pytest.mark.parametrize("mutation, seed, bare", CASES,
                         ids=[f"{m.__name__}-{s}" for m, s, _ in CASES])
def test_broken_file_is_exit_2_with_file_and_place(valid, tmp_path, mutation, seed, bare):
    rng = random.Random(f"{mutation.__name__}-{seed}")
    rows = _fields(valid[1] if bare else valid[0])
    content, place = mutation(rng, rows)
    path = tmp_path / f"{mutation.__name__}.csv"
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    result = CliRunner().invoke(main, ["identify", MECH, str(path), "--solver", "dp"])
    assert result.exit_code == 2, (result.output, result.exception)
    message = result.stderr
    assert "Traceback" not in result.output and message.startswith("error: ")
    assert len(message.strip().splitlines()) == 1
    assert str(path) in message
    if place:
        assert place in message, message


def test_at_least_a_hundred_cases():
    assert len(CASES) >= 100


def test_unknown_columns_are_not_an_error(valid, tmp_path):
    rows = _fields(valid[0])
    rows[0].append("temperature")
    for r in rows[1:]:
        r.append("21.5")
    path = tmp_path / "extra.csv"
    path.write_text(_join(rows))
    result = CliRunner().invoke(main, ["identify", MECH, str(path), "--solver", "dp", "--format", "json"])
    assert result.exit_code == 0, result.output
    assert "temperature" in result.stdout


def test_missing_file_and_directory(tmp_path):
    for target in (tmp_path / "nope.csv", tmp_path):
        result = CliRunner().invoke(main, ["identify", MECH, str(target), "--solver", "dp"])
        assert result.exit_code == 2 and str(target) in result.stderr and "Traceback" not in result.output


def test_valid_file_passes(valid, tmp_path):
    path = tmp_path / "ok.csv"
    path.write_text("\n".join(valid[0]) + "\n")
    result = CliRunner().invoke(main, ["identify", MECH, str(path), "--solver", "dp", "--format", "json"])
    assert result.exit_code == 0, result.output
    assert np.isfinite(float(json.loads(result.stdout)["condition_number"]))
