"""Effects and noise levels as text (``KIND:COORD``, ``KIND:COORD=V,V``, ``SD,SD``): what
the command line's options and the Python functions accept alike."""

from __future__ import annotations

from collections.abc import Iterable
import json
from fractions import Fraction
from pathlib import Path

from baseparams.errors import InputError
from baseparams.model.mechanism import EffectSpec, Mechanism


# ----- --effect ---------------------------------------------------------------------------
def parse_effect(text: str, mechanism: Mechanism, *, values: bool) -> EffectSpec:
    """``KIND:COORD`` (values=False), or with values (values=True) ``KIND:COORD=V[,V...]`` (the
    coefficients in the effect's order) or ``KIND:COORD:NAME=V[,NAME=V...]``; values are
    exact decimals or rationals."""
    key = f"--effect {text}"
    head, _, given = text.partition("=") if values else (text, "", "")
    parts = head.split(":")
    if len(parts) not in (2, 3) or not all(p.strip() for p in parts[:2]) or (len(parts) == 3 and not values):
        form = "KIND:COORD=VALUE[,VALUE] or KIND:COORD:NAME=VALUE[,NAME=VALUE]" if values else "KIND:COORD"
        raise InputError(f"expected {form}", key=key)
    kind, coordinate = parts[0].strip(), parts[1].strip()
    from baseparams.dynamics.forces import checked_effect    # on use, like the verbs: fast --help
    effect = checked_effect(mechanism, kind, coordinate, key)
    if not values:
        return EffectSpec(kind, coordinate)
    coefficients = effect.coefficients
    if len(parts) == 3:                          # KIND:COORD:NAME=V,NAME=V (head holds NAME)
        pairs = (parts[2] + "=" + given).split(",")
        out = {}
        for pair in pairs:
            name, sep, value = pair.partition("=")
            name = name.strip()
            if not sep or name not in coefficients:
                raise InputError(f"{pair!r}: expected NAME=VALUE with NAME one of {', '.join(coefficients)}",
                                 key=key)
            out[name] = _number(value, key)
    else:
        numbers = [v for v in given.split(",")] if given else []
        if len(numbers) != len(coefficients):
            raise InputError(f"{kind} has {len(coefficients)} coefficients ({', '.join(coefficients)}): "
                             f"give {len(coefficients)} values, not {len(numbers)}", key=key)
        out = {name: _number(v, key) for name, v in zip(coefficients, numbers)}
    missing = [c for c in coefficients if c not in out]
    if missing:
        raise InputError(f"no value for {', '.join(missing)}", key=key)
    return EffectSpec(kind, coordinate, out)


def _number(text: str, key: str) -> Fraction:
    try:
        return Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        raise InputError(f"{text.strip()!r} is not a number", key=key) from None


def parse_noise(text: str) -> list[float] | float:
    from baseparams.recordings.data import MAX_MAGNITUDE, NUMBER
    parts = [v.strip() for v in text.split(",")]
    if not all(NUMBER.fullmatch(v) for v in parts):
        raise InputError(f"{text!r}: expected SD or SD,SD,... (one per independent coordinate; ASCII "
                         "digits)", key="--noise")
    values = [float(v) for v in parts]
    if not all(0 <= v <= MAX_MAGNITUDE for v in values):
        raise InputError(f"{text!r}: a standard deviation is between 0 and {MAX_MAGNITUDE:g}", key="--noise")
    return values[0] if len(values) == 1 else values


def parse_effects(texts: Iterable[str], mechanism: Mechanism, still: Iterable[str] = ()) -> list[EffectSpec]:
    """``--effect`` values; ``KIND:*`` is the effect on every independent coordinate but the
    ``still`` ones (held still in the data: the effect has no column there)."""
    from baseparams.dynamics.forces import independent_names
    out = []
    skip = set(still)
    for text in texts:
        kind, sep, coordinate = text.partition(":")
        if sep and coordinate.strip() == "*":
            out += [parse_effect(f"{kind}:{c}", mechanism, values=False) for c in independent_names(mechanism)
                    if c not in skip]
        else:
            out.append(parse_effect(text, mechanism, values=False))
    return out


def parse_separate(text: str, mechanism: Mechanism) -> tuple[tuple[str, str], ...]:
    """``KIND:COORD,KIND:COORD`` or a ``diagnose --format json`` file (its "ambiguous" groups)."""
    from baseparams.dynamics.forces import checked_effect
    pairs = []
    path = Path(text)
    if text.endswith(".json") or path.is_file():
        try:
            report = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot read a diagnose JSON report: {exc}", file=text, key="--separate") from None
        groups = report.get("ambiguous") if isinstance(report, dict) else None
        if not isinstance(groups, list):
            raise InputError("no \"ambiguous\" list (expected `baseparams diagnose --format json` output)",
                             file=text, key="ambiguous")
        for k, group in enumerate(groups):
            try:
                pairs += [(c["kind"], c["coordinate"]) for c in group["candidates"]]
            except (KeyError, TypeError):
                raise InputError("expected {\"candidates\": [{\"kind\", \"coordinate\"}, ...]}", file=text,
                                 key=f"ambiguous[{k}]") from None
        if not pairs:
            raise InputError("the diagnosis reports no ambiguous effects: nothing to separate", file=text,
                             key="ambiguous")
    else:
        for item in (s.strip() for s in text.split(",") if s.strip()):
            kind, sep, coordinate = item.partition(":")
            if not sep or not kind.strip() or not coordinate.strip():
                raise InputError(f"{item!r}: expected KIND:COORD", key="--separate")
            pairs.append((kind.strip(), coordinate.strip()))
    for kind, coordinate in pairs:
        checked_effect(mechanism, kind, coordinate, key=f"--separate {kind}:{coordinate}")
    unique = tuple(dict.fromkeys(pairs))
    if len(unique) < 1:
        raise InputError("name at least one effect to separate", key="--separate")
    return unique
