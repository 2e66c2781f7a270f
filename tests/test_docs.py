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
  with placeholders (``MECH``, ``[--digits D]``) go in ```` ```text ```` blocks, not console ones. The command runs in-process through click's CliRunner, in a temporary folder;
- every other block that runs something (issue 45, item 4): every ```` ```python ```` block and
  every command fence (bash, console, plain) with a ``baseparams ...`` or ``python ...`` line,
  in a fresh copy of examples/, tests/data and docs/ with no ``../shared`` beside it; a block
  that cannot run as written says why in ``<!-- not run: reason -->`` just above its fence, and
  an unmarked block that fails is reported as ``file:line`` (``test_doc_blocks_run`` below).

And the command line's own help (every option's help and every command's docstring) cites
only URLs or files the wheel installs: docs/ is not installed.
"""

from __future__ import annotations

import glob
import importlib
import os
import re
import shlex
import shutil
import subprocess
import sys
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
    at: int = 0                                          # the line in the file (1-based)

    @property
    def id(self) -> str:
        return f"{self.source}: {self.line[:70]}"


def console_examples(text: str, source: str = "") -> list[Example]:
    examples: list[Example] = []
    for m in FENCE_RE.finditer(text):
        if m.group(1) != "console":
            continue
        current = None
        first = text.count("\n", 0, m.start()) + 2
        for k, raw in enumerate(m.group(2).splitlines()):
            if raw.startswith("$ "):
                current = None
                invocations = baseparams_invocations(raw[2:])
                if invocations:
                    code = EXIT_RE.search(raw)
                    current = Example(source, raw[2:].strip(), invocations[0], int(code.group(1)) if code else 0,
                                      at=first + k)
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
    where = f"{example.source}:{example.at}"
    assert result.exit_code == example.code, (where, result.stdout[-2000:], result.stderr[-2000:])
    assert output_problems(example, result.stdout) == [], where


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


# ----- every Python block and every command block runs (issue 45, item 4) -------------------------
# A block is a fence: ```python, or a command fence (console, bash, sh, shell or plain) with a
# line that runs ``baseparams`` or ``python`` (after ``$ `` and ``VAR=value`` assignments).
# Each runs in a fresh copy of the project's examples/, tests/data and docs/ (cwd at the copy's
# root; no ``../shared`` beside it) with ``baseparams`` and ``python`` this interpreter:
# - python: the block's text on stdin of a fresh interpreter (cwd on sys.path, as in a REPL); it
#   must exit 0;
# - a command fence with ``$ `` lines: each ``$`` command (continuations joined) in one bash
#   session, exiting with the code its comment prints (``# exit 2``; 0 when none), and the lines
#   printed below it found in its stdout as for console blocks (``...`` ends a prefix; timings
#   skipped);
# - a command fence without ``$``: the block is a bash script, run with ``set -e``.
# Console blocks whose ``$`` lines are all ``baseparams`` run through ``test_console_examples_run``
# above (in-process, faster); they are not run twice.
# A block that cannot run as written (placeholders, a synopsis, a benchmark, data outside the
# project) carries ``<!-- not run: reason -->`` on the line just above its fence; an unmarked
# block that fails is a failure reported as ``file:line``.
NOT_RUN_RE = re.compile(r"^<!--\s*not run:\s*(.+?)\s*-->\s*$")
COMMAND_RE = re.compile(r"^(?:\$ )?(?:[A-Z_]+=\S+ )*(baseparams|python)\b")


@dataclass
class Block:
    """One fenced block of a markdown file: where it starts (the fence's line, 1-based)."""
    source: str
    line: int
    language: str
    body: str
    not_run: str | None = None

    @property
    def id(self) -> str:
        return f"{self.source}:{self.line}"

    @property
    def kind(self) -> str | None:
        """'python', 'console' (run by test_console_examples_run), 'commands' (``$`` lines),
        'script' (a bash script), or None: nothing to run."""
        if self.language == "python":
            return "python"
        if self.language not in COMMAND_LANGUAGES:
            return None
        lines = [raw.strip() for raw in self.body.splitlines()]
        if not any(COMMAND_RE.match(line) for line in lines):
            return None
        dollars = [line[2:] for line in lines if line.startswith("$ ")]
        if dollars:
            if self.language == "console" and all(baseparams_invocations(d) for d in dollars):
                return "console"
            return "commands"
        return "script"


def blocks(text: str, source: str = "") -> list[Block]:
    out = []
    for m in FENCE_RE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        marked = NOT_RUN_RE.match(before.strip())
        out.append(Block(source, line, m.group(1), m.group(2), marked.group(1) if marked else None))
    return out


def runnable_blocks(text: str, source: str = "") -> list[Block]:
    return [b for b in blocks(text, source) if b.kind is not None]


def block_commands(block: Block) -> list[Example]:
    """The ``$`` commands of a block, with their expected exit code and printed lines
    (``Example.line`` is the command as bash gets it; ``source`` its ``file:line``)."""
    examples: list[Example] = []
    current, pending, start = None, None, 0
    for k, raw in enumerate(block.body.splitlines()):
        if pending is not None:
            pending += " " + raw.strip()
        elif raw.startswith("$ "):
            pending, start = raw[2:].strip(), k
        else:
            if current is not None and raw.strip():
                current.output.append(raw)
            continue
        if pending.endswith("\\"):
            pending = pending[:-1].rstrip()
            continue
        code = EXIT_RE.search(pending)
        current = Example(f"{block.source}:{block.line + 1 + start}", pending, [], int(code.group(1)) if code else 0)
        examples.append(current)
        pending = None
    return examples


def block_script(block: Block) -> tuple[str, list[Example]]:
    """The bash script that runs a block's commands, each one's stdout, stderr and exit code
    to ``.doc_out_K``, ``.doc_err_K``, ``.doc_rc_K`` (a script block: the block itself, set -e)."""
    if block.kind == "script":
        return "set -e\n" + block.body, []
    commands = block_commands(block)
    parts = []
    for k, example in enumerate(commands):
        parts.append(f"{{ {example.line}\n}} > .doc_out_{k} 2> .doc_err_{k}\necho $? > .doc_rc_{k}\n")
    return "".join(parts), commands


DOC_COPY = ("examples", "tests/data", "docs")


@pytest.fixture(scope="session")
def project_template(tmp_path_factory) -> Path:
    """The project files the docs' commands read, copied away from ``../shared``, and ``bin/``
    with ``baseparams`` and ``python`` running this interpreter."""
    base = tmp_path_factory.mktemp("docs_template")
    for part in DOC_COPY:
        shutil.copytree(ROOT / part, base / "project" / part,
                        ignore=shutil.ignore_patterns("__pycache__", "*.png"))
    bin_dir = base / "bin"
    bin_dir.mkdir()
    for name, command in (("baseparams", f'"{sys.executable}" -m baseparams'), ("python", f'"{sys.executable}"')):
        (bin_dir / name).write_text(f'#!/bin/sh\nexec {command} "$@"\n')
        (bin_dir / name).chmod(0o755)
    return base


def run_block(block: Block, template: Path, tmp_path: Path) -> list[str]:
    """Run one block in a fresh copy of the project; the problems found, each with file:line."""
    project = tmp_path / "project"
    shutil.copytree(template / "project", project)
    env = dict(os.environ, PATH=f"{template / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}", MPLBACKEND="Agg",
               PYTHONPATH="")
    env.pop("PYTHONSTARTUP", None)
    if block.kind == "python":
        done = subprocess.run([sys.executable, "-"], input=block.body, cwd=project, env=env,
                              capture_output=True, text=True, timeout=1800)
        if done.returncode != 0:
            return [f"{block.id}: python block exited {done.returncode}:\n{done.stderr[-3000:]}"]
        return []
    script, commands = block_script(block)
    done = subprocess.run(["bash", "-c", script], cwd=project, env=env, capture_output=True, text=True,
                          timeout=1800)
    if block.kind == "script":
        if done.returncode != 0:
            return [f"{block.id}: script exited {done.returncode}:\n{done.stdout[-1500:]}\n{done.stderr[-3000:]}"]
        return []
    problems = []
    for k, example in enumerate(commands):
        code = int((project / f".doc_rc_{k}").read_text())
        stdout = (project / f".doc_out_{k}").read_text()
        stderr = (project / f".doc_err_{k}").read_text()
        if code != example.code:
            problems.append(f"{example.source}: {example.line!r} exited {code}, not {example.code}:\n{stderr[-3000:]}")
        elif missing := output_problems(example, stdout):
            problems.append(f"{example.source}: {example.line!r}: lines not printed: {missing}\n"
                            f"--- stdout ---\n{stdout[-3000:]}")
    return problems


BLOCKS = [block for doc in DOCS for block in runnable_blocks(doc.read_text(encoding="utf-8"), doc.name)]
# Blocks that took more than 6 s (wall seconds with `-m "slow or not slow" --durations=0` on the
# shared 2-core machine, load about 2), keyed by file and the start of the block's first line so
# that edits above a block do not move it; they run with ``-m slow``. The others add about 30 s.
SLOW_BLOCKS: dict[tuple[str, str], float] = {
    ("README.md", "$ baseparams excite examples/data/tx40/"): 39.7,
    ("identification.md", "$ baseparams simulate sla_suspension -o sla.csv --effect spring"): 11.9,
    ("README.md", "$ baseparams simulate sla_suspension -o sla.csv --samples 2000"): 10.1,
    ("urdf.md", "baseparams show tests/data/urdf/gripper_arm.urdf"): 9.9,
    ("diagnosis.md", "baseparams simulate sla_suspension -o sla.csv --samples 2000"): 7.7,
    ("README.md", "$ baseparams solve tests/data/urdf/ur5.urdf --solver dp"): 7.3,
    ("performance.md", "baseparams export puma560 --to python"): 7.2,
}


def _slow(block: Block) -> bool:
    first = block.body.strip().splitlines()[0].strip()
    return any(block.source == source and first.startswith(start) for source, start in SLOW_BLOCKS)


def _block_params():
    out = []
    for block in BLOCKS:
        if block.kind == "console":
            continue
        marks = []
        if block.not_run:
            marks.append(pytest.mark.skip(reason=f"not run: {block.not_run}"))
        elif _slow(block):
            marks.append(pytest.mark.slow)
        out.append(pytest.param(block, id=block.id, marks=marks))
    return out


@pytest.mark.parametrize("block", _block_params())
def test_doc_blocks_run(block, project_template, tmp_path):
    problems = run_block(block, project_template, tmp_path)
    assert not problems, "\n".join(problems)


def test_block_finder_on_a_sample():
    text = ("```python\nprint(1)\n```\n\n<!-- not run: a placeholder -->\n```\n$ baseparams solve robot.urdf\n```\n"
            "```\nerror: x\n```\n```bash\nE=1\npython -c 'print(2)'\n```\n"
            "```console\n$ baseparams list\n$ python x.py   # exit 1\nout\n```\n")
    found = runnable_blocks(text, "x.md")
    assert [(b.line, b.kind, b.not_run) for b in found] == [
        (1, "python", None), (6, "commands", "a placeholder"), (12, "script", None), (16, "commands", None)]
    commands = block_commands(found[3])
    assert [(c.source, c.line, c.code, c.output) for c in commands] == [
        ("x.md:17", "baseparams list", 0, []), ("x.md:18", "python x.py   # exit 1", 1, ["out"])]


def test_block_runner_fails_on_a_wrong_block(project_template, tmp_path):
    """An unmarked block that fails is a failure naming its file and line."""
    bad = Block("x.md", 7, "", "$ baseparams solve pendulum --solver dp\npendulum: dp solver, 10 parameters, rank 4\n")
    [problem] = run_block(bad, project_template, tmp_path / "a")
    assert problem.startswith("x.md:8: 'baseparams solve pendulum --solver dp': lines not printed")
    good = Block("x.md", 7, "", "$ baseparams solve pendulum --solver dp\npendulum: dp solver, 10 parameters, rank 3\n")
    assert run_block(good, project_template, tmp_path / "b") == []
    crash = Block("x.md", 1, "python", "import baseparams as bp\nbp.solve('no_such_mechanism')\n")
    [problem] = run_block(crash, project_template, tmp_path / "c")
    assert problem.startswith("x.md:1: python block exited 1") and "no_such_mechanism" in problem
    assert not Path(tmp_path / "c" / "shared").exists()


def test_every_block_runs_or_says_why():
    """The census: the blocks that run, and the marked ones each with a reason."""
    kinds = [b.kind for b in BLOCKS]
    assert kinds.count("python") >= 10 and kinds.count("commands") + kinds.count("script") >= 10
    assert all(b.not_run.strip() for b in BLOCKS if b.not_run)
    for source, start in SLOW_BLOCKS:               # a stale key would silently run a block by default
        assert sum(b.source == source and b.body.strip().startswith(start) for b in BLOCKS) == 1, (source, start)
    # a console block with a command that is not baseparams runs as a command block
    assert all(b.kind != "console" or all(baseparams_invocations(e.line) for e in console_examples(
        f"```console\n{b.body}```\n")) for b in BLOCKS)
