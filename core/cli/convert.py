"""``baseparams convert``: a mechanism from one file format to another, through reader and
writer plugins chosen by suffix (registered on ``main``; docs/urdf.md).

``--inertia identified.json`` replaces the bodies' inertial parameters by the ``"physical"``
set of ``baseparams identify ... --physical --format json`` (parameter name -> decimal
string, about each body's origin in body axes), checked to be physically consistent,
so identified parameters go back into a URDF's ``<inertial>`` elements.
"""

import dataclasses
import json
from pathlib import Path

import click
import numpy as np

from baseparams import registry
from baseparams.cli.commands import UserError, main
from baseparams.errors import InputError
from baseparams.io.atomic import atomic_path
from baseparams.io.loader import check_mobility, reader_for, resolve
from baseparams.model.expressions import ExpressionError, parse_decimal
from baseparams.model.mechanism import Mechanism
from baseparams.model.params import PARAMETER_KINDS, body_parameter_names, split_name

READER_OPTIONS = ("merge_fixed", "floating_base")
CONSISTENCY_TOLERANCE = 1e-9        # relative to the trace: eigenvalues of the COM inertia above -tol


@main.command()
@click.argument("mech", metavar="MECH")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The file to write; its suffix chooses the writer (.toml, .urdf, ...).")
@click.option("--merge-fixed", is_flag=True,
              help="Reader option (URDF): merge each fixed joint's link into its parent, inertia exactly.")
@click.option("--floating-base", is_flag=True,
              help="Reader option (URDF): attach the root link to the ground by a Free (6-coordinate) joint.")
@click.option("--inertia", "inertia_file", type=click.Path(dir_okay=False), default=None, metavar="JSON",
              help="Replace the bodies' inertial parameters by the \"physical\" set of "
                   "`baseparams identify ... --physical --format json`.")
def convert(mech, output, merge_fixed, floating_base, inertia_file):
    """Write MECH (a registered name or a file) as OUTPUT in the format of its suffix.

    Notes on what the target format cannot hold, or what was approximated (URDF angles
    that are not multiples of pi/2), go to stderr.
    """
    options = {name: True for name, on in (("merge_fixed", merge_fixed), ("floating_base", floating_base)) if on}
    mechanism, notes = read(mech, options)
    if inertia_file is not None:
        mechanism = with_inertia(mechanism, load_physical(inertia_file), inertia_file)
    writer = writer_for(output)
    # every writer (a plugin's too) writes to a temporary file renamed over OUTPUT when it
    # is complete: a missing folder, a full disk or a kill never leaves a partial file
    with atomic_path(output) as temporary:
        notes += writer.write(mechanism, str(temporary)) or []
    for note in notes:
        click.echo(f"{'warning' if note in mechanism.warnings else 'note'}: {note}", err=True)
    if mechanism.nonphysical and Path(output).suffix == ".toml":
        count = len(mechanism.nonphysical)
        click.echo(f"warning: {output}: {count} bod{'y' if count == 1 else 'ies'} with a non-physical "
                   "inertia: the mechanism-file reader refuses them until the "
                   "inertia is fixed (or replaced with --inertia)", err=True)
    click.echo(f"wrote {output} ({writer.name}): {len(mechanism.bodies)} bodies, {len(mechanism.joints)} joints, "
               f"{len(mechanism.coordinates)} coordinates")


