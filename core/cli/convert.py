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


def read(mech: str, options: dict) -> tuple[Mechanism, list[str]]:
    """The mechanism (mobility checked) and its reader's notes, with reader options."""
    if not options and not Path(mech).suffix:
        return resolve(mech), []
    reader = reader_for(mech)
    if not Path(mech).exists():
        raise InputError("no such file", file=mech)
    known = getattr(reader, "options", ())
    for name in options:
        if name not in known:
            raise UserError(f"the {reader.name} reader has no --{name.replace('_', '-')} option")
    if hasattr(reader, "read_notes"):
        mechanism, notes = reader.read_notes(mech, **options)
    else:
        mechanism, notes = reader.read(mech, **options), []
    check_mobility(mechanism)
    return mechanism, list(notes) + list(getattr(mechanism, "warnings", ()))


def writer_for(path: str | Path):
    """The registered writer of ``path``'s suffix, or an InputError listing the known ones."""
    suffix = Path(path).suffix.lower()
    writers = {s.lower(): reg.item for reg in registry.writers().values() for s in reg.item.suffixes}
    if suffix not in writers:
        raise InputError(f"no writer for files ending in {suffix!r} (known: {', '.join(sorted(writers)) or 'none'})",
                         file=path)
    return writers[suffix]


def load_physical(path: str | Path) -> dict:
    """The ``"physical"`` table of an identify JSON file: parameter name -> decimal string."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON file: {exc}", file=path) from None
    physical = data.get("physical") if isinstance(data, dict) else None
    if not isinstance(physical, dict):
        raise InputError("needs a \"physical\" object (parameter name -> decimal string), as "
                         "`baseparams identify ... --physical --format json` writes", file=path, key="physical")
    return physical


def with_inertia(mech: Mechanism, physical: dict, path: str | Path) -> Mechanism:
    """``mech`` with every body's ten parameters taken from ``physical`` (exact decimals),
    each set checked: mass >= 0 and the inertia at the centre of mass positive semidefinite
    (to 1e-9 of its trace)."""
    labels = set(mech.body_labels)
    for name in physical:
        try:
            _, label = split_name(name)
        except ValueError:
            continue                                 # other identified quantities (friction ...)
        if label not in labels:
            raise InputError(f"body {label} is not a body of {mech.name} (bodies: {sorted(labels)})",
                             file=path, key=f"physical.{name}")
    bodies = []
    for body in mech.bodies:
        values = []
        for name in body_parameter_names(body.label):
            if name not in physical:
                raise InputError("missing: every body needs its ten parameters", file=path, key=f"physical.{name}")
            try:
                values.append(parse_decimal(physical[name]))
            except ExpressionError as exc:
                raise InputError(str(exc), file=path, key=f"physical.{name}") from None
        problem = consistency_problem(values)
        if problem:
            raise InputError(f"body {body.label} is not physically consistent: {problem}", file=path,
                             key=f"physical.m{body.label}")
        bodies.append(dataclasses.replace(body, inertia=tuple(values)))
    return dataclasses.replace(mech, bodies=tuple(bodies))


def consistency_problem(phi) -> str | None:
    """Why ten parameters (about the body origin) are not a physical body, or None."""
    m, h = phi[0], phi[1:4]
    if m < 0:
        return f"negative mass {float(m):g}"
    if m == 0:
        return "zero mass with a nonzero first moment" if any(h) else None
    kinds = dict(zip(PARAMETER_KINDS, (float(v) for v in phi)))
    c = np.array([float(v / m) for v in h])
    origin = np.array([[kinds["Ixx"], kinds["Ixy"], kinds["Ixz"]], [kinds["Ixy"], kinds["Iyy"], kinds["Iyz"]],
                       [kinds["Ixz"], kinds["Iyz"], kinds["Izz"]]])
    at_com = origin - float(m) * (c @ c * np.eye(3) - np.outer(c, c))
    smallest = np.linalg.eigvalsh(at_com)[0]
    if smallest < -CONSISTENCY_TOLERANCE * max(np.trace(at_com), np.finfo(float).tiny):
        return f"the inertia at the centre of mass has a negative eigenvalue ({smallest:.3g})"
    return None
