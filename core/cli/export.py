"""``baseparams export``: the regressor of a mechanism as a standalone Python module (registered on ``main``)."""

import click

from baseparams.cli.commands import get_solver, load, main
from baseparams.io.atomic import atomic_write
from baseparams.solvers.protocol import check_options, require_applicable


@main.command()
@click.argument("mech", metavar="MECH")
@click.option("--to", "target", type=click.Choice(["python"]), required=True,
              help="What to write: a Python module (numpy only).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True), default=None,
              help="File to write [default: stdout].")
@click.option("--solver", "solver_name", default="dp", show_default=True, metavar="NAME",
              help="Solver whose base parameters give base_regressor's columns (dp, vp, exact, ...).")
@click.option("--samples", type=click.IntRange(2, 1_000_000), default=None,
              help="Samples of the exciting trajectory for the solver [default: the file's].")
def export(mech, target, output, solver_name, samples):
    """Write MECH's regressor as a standalone module (numpy only).

    The module has regressor(q, qd, qdd) -> K (tau = K phi, batches of states) and
    base_regressor(q, qd, qdd), the columns of the base parameters the solver finds (their
    expressions are in the module's docstring and BASE_PARAMETERS). For a closed loop the
    functions take all tree coordinates on the constraint manifold (the module does not
    close the loops) and return K in the independent coordinates.
    """
    from baseparams.dynamics.codegen import export_source       # numpy/sympy on use, as commands.load
    solver = get_solver(solver_name)
    options = check_options(solver, {"samples": samples} if samples is not None else {})
    mechanism = load(mech)
    require_applicable(solver, mechanism)
    result = solver.solve(mechanism, **options)
    source = export_source(mechanism, result)
    if output is None:
        click.echo(source, nl=False)
        return
    atomic_write(output, source)            # a full disk or a kill keeps the old module whole
    click.echo(f"wrote {output}: regressor and base_regressor of {mechanism.name} "
               f"({len(result.base)} base parameters, {result.solver})", err=True)
