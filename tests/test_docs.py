"""Docs that cannot drift (issue 23, item 7): README.md and docs/*.md against the code.

What is checked, for every markdown file:

- every repository path it cites (``core/...``, ``plugins/...``, ``tests/...``,
  ``benchmarks/...``, ``docs/...``, ``examples/...``, ``mechanisms/...``; globs allowed) exists,
  and every markdown link to a local file;
- every dotted name ``baseparams.x.y`` imports (the longest importable module, then attributes);
- every command line ``baseparams VERB ...`` (console, bash and plain code blocks, inline code)
  names a verb of the click group (a subcommand for ``plot``) and only options that verb has;
  every option cited alone in inline code (`` `--workers N` ``) belongs to some verb;
- the ```` ```console ```` examples run: each ``$ baseparams ...`` line exits with the code its
  comment prints (``# exit 2``; 0 when none), and every output line printed below it appears in
  the output (a line cut with ``...`` as a prefix; lines with timings such as ``0.7s`` are skipped).
  Rule for the default run: a console command runs there when it took at most 3 s in-process
  on the 2-core machine (``SLOW`` below lists the others with their measured time; they run
  with ``-m slow``), so that all of them together add about 12 s to the default run. Synopses
  with placeholders (``MECH``, ``[--digits D]``) go in ```` ```text ```` blocks, not console ones. The command runs in-process through click's CliRunner, in a temporary folder.

And the command line's own help (every option's help and every command's docstring) cites
only URLs or files the wheel installs: docs/ is not installed.
"""

from __future__ import annotations

import glob
import importlib
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from baseparams.cli import main

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

PATH_RE = re.compile(r"(?<![\w./-])((?:core|plugins|tests|benchmarks|docs|examples|mechanisms)/[\w.*/-]*[\w*/])")
DOTTED_RE = re.compile(r"(?<![\w./-])(baseparams(?:\.\w+)+)")
FENCE_RE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.S | re.M)
INLINE_RE = re.compile(r"`([^`\n]+)`")
OPTION_RE = re.compile(r"^--[a-z][\w-]*$")
TIMING_RE = re.compile(r"\b\d+(\.\d+)?\s?(s|ms)\b")
EXIT_RE = re.compile(r"#.*\bexit (\d)\b")
COMMAND_LANGUAGES = ("console", "bash", "sh", "shell", "")


# ----- the checker: pure functions of markdown text ------------------------------------------
def cited_paths(text: str) -> list[str]:
    """Repository paths the text cites, in order (sentence-final dots stripped)."""
    return [m.group(1).rstrip(".") for m in PATH_RE.finditer(text)]


def missing_paths(text: str, root: Path = ROOT) -> list[str]:
    """Cited paths that do not exist under ``root`` (a glob must match something)."""
    out = []
    for path in cited_paths(text):
        found = glob.glob(str(root / path)) if "*" in path else (root / path).exists()
        if not found:
            out.append(path)
    return out


LINK_RE = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def missing_links(text: str, folder: Path) -> list[str]:
    """Markdown links ``[text](target)`` to local files that do not exist (relative to the
    document's folder, as a reader's browser resolves them); URLs are not fetched."""
    return [m.group(1) for m in LINK_RE.finditer(text)
            if not re.match(r"[a-z]+:", m.group(1)) and not (folder / m.group(1)).exists()]


