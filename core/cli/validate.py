"""``baseparams validate``: the orchestrator on the command line (registered on ``main``)."""

import math
import re
import sys

import click

from baseparams.cli.commands import emit, main
from baseparams.orchestrate.runners import make_runner
from baseparams.orchestrate.validate import (mechanism_texts, render_markdown, render_text, select_solvers,
                                             validate as run_validation)
from baseparams import registry


MAX_TIMEOUT_S = 1e7         # about 116 days: past SIGALRM's and the OS timers' range otherwise


class Seconds(click.ParamType):
    """A number of seconds from 0.1 to MAX_TIMEOUT_S in ASCII digits: click's FloatRange
    takes float()'s forms ("1_0" is 10, Arabic-Indic digits) and lets NaN through (every
    comparison with it is false)."""
    name = "seconds"
    _TEXT = re.compile(r"[+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")

    def convert(self, value, param, ctx):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            seconds = float(value)
        elif isinstance(value, str) and self._TEXT.fullmatch(value.strip()):
            seconds = float(value)
        else:
            self.fail(f"{value!r} is not a number of seconds", param, ctx)
        if not (math.isfinite(seconds) and 0.1 <= seconds <= MAX_TIMEOUT_S):
            self.fail(f"{value!r}: give 0.1 to {MAX_TIMEOUT_S:.0e} seconds", param, ctx)
        return seconds


@main.command()
@click.argument("mechs", nargs=-1, metavar="[MECH ...]")
@click.option("--all", "everything", is_flag=True, help="Every registered mechanism.")
@click.option("--solvers", default=None, metavar="A,B,...",
              help="Solvers to run, comma separated [default: every registered solver].")
@click.option("--format", "fmt", type=click.Choice(["text", "json", "markdown"]), default="text",
              show_default=True, help="Report format.")
@click.option("--workers", type=click.IntRange(1, 256), default=None,
              help="Run jobs in this many local worker processes (with --scheduler local: Dask workers).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="A Dask scheduler (tcp://host:8786), or 'local' for a LocalCluster of --workers "
                   "processes; needs pip install 'baseparams[distributed]'.")
@click.option("--timeout", type=Seconds(), default=None, metavar="S", help="Seconds one job may take (0.1 to 10^7); a job past it is reported as "
                                      "timed out.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def validate(mechs, everything, solvers, fmt, workers, scheduler, timeout, quiet):
    """Cross-validate every solver on MECH (or --all registered mechanisms).

    For each mechanism: every applicable solver runs (a solver that does not take the
    mechanism is listed with its reason, not as a failure); the model is checked in ball
    arithmetic (energy balance, every joint type's transfer rules); the results are
    compared with the strongest test each pair allows (equal ranks, exactly equal
    base-parameter spaces between exact results, principal angles within each numeric
    solver's stated tolerance, symbolic expressions equal to their values).

    Exit code 0 when everything agrees, 1 when a check fails, 2 for bad input.
    """
    if everything and mechs:
        raise click.UsageError("give mechanisms or --all, not both")
    names = list(registry.mechanisms()) if everything else list(mechs)
    if not names:
        raise click.UsageError("name at least one mechanism, or --all")
    chosen = select_solvers([s.strip() for s in solvers.split(",") if s.strip()] if solvers else None)
    texts = mechanism_texts(names)
    runner = make_runner(workers, scheduler)
    total = len(texts) * (len(chosen) + 1)
    show = not quiet and sys.stderr.isatty()
    if show:
        with click.progressbar(length=total, label="validate", file=sys.stderr, show_eta=True,
                               show_pos=True, item_show_func=lambda label: label) as bar:
            def progress(done, count, label):
                bar.update(done - bar.pos, label)
            report = run_validation(texts, chosen, runner=runner, timeout=timeout, progress=progress)
    else:
        report = run_validation(texts, chosen, runner=runner, timeout=timeout)
    if fmt == "markdown":
        click.echo(render_markdown(report))
    else:
        emit(fmt, report.to_json(), lambda: render_text(report))
    sys.exit(0 if report.ok else 1)
