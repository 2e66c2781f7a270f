"""``baseparams validate``: the orchestrator on the command line (registered on ``main``)."""

import math
import re
import sys

import click

from typing import Any

from baseparams import registry
from baseparams.cli.commands import emit, main
from baseparams.cli.options import (Progress, chosen_solvers, format_option, output_option, quiet_option, scheduler_option,
                                    solvers_option, workers_option, write_output)


MAX_TIMEOUT_S = 1e7         # about 116 days: past SIGALRM's and the OS timers' range otherwise


class Seconds(click.ParamType):
    """A number of seconds from 0.1 to MAX_TIMEOUT_S in ASCII digits: click's FloatRange
    takes float()'s forms ("1_0" is 10, Arabic-Indic digits) and lets NaN through (every
    comparison with it is false)."""
    name = "seconds"
    _TEXT = re.compile(r"[+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> float:
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
@solvers_option(help="A solver to run [default: every registered solver].")
@format_option("text", "json", "markdown", help="Report format.")
@output_option(help="Write the report to FILE instead of standard output.")
@workers_option(help="Run the jobs (mechanism x solver) in this many local worker processes (with --scheduler "
                     "local: Dask workers).")
@scheduler_option()
@click.option("--timeout", type=Seconds(), default=None, metavar="S", help="Seconds one job may take (0.1 to 10^7); a job past it is reported as "
                                      "timed out.")
@quiet_option()
def validate(mechs: tuple[str, ...], everything: bool, solver_names: tuple[str, ...], old_solvers: str | None,
             fmt: str, output: str | None, workers: int | None, scheduler: str | None, timeout: float | None,
             quiet: bool) -> None:
    """Cross-validate every solver on MECH (or --all registered mechanisms).

    For each mechanism: every applicable solver runs (a solver that does not take the
    mechanism is listed with its reason, not as a failure); the model is checked in ball
    arithmetic (energy balance, every joint type's transfer rules); the results are
    compared with the strongest test each pair allows (equal ranks, exactly equal
    base-parameter spaces between exact results, principal angles within each numeric
    solver's stated tolerance, symbolic expressions equal to their values).

    Exit code 0 when everything agrees, 1 when a check fails, 2 for bad input.
    """
    from baseparams.api import validate as run
    if everything and mechs:
        raise click.UsageError("give mechanisms or --all, not both")
    names = list(registry.mechanisms()) if everything else list(mechs)
    if not names:
        raise click.UsageError("name at least one mechanism, or --all")
    chosen = chosen_solvers(solver_names, old_solvers) or None
    with Progress("validate", quiet=quiet) as progress:
        result = run(names, solvers=chosen, workers=workers, scheduler=scheduler, timeout=timeout,
                     progress=progress.counted)
    if fmt == "markdown":
        write_output(output, result.to_markdown())
    else:
        emit(fmt, result.to_json(), result.to_text, output)
    sys.exit(0 if result.ok else 1)