def resolves(name: str) -> bool:
    """``baseparams.a.b.C``: the longest importable module prefix, then attributes."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def unresolved_names(text: str) -> list[str]:
    return [name for name in dict.fromkeys(m.group(1) for m in DOTTED_RE.finditer(text)) if not resolves(name)]


def _outside_fences(text: str) -> str:
    return FENCE_RE.sub("", text)


def command_lines(text: str) -> list[str]:
    """Shell lines that may run ``baseparams``: every line of bash blocks, the ``$ `` lines of
    console and plain blocks (continuations joined), and inline code spans."""
    lines = []
    for m in FENCE_RE.finditer(text):
        language, body = m.group(1), m.group(2)
        if language not in COMMAND_LANGUAGES:
            continue
        pending = None
        for raw in body.splitlines():
            line = raw.strip()
            if pending is not None:
                pending += " " + line
            elif language in ("bash", "sh", "shell") or line.startswith("$ "):
                pending = line.removeprefix("$ ")
            else:
                continue
            if pending.endswith("\\"):
                pending = pending[:-1]
            else:
                lines.append(pending)
                pending = None
    lines += [m.group(1) for m in INLINE_RE.finditer(_outside_fences(text))]
    return lines


def baseparams_invocations(line: str) -> list[list[str]]:
    """The argument lists of every ``baseparams ...`` (or ``python -m baseparams ...``) in a
    shell line: its parts between ``&&``, ``||``, ``;`` and ``|``, comments dropped."""
    out = []
    for part in re.split(r"&&|\|\||;|(?<![\w\]])\|(?![\w<])", line):
        try:
            tokens = shlex.split(part, comments=True)
        except ValueError:
            tokens = part.split()
        if tokens[:1] == ["baseparams"]:
            out.append(tokens[1:])
        elif tokens[1:3] == ["-m", "baseparams"]:
            out.append(tokens[3:])
    return out


def _options(command: click.Command) -> set[str]:
    found = {"--help", "-h"}
    for param in command.params:
        if isinstance(param, click.Option):
            found.update(param.opts + param.secondary_opts)
    return found


def cli_problems(text: str, group: click.Group = main) -> list[str]:
    """Verbs and options of ``baseparams`` command lines that the click group does not have."""
    problems = []
    for line in command_lines(text):
        for args in baseparams_invocations(line):
            allowed, command, words = _options(group), group, list(args)
            while words and words[0].startswith("-"):           # global options (--debug)
                words.pop(0)
            while isinstance(command, click.Group) and words and not words[0].startswith("-"):
                verb = words.pop(0)
                if verb.isupper() or verb == "...":                # a placeholder: VERB, ...
                    command = None
                    break
                if verb not in command.commands:
                    if command is group or not re.match(r"^[a-z][\w-]*$", verb):
                        problems.append(f"{line!r}: no verb {verb!r}")
                    else:
                        problems.append(f"{line!r}: {command.name} has no subcommand {verb!r}")
                    command = None
                    break
                command = command.commands[verb]
                allowed |= _options(command)
            if command is None:
                continue
            for word in words:
                option = word.strip("[]()").split("=")[0]
                if option.startswith("-") and len(option) > 1 and not re.match(r"^-\d", option) \
                        and option not in allowed:
                    problems.append(f"{line!r}: {command.name} has no option {option}")
    return problems


def every_option(group: click.Group = main) -> set[str]:
    found = set(_options(group))
    for command in group.commands.values():
        found |= _options(command)
        if isinstance(command, click.Group):
            found |= every_option(command)
    return found


def script_options(script: Path) -> set[str]:
    """The ``--options`` a benchmark script's argument parser declares."""
    return set(re.findall(r"[\"'](--[a-z][\w-]*)[\"']", script.read_text(encoding="utf-8")))


BENCH_RE = re.compile(r"(?<![\w./-])(benchmarks/\w+\.py)([^&|;#`]*)")
PYTEST_OPTIONS = {"--durations"}


def benchmark_problems(text: str, root: Path = ROOT) -> list[str]:
    """Options given to a ``benchmarks/*.py`` script in a command line that it does not declare."""
    problems = []
    for line in command_lines(text):
        for m in BENCH_RE.finditer(line):
            script = root / m.group(1)
            if not script.exists():
                continue                                  # reported by missing_paths
            declared = script_options(script)
            for word in m.group(2).split():
                option = word.strip("[]()").split("=")[0]
                if OPTION_RE.match(option) and option not in declared:
                    problems.append(f"{line!r}: {m.group(1)} has no option {option}")
    return problems


