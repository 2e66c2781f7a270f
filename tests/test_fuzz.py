"""A small subset of the fuzz corpus (tests/fuzz_corpus.py) through the real command line:
every mutation kind of the pendulum file, with ``show`` and ``solve --solver dp``, each in a
fresh interpreter with a CPU-time limit. No run may print a traceback, hang, exit with a
code other than 0 or 2, or exit 0 on input that is invalid.

A known gap would be marked ``xfail(strict=True)`` in KNOWN_GAPS (so that its fix XPASSes
and fails, and the mark goes); there are none. benchmarks/fuzz_mechanisms.py runs the whole
corpus (every built-in mechanism) and prints the table.

Below the corpus, property-based tests (hypothesis) of the loader, in process: any text,
random or a mutated built-in file, gives a Mechanism or an InputError (never another
exception) within a time bound, with a one-line message that names the file and leaks no
Python repr; and the schema's JSON Schema rendering agrees with the validator on every
corpus document (jsonschema as an independent implementation).
"""

import json
import re
import time
import tomllib
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from decimal import Decimal

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzz_corpus
from baseparams.errors import InputError
from baseparams.io.loader import check_trajectory, parse_mechanism
from baseparams.io.schema import json_schema, validate
from baseparams.model.mechanism import Mechanism

MECHANISM = "pendulum"
CPU_LIMIT = 10.0           # seconds of CPU per run: a healthy run of this file takes ~2
CASES = {case.name: case for case in fuzz_corpus.corpus(seed=0, mechanisms=[MECHANISM])}

KNOWN_GAPS: dict = {}       # (case name, command) -> reason, for xfail(strict=True)


def _params():
    for name in CASES:
        for command in fuzz_corpus.COMMANDS:
            reason = KNOWN_GAPS.get((name, command))
            marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
            yield pytest.param(name, command, marks=marks, id=f"{name}-{command}")


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    """All runs at once, two at a time (the subprocesses dominate the time)."""
    directory = tmp_path_factory.mktemp("fuzz")
    jobs = [(CASES[name], command) for name in CASES for command in fuzz_corpus.COMMANDS]
    with ThreadPoolExecutor(2) as pool:
        results = pool.map(lambda job: fuzz_corpus.run_case(*job, directory, CPU_LIMIT), jobs)
        return {(o.case.name, o.command): o for o in results}


@pytest.mark.parametrize("name, command", list(_params()))
def test_bad_file_never_crashes_hangs_or_passes(outcomes, name, command):
    outcome = outcomes[(name, command)]
    assert outcome.verdict == "ok", (f"{outcome.case.detail}: {outcome.verdict} after "
                                     f"{outcome.seconds:.1f} s; stderr ends: {outcome.message}")
    if outcome.returncode == 2:
        assert outcome.message.startswith("error: "), outcome.stderr


def test_known_gaps_name_real_cases():
    assert all(name in CASES and command in fuzz_corpus.COMMANDS for name, command in KNOWN_GAPS)


def test_corpus_is_deterministic_and_covers_every_kind():
    again = fuzz_corpus.corpus(seed=0, mechanisms=[MECHANISM])
    assert [c.data for c in again] == [c.data for c in CASES.values()]
    assert {c.kind for c in CASES.values()} == set(fuzz_corpus.KINDS)
    other = fuzz_corpus.corpus(seed=1, mechanisms=[MECHANISM])
    assert [c.data for c in other] != [c.data for c in again]


@pytest.mark.parametrize("name, path", sorted(fuzz_corpus.mechanism_files().items()))
def test_toml_writer_round_trips_every_builtin_file(name, path):
    """The "identity" case is the original document, so mutations change only what they say."""
    original = tomllib.loads(path.read_text(encoding="utf-8"), parse_float=Decimal)
    rewritten = tomllib.loads(fuzz_corpus.dumps(original), parse_float=Decimal)
    assert rewritten == original


HEAVY = {"puma560", "sla_suspension", "stewart_platform"}     # seconds per load: slow-marked


@pytest.mark.parametrize("mechanism", [
    pytest.param(name, marks=[pytest.mark.slow] if name in HEAVY else [])
    for name in sorted(fuzz_corpus.mechanism_files())])
