"""The simulation a user already has, as standard parameters: ``diagnose --params SOURCE``.

SOURCE is a mechanism file (TOML or URDF: its own inertias, e.g. the CAD model's) with the
same bodies as the mechanism diagnosed, or the JSON of an earlier ``identify``: its base
parameters (any standard parameters that reproduce them give the same torques: those
nearest the mechanism's own inertias when it has them, so that each body's mass means
something, else the least-norm ones), its identified effects (known effects now), and the
base parameters' covariance, within which a change is the fit's own error, not a change.
"""

import json
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from baseparams.errors import InputError
from baseparams.identify.model import standard_parameters
from baseparams.model.mechanism import EffectSpec, Mechanism


@dataclass(frozen=True)
class Given:
    """A simulation held as given: standard ``parameters`` (P,), the ``effects`` it brings;
    for an identify result the map ``base_map`` E (r, P) from standard to base parameters and
    their ``covariance`` (r, r; None when the JSON does not carry it); ``masses``: whether
    each body's mass in ``parameters`` is the body's (a file's, or completed from the
    mechanism's own inertias), not an arbitrary member of a group; ``gains``: the current
    gains an identify result estimated (``gain_COORD``: N m per unit of the channel)."""
    parameters: np.ndarray
    effects: list[EffectSpec] = field(default_factory=list)
    base_map: np.ndarray | None = None
    covariance: np.ndarray | None = None
    masses: bool = True
    gains: dict[str, float] = field(default_factory=dict)


def given_parameters(mechanism: Mechanism, source: str) -> Given:
    """What ``source`` holds as given for ``mechanism``."""
    path = Path(source)
    if path.suffix.lower() == ".json":
        return _from_identify(mechanism, path)
    from baseparams.io.loader import resolve
    from baseparams.model.consistency import require_physical
    from baseparams.identify.derived import welded
    other = resolve(source)
    require_physical(other, "diagnose --params", still={b for b, root in welded(other).items() if root == 0})
    if list(other.parameters) != list(mechanism.parameters):
        raise InputError(f"its bodies do not match {mechanism.name}'s ({len(other.parameters)} standard "
                         f"parameters against {len(mechanism.parameters)}): give the same robot's file",
                         file=source, key="--params")
    return Given(standard_parameters(other))


def _from_identify(mechanism: Mechanism, path: Path) -> Given:
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
    own = all(b.inertia is not None for b in mechanism.bodies)
    prior = standard_parameters(mechanism) if own else np.zeros(len(names))
    phi = prior + np.linalg.lstsq(E, beta - E @ prior, rcond=None)[0]
    effects = []
    for k, entry in enumerate(report.get("effects") or []):
        try:
            values = {c["name"].rsplit("_" + entry["coordinate"], 1)[0]: c["value"] for c in entry["coefficients"]
                      if c.get("value") is not None}
            effects.append(EffectSpec(entry["kind"], entry["coordinate"], values))
        except (KeyError, TypeError, AttributeError) as exc:
            raise InputError(f"an effect needs kind, coordinate and coefficients ({exc})", file=str(path),
                             key=f"effects[{k}]") from None
    gains = {}
    for k, entry in enumerate(report.get("gains") or []):
        try:
            gains[str(entry["name"])] = float(entry["value"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"a gain needs a name and a value ({exc})", file=str(path), key=f"gains[{k}]") from None
    return Given(phi, effects, E, _base_covariance(report, base, path), masses=own, gains=gains)


def _base_covariance(report: dict, base: list, path: Path) -> np.ndarray | None:
    """The base parameters' covariance (r, r) from the result's ``covariance`` (names and
    matrix over every estimate), None when it has none (a result of an older version)."""
    held = report.get("covariance")
    if held is None:
        return None
    try:
        names = list(held["names"])
        matrix = np.array([[np.nan if v is None else float(v) for v in row] for row in held["matrix"]])
        index = [names.index(entry["name"]) for entry in base]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"expected {{\"names\": [...], \"matrix\": [[...]]}} naming every base parameter "
                         f"({exc})", file=str(path), key="covariance") from None
    if matrix.shape != (len(names), len(names)):
        raise InputError(f"a {len(names)} x {len(names)} matrix is needed, not {matrix.shape}", file=str(path),
                         key="covariance.matrix")
    block = matrix[np.ix_(index, index)]
    return block if np.all(np.isfinite(block)) else None
