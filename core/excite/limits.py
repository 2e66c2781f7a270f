"""The limits a planned motion must respect, per independent coordinate.

Positions from the mechanism (a URDF's ``<limit lower upper>``, a mechanism file's
``limits``), velocities and torques from it too (a URDF's ``<limit velocity effort>``, a
mechanism file's ``drive_limits``), each overridable on the command line; accelerations have no URDF form and come from the command line or
the default below. A coordinate without a position range keeps the range the user gives,
or +-pi (angles) / +-0.5 m (lengths).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from baseparams.errors import InputError
from baseparams.dynamics.forces import independent_names
from baseparams.model.mechanism import Mechanism

DEFAULT_RANGE = {"angle": math.pi, "length": 0.5}          # half range without limits
DEFAULT_VELOCITY = {"angle": 2.0, "length": 0.5}           # rad/s, m/s without a URDF velocity
ACCELERATION_PER_VELOCITY = 4.0                            # default max |qdd| = 4/s x max |qd|


@dataclass
class Limits:
    """Per independent coordinate (``names`` order): position range (lo, hi), max |qd|,
    max |qdd| and max |tau| (inf: none); ``sources`` says where each came from."""
    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray
    sources: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        def number(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None
        return {name: {"position": [float(self.lower[k]), float(self.upper[k])],
                       "velocity": number(self.velocity[k]), "acceleration": number(self.acceleration[k]),
                       "torque": number(self.torque[k])} for k, name in enumerate(self.names)}


def drive_limits(mechanism: Mechanism) -> dict[str, dict[str, float]]:
    """{coordinate: {"velocity": v, "effort": e}} as the mechanism carries them (a URDF's
    ``<limit velocity effort>``, a mechanism file's ``drive_limits``)."""
    return {name: dict(values) for joint in mechanism.joints for name, values in joint.drive_limits.items()}


def parse_values(text: str | None, names: tuple, option: str, pair: bool = False) -> dict:
    """``V`` (every coordinate) or ``COORD=V,COORD=V``; with ``pair`` each V is ``LO:HI``.
    Returns {coordinate: value}; InputError naming the option otherwise."""
    if text is None:
        return {}
    out = {}

    def value(raw: str, where: str) -> float | tuple[float, float]:
        try:
            if pair:
                lo, hi = (float(v) for v in raw.split(":"))
                if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
                    raise ValueError
                return (lo, hi)
            v = float(raw)
            if not math.isfinite(v) or v <= 0:
                raise ValueError
            return v
        except ValueError:
            form = "LO:HI with LO < HI" if pair else "a positive number"
            raise InputError(f"{raw!r} is not {form}", key=option) from None

    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise InputError("no value given", key=option)
    if len(items) == 1 and "=" not in items[0]:
        return {name: value(items[0], option) for name in names}
    for item in items:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep or name not in names:
            raise InputError(f"{item!r}: give COORD=VALUE with COORD one of {', '.join(names)}", key=option)
        out[name] = value(raw.strip(), option)
    return out


def limits_of(mechanism: Mechanism, *, positions: str | None = None, velocity: str | None = None,
              acceleration: str | None = None, torque: str | None = None) -> Limits:
    """The limits of ``mechanism``'s independent coordinates, the options' overrides applied
    (positions: intersected with the file's range)."""
    names = independent_names(mechanism)
    drives = drive_limits(mechanism)
    ranges = parse_values(positions, names, "--position-range", pair=True)
    vel = parse_values(velocity, names, "--max-velocity")
    acc = parse_values(acceleration, names, "--max-acceleration")
    tau = parse_values(torque, names, "--max-torque")
    f = len(names)
    lower, upper = np.empty(f), np.empty(f)
    v_max, a_max, t_max = np.empty(f), np.empty(f), np.full(f, np.inf)
    sources = {}
    for k, name in enumerate(names):
        kind = mechanism.coordinate_kind(name)
        joint = mechanism.joint_of_coordinate(name)
        lo, hi = joint.limits.get(name, (-DEFAULT_RANGE[kind], DEFAULT_RANGE[kind]))
        source = "file" if name in joint.limits else "default"
        if name in ranges:
            lo, hi = max(lo, ranges[name][0]), min(hi, ranges[name][1])
            source = "option"
        if not lo < hi:
            raise InputError(f"coordinate {name}: the position range [{lo:.6g}, {hi:.6g}] is empty "
                             f"(the file's limits {joint.limits.get(name)} and --position-range "
                             f"{ranges.get(name)} do not overlap)", file=mechanism.path, key="--position-range")
        lower[k], upper[k] = lo, hi
        v_max[k] = vel.get(name, drives.get(name, {}).get("velocity", DEFAULT_VELOCITY[kind]))
        a_max[k] = acc.get(name, ACCELERATION_PER_VELOCITY * v_max[k])
        if name in tau or "effort" in drives.get(name, {}):
            t_max[k] = tau.get(name, drives.get(name, {}).get("effort"))
        sources[name] = {"position": source,
                         "velocity": "option" if name in vel else "file" if "velocity" in drives.get(name, {})
                         else "default",
                         "acceleration": "option" if name in acc else "default",
                         "torque": "option" if name in tau else "file" if math.isfinite(t_max[k]) else "none"}
    return Limits(names, lower, upper, v_max, a_max, t_max, sources)