def test_every_case_is_refused_or_accepted_as_labelled_in_process(mechanism):
    """Every corpus case of a built-in file, in process (no interpreter start-up): an
    "invalid" case raises an InputError from loading plus the trajectory check (what
    ``show`` runs), a "valid" one loads; messages name the file and leak no Python."""
    for case in fuzz_corpus.corpus(seed=0, mechanisms=[mechanism]):
        expect = case.show
        try:
            text = case.data.decode("utf-8")
            mech = parse_mechanism(text, f"{case.name}.toml")
            check_trajectory(mech)
        except UnicodeDecodeError:
            assert expect != "valid", case.detail        # the reader refuses non-UTF-8 (exit 2)
            continue
        except InputError as exc:
            assert expect != "valid", f"{case.name} ({case.detail}): {exc.message}"
            _check_message(exc.message, f"{case.name}.toml")
            continue
        assert expect != "invalid", f"{case.name} ({case.detail}) was accepted"


# ----- property-based: the loader ---------------------------------------------------

LOADER = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
LOAD_SECONDS = 5.0      # CPU seconds (process_time): a loaded machine slows the wall clock, not the work (issue 46)
BASES = [path.read_text(encoding="utf-8") for name, path in sorted(fuzz_corpus.mechanism_files().items())
         if name in ("pendulum", "four_bar", "planar_2r")]
ASSIGNMENT = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*)(\s*=\s*)(.*)$")
VALUES = st.one_of(
    st.sampled_from(['"0"', '"1e400"', "nan", "-inf", '"L/0"', "[]", "{}", "true", '"m2"', "1e999",
                     '"2**2**2**2**2"', '"-1"', "99", "-1", '""', '"t"', "[1, 2]", '["0", "0"]',
                     '["1e-300", "0", "0"]', "{ a = 1 }", '"\\u0000"', "0x10", "1979-05-27",
                     '"sin(t)"', '"E"', '"lambda"', "9" * 5000, '"' + "9" * 300 + '"']),
    st.text(max_size=12).map(json.dumps),
    st.integers(-10 ** 6, 10 ** 6).map(str),
    st.decimals(allow_nan=False, allow_infinity=False, places=4).map(str),
)
KEYS = st.sampled_from(["mass", "mas", "com", "typ", "type", "axis", "axes", "label", "samples", "q",
                        "inertia", "loop", "limits", "coordinates", "kind", "values", "\u043c"])


@st.composite
def mutated_files(draw):
    lines = draw(st.sampled_from(BASES)).splitlines()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["value", "value", "delete", "duplicate", "key", "insert"]))
        match = ASSIGNMENT.match(lines[i])
        if op == "value" and match:
            lines[i] = match[1] + match[2] + match[3] + draw(VALUES)
        elif op == "key" and match:
            lines[i] = match[1] + draw(KEYS) + match[3] + match[4]
        elif op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "insert":
            lines.insert(i, draw(st.one_of(st.text(max_size=30), st.sampled_from(
                ["[[joints]]", "[[bodies]]", "label = 1", "[[effects]]", 'kind = "spring"', "[geometry]",
                 "[trajectory]", "\ufeff", "loop = true"]))))
        if not lines:
            break
    return "\n".join(lines) + "\n"


def _check_message(message: str, path: str) -> None:
    assert message.startswith(path + ": "), message
    assert "\n" not in message and len(message) < 1000, message
    assert not re.search(r"Decimal\(|Fraction\(|<class |Traceback", message), message


def _load(text: str, path: str = "fuzz.toml"):
    start = time.process_time()
    try:
        mech = parse_mechanism(text, path)
        check_trajectory(mech)
    except InputError as exc:
        _check_message(exc.message, path)
        mech = None
    assert time.process_time() - start < LOAD_SECONDS
    return mech


@LOADER
@given(mutated_files())
def test_a_mutated_file_gives_a_mechanism_or_an_input_error(text):
    mech = _load(text)
    assert mech is None or isinstance(mech, Mechanism)


@LOADER
@given(st.one_of(st.text(max_size=200), st.binary(max_size=200).map(lambda b: b.decode("latin-1"))))
def test_any_text_gives_a_mechanism_or_an_input_error(text):
    mech = _load(text)
    assert mech is None or isinstance(mech, Mechanism)


