"""``baseparams convert``: a mechanism from one file format to another, through reader and
writer plugins chosen by suffix (registered on ``main``; docs/urdf.md).

``--inertia identified.json`` replaces the bodies' inertial parameters by the ``"physical"``
set of ``baseparams identify ... --physical --format json`` (parameter name -> decimal
string, about each body's origin in body axes), checked to be physically consistent,
so identified parameters go back into a URDF's ``<inertial>`` elements.
"""

from pathlib import Path

import click

from baseparams.cli.commands import main
from baseparams.cli.options import output_option


@main.command()
@click.argument("mech", metavar="MECH")
@output_option(help="The file to write; its suffix chooses the writer (.toml, .urdf, ...).", required=True)
@click.option("--merge-fixed", is_flag=True,
              help="Reader option (URDF): merge each fixed joint's link into its parent, inertia exactly "
                   "(the default since issue 47).")
@click.option("--keep-fixed", is_flag=True,
              help="Reader option (URDF): keep each fixed joint's link as a body of its own.")
@click.option("--floating-base", is_flag=True,
              help="Reader option (URDF): attach the root link to the ground by a Free (6-coordinate) joint.")
@click.option("--inertia", "inertia_file", type=click.Path(dir_okay=False), default=None, metavar="JSON",
              help="Replace the bodies' inertial parameters by the \"physical\" set of "
                   "`baseparams identify ... --physical --format json`.")
def convert(mech: str, output: str, merge_fixed: bool, keep_fixed: bool, floating_base: bool,
            inertia_file: str | None) -> None:
    """Write MECH (a registered name or a file) as OUTPUT in the format of its suffix.

    Notes on what the target format cannot hold, or what was approximated (URDF angles
    that are not multiples of pi/2), go to stderr.
    """
    from baseparams.api import convert as run
    result = run(mech, output, merge_fixed=merge_fixed, keep_fixed=keep_fixed, floating_base=floating_base,
                 inertia=inertia_file)
    mechanism = result.mechanism
    for note in result.notes:
        click.echo(f"{'warning' if note in mechanism.warnings else 'note'}: {note}", err=True)
    if mechanism.nonphysical and Path(output).suffix == ".toml":
        count = len(mechanism.nonphysical)
        click.echo(f"warning: {output}: {count} bod{'y' if count == 1 else 'ies'} with a non-physical "
                   "inertia: the mechanism-file reader refuses them until the "
                   "inertia is fixed (or replaced with --inertia)", err=True)
    click.echo(result.to_text())