def unknown_cited_options(text: str, group: click.Group = main) -> list[str]:
    """Options cited alone in inline code (`` `--workers N` ``) that neither a verb nor a
    benchmark script (nor pytest: ``--durations``) has."""
    known = every_option(group) | PYTEST_OPTIONS
    for script in (ROOT / "benchmarks").glob("*.py"):
        known |= script_options(script)
    out = []
    for m in INLINE_RE.finditer(_outside_fences(text)):
        first = m.group(1).split()[0].split("=")[0]
        if OPTION_RE.match(first) and first not in known:
            out.append(first)
    return out


@dataclass
class Example:
    """One ``$ baseparams ...`` line of a console block and the output printed below it."""
    source: str
    line: str
    args: list[str]
    code: int
    output: list[str] = field(default_factory=list)

    @property
    def id(self) -> str:
        return f"{self.source}: {self.line[:70]}"


def console_examples(text: str, source: str = "") -> list[Example]:
    examples: list[Example] = []
    for m in FENCE_RE.finditer(text):
        if m.group(1) != "console":
            continue
        current = None
        for raw in m.group(2).splitlines():
            if raw.startswith("$ "):
                current = None
                invocations = baseparams_invocations(raw[2:])
                if invocations:
                    code = EXIT_RE.search(raw)
                    current = Example(source, raw[2:].strip(), invocations[0], int(code.group(1)) if code else 0)
                    examples.append(current)
            elif current is not None and raw.strip():
                current.output.append(raw)
    return examples


def output_problems(example: Example, stdout: str) -> list[str]:
    """Printed lines missing from ``stdout`` (whitespace collapsed; ``...`` ends a prefix)."""
    def flat(s: str) -> str:
        return " ".join(s.split())
    got = [flat(line) for line in stdout.splitlines()]
    problems = []
    for line in example.output:
        want = flat(line.split("...")[0])
        if not want or TIMING_RE.search(line):
            continue
        if not any(g.startswith(want) if "..." in line else g == want for g in got):
            problems.append(line)
    return problems


# ----- the checker on small synthetic markdown (it can fail) ----------------------------------
SAMPLE = """See `core/errors.py`, [the design](docs/design.md) and `tests/test_*.py`; https://x.org/core/no.py
is a URL. `baseparams.errors.InputError` and `baseparams.io.loader` resolve.

```console
$ baseparams solve pendulum --solver dp    # exit 0
pendulum: dp solver, 10 parameters, rank 3
```

`baseparams validate --all --workers 2` and `--samples N`.
"""


def test_checker_passes_a_true_sample():
    assert cited_paths(SAMPLE) == ["core/errors.py", "docs/design.md", "tests/test_*.py"]
    assert missing_paths(SAMPLE) == []
    assert unresolved_names(SAMPLE) == []
    assert cli_problems(SAMPLE) == [] and unknown_cited_options(SAMPLE) == []
    [example] = console_examples(SAMPLE)
    assert example.args == ["solve", "pendulum", "--solver", "dp"] and example.code == 0


def test_checker_fails_when_a_cited_path_is_renamed(tmp_path):
    """The done-when of item 7: rename a cited file and the check names it."""
    (tmp_path / "core").mkdir()
    (tmp_path / "core" / "backends.py").write_text("")
    text = "The backends (`core/backends.py`)."
    assert missing_paths(text, tmp_path) == []
    (tmp_path / "core" / "backends.py").rename(tmp_path / "core" / "arithmetic.py")
    assert missing_paths(text, tmp_path) == ["core/backends.py"]
    assert missing_links("[x](urdf.md#top) [y](https://a.b/c.md)", tmp_path) == ["urdf.md"]


