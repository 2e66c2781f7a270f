"""The options every verb spells the same way (docs/cli.md, "One grammar"), the output
file behind ``-o``, and the progress display on stderr."""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

import click

from baseparams.api.solving import DEFAULT_SOLVER
from baseparams.model.mechanism import MAX_SAMPLES
from baseparams.solvers.protocol import MAX_SEED

F = TypeVar("F", bound=Callable[..., Any])


Decorator = Callable[[F], F]


def paths_after(args: list[str], options: Iterable[str]) -> list[str]:
    """``args`` with every path after ``OPTION VALUE`` (an option of ``options``) up to the next
    option read as another value of it: ``--baseline B1 B2`` as ``--baseline B1 --baseline B2``.
    Why: click gives an option one value, so the usage line's ``--baseline BASE...`` read B2 as
    a changed run (the baseline's own run among the changed ones halved a payload found), and
    ``--validate V1 V2`` fitted V2. The verb's own paths (DATA) go before such an option."""
    names = tuple(options)
    out: list[str] = []
    taking = ""
    for k, token in enumerate(args):
        if token == "--":
            return out + args[k:]
        if taking and not token.startswith("-"):
            out += [taking, token]
            continue
        taking = next((n for n in names if token.startswith(n + "=")), "") or \
            (out[-1] if out and out[-1] in names and not token.startswith("-") else "")
        out.append(token)
    return out


class PathsAfterOptions(click.Command):
    """A verb whose options :attr:`greedy` take every path after them (:func:`paths_after`);
    its paths before them (:attr:`paths`, the argument's name) are then required there."""
    greedy: tuple[str, ...] = ()
    paths = "data_paths"

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        read = paths_after(list(args), self.greedy)
        try:
            return super().parse_args(ctx, read)
        except click.MissingParameter as exc:
            if read != list(args) and exc.param is not None and exc.param.name == self.paths:
                taken = " / ".join(self.greedy)
                raise click.BadParameter(f"none given: every path after {taken} is one of its runs; put "
                                         f"{exc.param.human_readable_name} before {taken}",
                                         ctx=ctx, param=exc.param) from None
            raise


def output_option(help: str = "Write the output to FILE (atomically) instead of standard output.",
                  required: bool = False) -> Decorator:
    """``-o/--output FILE``: the verb's output goes there; standard output when absent.
    ``required``: no default at all (click 8.3 and later take an explicit ``default=None`` as a
    value given, and a required ``-o`` was None: ``plot`` ended in a TypeError, issue 46)."""
    if required:
        return click.option("-o", "--output", "output", type=click.Path(dir_okay=False), required=True,
                            metavar="FILE", help=help)
    return click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
                        metavar="FILE", help=help)


def solver_option(help: str = "A registered solver (`baseparams plugins` lists them).",
                  default: str = DEFAULT_SOLVER) -> Decorator:
    """``--solver NAME`` (one solver; the default is the same on every verb)."""
    return click.option("--solver", "solver_name", default=default, show_default=True, metavar="NAME", help=help)


def solvers_option(help: str, default: tuple[str, ...] = ()) -> Decorator:
    """``--solver NAME`` repeatable (verbs that run several), with the comma-separated
    ``--solvers A,B`` of earlier releases still read (deprecated: a note on stderr)."""
    def decorate(function: F) -> F:
        function = click.option("--solver", "solver_names", multiple=True, default=default, metavar="NAME",
                                show_default=bool(default), help=help + " Repeat the option for several.")(function)
        return click.option("--solvers", "old_solvers", default=None, hidden=True,
                            help="Deprecated spelling of repeated --solver (A,B,...).")(function)
    return decorate


def chosen_solvers(names: Iterable[str], old: str | None) -> list[str]:
    """The solvers of a repeatable ``--solver`` and the deprecated ``--solvers A,B``."""
    out = list(names)
    if old is not None:
        click.echo("note: --solvers A,B is deprecated; repeat --solver instead (--solver A --solver B)", err=True)
        out += [s.strip() for s in old.split(",") if s.strip()]
    return list(dict.fromkeys(out))


def solver_options_option() -> Decorator:
    """``-O NAME=VALUE``: any option the chosen solver declares, repeatable."""
    return click.option("-O", "--option", "extra", multiple=True, metavar="NAME=VALUE",
                        help="An option the solver declares (`baseparams solve --help` lists them), e.g. "
                             "-O digits=40; repeatable. An option it does not declare is an error (exit 2).")


def samples_option(help: str = "Samples of the exciting trajectory [default: the mechanism file's].",
                   default: int | None = None) -> Decorator:
    """``--samples N``: 2 to 10^6 on every verb (a verb may need more than 2 and says so)."""
    return click.option("--samples", type=click.IntRange(2, MAX_SAMPLES), default=default,
                        show_default=default is not None, help=help + f" 2 to {MAX_SAMPLES:,}.")


def seed_option(help: str = "Seed of the random numbers.", default: int | None = 0) -> Decorator:
    """``--seed N``: 0 to 2^32 - 1 on every verb that draws random numbers."""
    return click.option("--seed", type=click.IntRange(0, MAX_SEED), default=default,
                        show_default=default is not None, help=help + " 0 to 2^32 - 1.")


