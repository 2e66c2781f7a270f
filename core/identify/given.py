"""The simulation a user already has, as standard parameters: ``diagnose --params SOURCE``.

SOURCE is a mechanism file (TOML or URDF: its own inertias, e.g. the CAD model's) with the
same bodies as the mechanism diagnosed, or the JSON of an earlier ``identify`` (its base
parameters; any standard parameters that reproduce them give the same torques, so the
least-norm ones are used, and its identified effects become known effects).
"""

import json
from fractions import Fraction
from pathlib import Path

import numpy as np

from baseparams.errors import InputError
from baseparams.identify.model import standard_parameters
from baseparams.model.mechanism import EffectSpec, Mechanism


def given_parameters(mechanism: Mechanism, source: str) -> tuple[np.ndarray, list[EffectSpec]]:
    """(standard parameters (P,), known effects) of ``source`` for ``mechanism``."""
    path = Path(source)
    if path.suffix.lower() == ".json":
        return _from_identify(mechanism, path)
    from baseparams.io.loader import resolve
    from baseparams.model.consistency import require_physical
    other = resolve(source)
    require_physical(other, "diagnose --params")
    if list(other.parameters) != list(mechanism.parameters):
        raise InputError(f"its bodies do not match {mechanism.name}'s ({len(other.parameters)} standard "
                         f"parameters against {len(mechanism.parameters)}): give the same robot's file",
                         file=source, key="--params")
    return standard_parameters(other), []


def _from_identify(mechanism: Mechanism, path: Path) -> tuple[np.ndarray, list[EffectSpec]]:
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=str(path), key="--params") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"not JSON: {exc.msg} (line {exc.lineno})", file=str(path), key="--params") from None
    base = report.get("base") if isinstance(report, dict) else None
    if not isinstance(base, list) or not base:
        raise InputError("not the JSON of `baseparams identify` (no 'base' list)", file=str(path), key="base")
    names = list(mechanism.parameters)
    E = np.zeros((len(base), len(names)))
    beta = np.zeros(len(base))
    for k, entry in enumerate(base):
        where = f"base[{k}]"
        try:
            beta[k] = float(entry["value"])
            for name, coefficient in entry["expression"].items():
                E[k, names.index(name)] = float(Fraction(str(coefficient)))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"a value and an expression over {mechanism.name}'s standard parameters are "
                             f"needed ({exc})", file=str(path), key=where) from None
    if not np.all(np.isfinite(beta)):
        raise InputError("a base parameter value is not finite", file=str(path), key="base")
    phi = np.linalg.lstsq(E, beta, rcond=None)[0]
    effects = []
    for k, entry in enumerate(report.get("effects") or []):
        try:
            values = {c["name"].rsplit("_" + entry["coordinate"], 1)[0]: c["value"] for c in entry["coefficients"]
                      if c.get("value") is not None}
            effects.append(EffectSpec(entry["kind"], entry["coordinate"], values))
        except (KeyError, TypeError, AttributeError) as exc:
            raise InputError(f"an effect needs kind, coordinate and coefficients ({exc})", file=str(path),
                             key=f"effects[{k}]") from None
    return phi, effects
