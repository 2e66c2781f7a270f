"""Writing the fixed mechanism (``diagnose --write``): the user's TOML text with the named
effects appended as ``[[effects]]`` tables, checked to load back, written atomically.
"""

import os
from collections.abc import Sequence
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

from baseparams.errors import InputError
from baseparams.io.atomic import atomic_write
from baseparams.io.loader import parse_mechanism
from baseparams.model.mechanism import EffectSpec, Mechanism


def decimal_text(value: float | Fraction) -> str:
    """A float as a plain decimal string (exact in the mechanism format, no exponent)."""
    return format(Decimal(repr(float(value))), "f")


def effects_toml(effects: Sequence[EffectSpec], origin: str) -> str:
    """``[[effects]]`` tables for ``effects`` (coefficients as decimal strings)."""
    lines = ["", f"# Added by baseparams diagnose ({origin}): estimated effects."]
    for spec in effects:
        values = ", ".join(f'{name} = "{decimal_text(v)}"' for name, v in spec.values.items())
        lines += ["[[effects]]", f'kind = "{spec.kind}"', f'coordinate = "{spec.coordinate}"',
                  f"values = {{ {values} }}", ""]
    return "\n".join(lines)


def check_writable(mechanism: Mechanism, path: str | os.PathLike) -> None:
    """--write needs a TOML mechanism file to append to: refused before the run otherwise."""
    source = mechanism.path
    if not source or Path(source).suffix.lower() != ".toml":
        raise InputError(f"--write needs a TOML mechanism file; {mechanism.name} was read from "
                         f"{source or 'no file'} (convert it first: baseparams convert MECH FILE.toml)",
                         key="--write")
    if Path(path).suffix.lower() != ".toml":
        raise InputError(f"--write writes a TOML mechanism file, not {Path(path).name}", key="--write")


def write_fixed(mechanism: Mechanism, effects: Sequence[EffectSpec], path: str | os.PathLike,
                origin: str = "") -> Mechanism:
    """Write the mechanism's own TOML text with ``effects`` appended as ``[[effects]]`` tables
    (the user's file stays as it was above them), check that it loads back with them, and
    write it atomically. Returns the mechanism read back."""
    check_writable(mechanism, path)
    source = mechanism.path
    try:
        text = Path(str(source)).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=source) from None
    fixed = text.rstrip("\n") + "\n" + effects_toml(effects, origin)
    back = parse_mechanism(fixed, path=str(path))
    have = {(e.kind, e.coordinate) for e in back.effects}
    missing = [f"{e.kind}:{e.coordinate}" for e in effects if (e.kind, e.coordinate) not in have]
    if missing:
        raise InputError(f"the written mechanism does not load back with {', '.join(missing)}",
                         file=str(path), key="effects")
    atomic_write(path, fixed)
    return back