def format_option(*choices: str, help: str = "Output format: readable text or one JSON object.") -> Decorator:
    """``--format``: text (the default) or one JSON object, or a verb's own ``choices``
    (``solve``: text, json, csv; ``report``: text, markdown, latex). Never an image format
    (plots take ``--image-format``)."""
    return click.option("--format", "fmt", type=click.Choice(list(choices or ("text", "json"))), default="text",
                        show_default=True, help=help)


MAX_WORKERS = 256


def workers_option(help: str = "Run the jobs in this many local worker processes.") -> Decorator:
    """``--workers N``: 1 to 256 local processes, on the verbs whose work splits into
    independent jobs (``validate``: mechanism x solver; ``excite``: the starts)."""
    return click.option("--workers", type=click.IntRange(1, MAX_WORKERS), default=None, metavar="N",
                        help=help + f" 1 to {MAX_WORKERS} [default: in this process].")


def scheduler_option(help: str = "Run the jobs on a Dask scheduler (tcp://host:8786), or 'local' for a "
                                 "LocalCluster of --workers processes; needs pip install 'baseparams[distributed]'.") \
        -> Decorator:
    """``--scheduler ADDRESS``: beside ``--workers`` wherever it is."""
    return click.option("--scheduler", default=None, metavar="ADDRESS", help=help)


def quiet_option() -> Decorator:
    """``--quiet``: no progress on stderr (warnings and errors are still printed)."""
    return click.option("--quiet", is_flag=True, help="No progress display on stderr (warnings are still printed).")


def image_format_option() -> Decorator:
    """``--image-format png|pdf|svg`` (plot verbs); by default the output's suffix says."""
    return click.option("--image-format", "image_format", type=click.Choice(["png", "pdf", "svg"]), default=None,
                        help="Image format [default: from the file name's suffix, else png].")


def write_output(output: str | None, text: str) -> None:
    """``text`` to standard output, or atomically to ``output`` with a ``wrote`` line on stderr."""
    if output is None:
        click.echo(text)
        return
    from baseparams.io.atomic import atomic_write
    atomic_write(output, text if text.endswith("\n") else text + "\n", what="the output")
    click.echo(f"wrote {output}", err=True)


def emit(fmt: str, data: Any, text: str | Callable[[], str], output: str | None = None) -> None:
    """Print ``data`` as JSON or ``text`` (a string or a callable returning one), to
    standard output or to the file ``output``."""
    if fmt == "json":
        write_output(output, json.dumps(data, indent=2))
    else:
        write_output(output, text() if callable(text) else text)


class Progress:
    """Progress on stderr for work that can take more than 2 s: a bar on a terminal
    (redrawn on one line); elsewhere (logs, pipes) one line per step, starting only once
    the work has run for ``AFTER`` seconds, so quick runs and input errors print nothing
    but their result. ``quiet``: nothing at all.

    Call it with a message (a step of ``steps``) or use :meth:`counted` for ``(done,
    total, label)`` callbacks (jobs, starts). Use as a context manager: the bar's line is
    ended, and the pending line dropped, when the work ends."""

    WIDTH = 24
    AFTER = 2.0

    def __init__(self, verb: str, *, steps: int = 0, quiet: bool = False) -> None:
        self.verb, self.steps, self.quiet = verb, steps, quiet
        self.tty = sys.stderr.isatty()
        self.done, self.start, self.drawn = 0, time.monotonic(), False
        self.latest: tuple[int, int, str] | None = None
        self.lock = threading.Lock()
        self.timer: threading.Timer | None = None
        if not quiet and not self.tty:
            self.timer = threading.Timer(self.AFTER, self._late)
            self.timer.daemon = True
            self.timer.start()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: object) -> None:
        if self.timer is not None:
            self.timer.cancel()
        with self.lock:
            if self.drawn:
                click.echo("", err=True)
                self.drawn = False

    def __call__(self, message: str) -> None:
        self.done += 1
        self.show(self.done, self.steps, message)

    def counted(self, done: int, total: int, label: str) -> None:
        self.show(done, total, label)

    def _late(self) -> None:
        """The work has run for AFTER seconds: show the step it is at."""
        with self.lock:
            latest = self.latest
        if latest is not None:
            self._line(*latest)

    def _line(self, done: int, total: int, label: str) -> None:
        count = f" [{done}/{total}]" if total else ""
        click.echo(f"{self.verb}{count}: {label} ({time.monotonic() - self.start:.0f} s)", err=True)

    def show(self, done: int, total: int, label: str) -> None:
        if self.quiet:
            return
        with self.lock:
            self.latest = (done, total, label)
        if not self.tty:
            if time.monotonic() - self.start >= self.AFTER:
                self._line(done, total, label)
            return
        bar = ""
        if total:
            filled = int(self.WIDTH * min(done, total) / total)
            bar = f"[{'#' * filled}{'-' * (self.WIDTH - filled)}] {done}/{total} "
        line = f"{self.verb} {bar}{label} ({time.monotonic() - self.start:.0f} s)"
        with self.lock:
            click.echo("\r\033[K" + line[:200], err=True, nl=False)
            self.drawn = True