# ----- the schema, twice -------------------------------------------------------------

def _as_json(value):
    """A parsed TOML value as JSON data: a finite Decimal as a float, nan and inf (not JSON)
    as strings, which the schema's value type also allows (the builder refuses them)."""
    if isinstance(value, Decimal):
        return float(value) if value.is_finite() else str(value)
    if isinstance(value, list):
        return [_as_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_json(v) for k, v in value.items()}
    return value


def test_the_json_schema_agrees_with_the_validator():
    jsonschema = pytest.importorskip("jsonschema")
    checker = jsonschema.Draft202012Validator(json_schema())
    jsonschema.Draft202012Validator.check_schema(json_schema())
    seen = {True: 0, False: 0}
    for case in fuzz_corpus.corpus(seed=0) + fuzz_corpus.corpus(seed=1, mechanisms=["pendulum", "four_bar"]):
        try:
            doc = tomllib.loads(case.data.decode("utf-8").removeprefix("\ufeff"), parse_float=Decimal)
        except (UnicodeDecodeError, ValueError):
            continue
        try:
            validate(doc, "x.toml")
            ours = True
        except InputError:
            ours = False
        theirs = checker.is_valid(_as_json(doc))
        assert ours == theirs, (case.name, case.detail)
        seen[ours] += 1
    assert seen[True] > 40 and seen[False] > 20, seen


# ----- bad command-line values (issue 24): options, output targets, scheduler addresses ---------
# In process (CliRunner: no interpreter start-up), so all ~240 cases take seconds; an exception
# other than SystemExit is a traceback the real command line would print.

def _run_command_case(case, env=None):
    from click.testing import CliRunner
    from baseparams.cli.commands import main
    start = time.process_time()           # CPU, not wall: the bound holds on a loaded machine (issue 46)
    result = CliRunner(env=env).invoke(main, list(case.args))
    seconds = time.process_time() - start
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        f"{case.name}: {type(result.exception).__name__}: {result.exception}"
    assert result.exit_code in (0, 2), f"{case.name}: exit {result.exit_code}: {result.output[-300:]}"
    assert "Traceback" not in result.output and "internal error" not in result.output, case.name
    if case.expect == "invalid":
        assert result.exit_code == 2, f"{case.name}: accepted: {result.stdout[:200]}"
    if case.expect == "valid":
        assert result.exit_code == 0, f"{case.name}: {result.stderr[-300:]}"
    if result.exit_code == 2:
        last = [line for line in result.stderr.splitlines() if line.strip()][-1]
        assert last.startswith(("error: ", "Error: ")) and "\n" not in last, (case.name, result.stderr)
        assert result.stdout == "", f"{case.name}: a refused run printed a result"
    assert seconds < 60, (case.name, seconds)


OPTION_CASES = fuzz_corpus.option_cases()


@pytest.mark.parametrize("case", OPTION_CASES, ids=[c.name for c in OPTION_CASES])
def test_a_bad_option_value_is_refused_never_crashes(case):
    _run_command_case(case)


def test_the_option_corpus_covers_every_declared_option():
    from baseparams import registry
    for name, options in fuzz_corpus.OPTION_TYPES.items():
        assert set(options) == {o.name for o in registry.solvers()[name].item.options}, name
    assert len(OPTION_CASES) >= 180          # 182 since dp and exact declare no digits (issue 23)


@pytest.mark.parametrize("case", fuzz_corpus.output_cases("{folder}"),
                         ids=[c.name for c in fuzz_corpus.output_cases("{folder}")])
def test_a_bad_output_target_is_refused_never_crashes(case, tmp_path):
    (tmp_path / "file.txt").write_text("a file, not a folder\n")
    case = fuzz_corpus.CommandCase(case.name, tuple(a.replace("{folder}", str(tmp_path)) for a in case.args),
                                   case.expect)
    if "/dev/full" in case.args and not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    _run_command_case(case)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]        # nothing half-written


@pytest.mark.parametrize("case", fuzz_corpus.scheduler_cases(), ids=[c.name for c in fuzz_corpus.scheduler_cases()])
def test_a_bad_scheduler_address_is_refused_before_any_connection(case):
    _run_command_case(case)
