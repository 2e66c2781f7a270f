"""``baseparams export``: the regressor of a mechanism as a standalone Python module (registered on ``main``)."""

import click

from baseparams.cli.commands import _progress, get_solver, given_options, load, main
from baseparams.cli.options import (output_option, quiet_option, samples_option, solver_option,
                                    solver_options_option)


@main.command()
@click.argument("mech", metavar="MECH")
@click.option("--to", "target", type=click.Choice(["python"]), default="python", show_default=True,
              help="What to write: a Python module (numpy only), the one target today.")
@output_option(help="File to write (atomically) [default: standard output].")
@solver_option(help="Solver whose base parameters give base_regressor's columns (dp, vp, exact, ...).")
@samples_option(help="Samples of the exciting trajectory for the solver [default: the file's].")
@solver_options_option()
@quiet_option()
def export(mech: str, target: str, output: str | None, solver_name: str, samples: int | None,
           extra: tuple[str, ...], quiet: bool) -> None:
    """Write MECH's regressor as a standalone module (numpy only).

    The module has regressor(q, qd, qdd) -> K (tau = K phi, batches of states) and
    base_regressor(q, qd, qdd), the columns of the base parameters the solver finds (their
    expressions are in the module's docstring and BASE_PARAMETERS). For a closed loop the
    functions take all tree coordinates on the constraint manifold (the module does not
    close the loops) and return K in the independent coordinates. The solver's progress
    goes to stderr (--quiet: none).
    """
    from baseparams.api import export as run
    options, common = given_options(get_solver(solver_name), extra, samples=samples)
    result = run(load(mech), to=target, output=output, solver=solver_name, solver_options=options, common=common,
                 progress=None if quiet else _progress)
    if output is None:
        click.echo(result.source, nl=False)
        return
    click.echo(f"wrote {output}: regressor and base_regressor of {result.solution.mechanism.name} "
               f"({len(result.solution.result.base)} base parameters, {result.solution.result.solver})", err=True)
