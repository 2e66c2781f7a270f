"""Load mechanisms: a registered name or a file, read by the reader its suffix selects.

Readers come from the ``baseparams_readers`` hook (TOML built in, registered like a third
party's). Every mechanism loaded here then passes :func:`check_mobility`, which needs the
kinematics and so lives above the model. Every problem is an
:class:`baseparams.errors.InputError` naming the file, the key path and the reason.
"""

import os
from pathlib import Path

import numpy as np

from baseparams import registry
from baseparams.dynamics.evaluator import ClosureStructure, closure_structure
from baseparams.dynamics.trajectory import Trajectory, samples_float64
from baseparams.errors import InputError, KinematicsError
from baseparams.formats import Reader
from baseparams.io.toml_reader import parse_toml
from baseparams.model.mechanism import Mechanism


def resolve(mech: str | os.PathLike[str]) -> Mechanism:
    """A registered mechanism name or a path to a mechanism file -> Mechanism."""
    known = registry.mechanisms()
    if str(mech) in known:
        return load_mechanism(known[str(mech)].item.path)
    path = Path(mech)
    if path.suffix or path.exists():
        return load_mechanism(path)
    raise InputError(f"unknown mechanism {str(mech)!r}: not a registered name "
                     f"({', '.join(known) or 'none registered'}) and not a file")


def readers_by_suffix() -> dict[str, Reader]:
    """Lower-case suffix (".toml") -> the registered reader object that reads it."""
    out: dict[str, Reader] = {}
    owner: dict[str, str] = {}
    for name, reg in registry.readers().items():
        for suffix in reg.item.suffixes:
            suffix = suffix.lower()
            if suffix in out:
                raise InputError(f"the suffix {suffix!r} is claimed by two readers "
                                 f"({owner[suffix]} and {name})")
            out[suffix], owner[suffix] = reg.item, name
    return out


def reader_for(path: str | Path) -> Reader:
    """The reader registered for ``path``'s suffix, or an InputError listing the known ones."""
    path = Path(path)
    readers = readers_by_suffix()
    reader = readers.get(path.suffix.lower())
    if reader is None:
        what = f"files ending in {path.suffix!r}" if path.suffix else "files without a suffix"
        raise InputError(f"no reader for {what} (known: {', '.join(sorted(readers)) or 'none'})", file=path)
    return reader


def load_mechanism(path: str | Path) -> Mechanism:
    """Read the mechanism file at ``path`` with its suffix's reader, then check its mobility."""
    path = Path(path)
    reader = reader_for(path)
    if not path.exists():
        raise InputError("no such file", file=path)
    mech = reader.read(path)
    if not isinstance(mech, Mechanism):
        raise InputError(f"the {reader.name!r} reader returned {type(mech).__name__}, not a Mechanism",
                         file=path)
    check_mobility(mech)
    return mech


def parse_mechanism(text: str, path: str | Path = "<string>") -> Mechanism:
    """A mechanism from TOML ``text`` (``path`` names it in errors), mobility checked."""
    mech = parse_toml(text, path)
    check_mobility(mech)
    return mech


def check_mobility(mech: Mechanism) -> None:
    """Raise an InputError unless the mechanism moves, its independent coordinates are given
    when it has loops, and its trajectory drives every independent coordinate.

    Needs the loop-closure Jacobian, which is why the builder cannot run it (the model does
    not import the kinematics). Keys are the TOML format's (docs/mechanism-format.md).
    """
    def error(key: str, reason: str) -> InputError:
        return InputError(reason, file=mech.path, key=key)

    try:
        structure = closure_structure(mech)
    except KinematicsError as exc:
        raise error("joints", f"cannot evaluate the kinematics: {exc}") from None
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        raise error("joints", f"cannot evaluate the kinematics in double precision ({type(exc).__name__}): "
                              f"check the magnitudes of the geometry") from None
    _check_redundant_joints(mech, structure)
    if structure.dof == 0:
        tied = f" with {len(mech.couplings)} coupling(s)" if mech.loops and mech.couplings else ""
        raise error("joints", f"the mechanism has no degree of freedom "
                              f"(Gruebler count {mech.gruebler}; closure rank {structure.rank}{tied})")
    if mech.loops and not mech.independent:
        names = [mech.coordinates[i] for i in structure.independent]
        raise error("coordinates.independent",
                    f"required for a mechanism with loops; choose {structure.dof} of "
                    f"{', '.join(mech.coordinates)} (for example {names})")
    if mech.trajectory:
        missing = [c for c in mech.independent if c not in mech.trajectory.expressions]
        if missing:
            raise error("trajectory.q", f"no expression for {', '.join(missing)}")


def _check_redundant_joints(mech: Mechanism, structure: ClosureStructure) -> None:
    """Refuse a loop-closing joint none of whose closure equations is independent of the
    other joints' (a second coaxial revolute between the same bodies, a duplicated joint):
    it constrains nothing, and Newton would have no equation to solve."""
    if not mech.loops:
        return
    kept, start = set(structure.rows), 0
    for joint in mech.loops:
        count = len(joint.type.closure)
        if count and not kept.intersection(range(start, start + count)):
            index = mech.joints.index(joint)
            raise InputError(f"joint {joint.name!r} ({joint.type.name}, {joint.parent} -> {joint.child}) is "
                             f"redundant: its {count} closure equations all follow from the other joints "
                             f"(a duplicated or coaxial joint?); remove it",
                             file=mech.path, key=f"joints[{index}]")
        start += count
    for k, coupling in enumerate(mech.couplings):         # their equations follow the loops'
        if start + k not in kept:
            raise InputError(f"{coupling.coordinate} = {coupling.ratio} {coupling.leader} + {coupling.offset} "
                             f"follows from the closed loops (the loop joints already tie {coupling.coordinate!r} "
                             f"to {coupling.leader!r}, or the other couplings do); remove the coupling",
                             file=mech.path, key=f"couplings[{k}]")


def check_trajectory(mech: Mechanism, samples: int | None = None) -> None:
    """Everything ``solve`` checks of the default trajectory before solving: the sample count
    and its memory, every expression evaluable and finite, the loops closed and the
    coordinate limits respected at every sample (float64). Raises InputError (the file,
    ``trajectory`` and the reason: the time and the coordinates)."""
    if mech.trajectory is None:
        return
    trajectory = Trajectory.default(mech, samples=samples)
    try:
        samples_float64(mech, trajectory)
    except KinematicsError as exc:
        raise InputError(str(exc), file=mech.path, key="trajectory") from None
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(f"cannot be evaluated in double precision ({type(exc).__name__}): check the "
                         f"magnitudes of the geometry and of the expressions", file=mech.path,
                         key="trajectory") from None