def test_checker_fails_on_stale_names_verbs_options_and_output():
    assert unresolved_names("`baseparams.numeric.krawczyk` and `baseparams.errors.NoSuchError`") == [
        "baseparams.numeric.krawczyk", "baseparams.errors.NoSuchError"]
    assert len(cli_problems("`baseparams slove pendulum`")) == 1
    assert len(cli_problems("```bash\nbaseparams solve pendulum --solvers dp\n```\n")) == 1
    assert len(cli_problems("`baseparams plot mechanisms x`")) == 1
    assert cli_problems("`pip install . && baseparams validate --all --workers 2`") == []
    assert unknown_cited_options("use `--wokers 2`") == ["--wokers"]
    assert benchmark_problems("`python benchmarks/bench_solvers.py --no-such-flag`") == [
        "'python benchmarks/bench_solvers.py --no-such-flag': benchmarks/bench_solvers.py has no option --no-such-flag"]
    example = Example("x", "", [], 0, ["joints (5):", "  Fixed  baseparams  rigid ...", "x 0.4s ok"])
    assert output_problems(example, "joints (6):\n  Fixed  baseparams  rigid connection\n") == ["joints (5):"]


# ----- the real docs ----------------------------------------------------------------------------
@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_paths_exist(doc):
    assert missing_paths(doc.read_text(encoding="utf-8")) == []
    assert missing_links(doc.read_text(encoding="utf-8"), doc.parent) == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_dotted_names_resolve(doc):
    assert unresolved_names(doc.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_verbs_and_options_exist(doc):
    text = doc.read_text(encoding="utf-8")
    assert cli_problems(text) == []
    assert benchmark_problems(text) == []
    assert unknown_cited_options(text) == []


# Seconds measured with `python -m pytest tests/test_docs.py -k console -m "slow or not slow"
# --durations=0` on the 2-core machine (shared, load about 2): the console commands above 3 s.
SLOW = {
    "baseparams validate pendulum four_bar sla_suspension": 11.3,
    "baseparams plot singular-values sla_suspension -o sv.png": 6.9,
    "baseparams solve sla_suspension --solver vp --format json": 4.6,
    "baseparams solve sla_suspension --solver vp": 3.9,
}
EXAMPLES = [example for doc in DOCS for example in console_examples(doc.read_text(encoding="utf-8"), doc.name)]


def _command(example: Example) -> str:
    return " ".join(["baseparams", *example.args])


@pytest.mark.parametrize("example", [pytest.param(e, id=e.id, marks=pytest.mark.slow if _command(e) in SLOW else ())
                                     for e in EXAMPLES])
def test_console_examples_run(example, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, example.args)
    assert result.exit_code == example.code, (result.stdout[-2000:], result.stderr[-2000:])
    assert output_problems(example, result.stdout) == []


def test_there_are_console_examples():
    assert len(EXAMPLES) >= 10 and all(e.args for e in EXAMPLES)


# ----- help texts cite URLs or installed files ----------------------------------------------------
def help_texts(group: click.Group = main) -> list[tuple[str, str]]:
    """(where, text) for every command's help and every parameter's help."""
    out = [(group.name or "baseparams", group.help or "")]
    for name, command in group.commands.items():
        out.append((name, command.help or ""))
        for param in command.params:
            out.append((f"{name} {'/'.join(param.opts)}", getattr(param, "help", None) or ""))
        if isinstance(command, click.Group):
            out += [(f"{name} {where}", text) for where, text in help_texts(command)[1:]]
    return out


def uninstalled_citations(texts: list[tuple[str, str]]) -> list[str]:
    """Repository paths cited in help texts that an installed package does not contain
    (docs/, tests/, benchmarks/ are not in the wheel); URLs are fine."""
    out = []
    for where, text in texts:
        for path in cited_paths(re.sub(r"https?://\S+", "", text)):
            out.append(f"{where}: {path}")
    return out


def test_help_text_checker():
    assert uninstalled_citations([("x", "see docs/cli.md or https://example.org/docs/cli.md")]) == ["x: docs/cli.md"]
    assert uninstalled_citations([("x", "see `baseparams --help`")]) == []
    assert len(help_texts()) > 50


def test_help_texts_cite_only_urls_or_installed_files():
    assert uninstalled_citations(help_texts()) == []
