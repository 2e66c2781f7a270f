"""The limits a planned motion must respect, per independent coordinate.

Positions from the mechanism (a URDF's ``<limit lower upper>``, a mechanism file's
``limits``), velocities and torques from it too (a URDF's ``<limit velocity effort>``, a
mechanism file's ``drive_limits``), each overridable on the command line. Accelerations and
jerks have no URDF form: they are limited only when the user gives them (no robot data gives
a default), and the report states the assumption. The velocity limit the plan keeps is the
given one less a margin (``velocity_margin``, a fraction). A coordinate without a position
range keeps the range the user gives, or +-pi (angles) / +-0.5 m (lengths), stated too.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from baseparams.errors import InputError
from baseparams.dynamics.forces import independent_names
from baseparams.model.mechanism import Mechanism

DEFAULT_RANGE = {"angle": math.pi, "length": 0.5}          # half range without limits
DEFAULT_VELOCITY = {"angle": 2.0, "length": 0.5}           # rad/s, m/s without a URDF velocity
VELOCITY_MARGIN = 0.05                                     # the plan keeps 5 % of each velocity limit


@dataclass
class Limits:
    """Per independent coordinate (``names`` order): position range (lo, hi), max |qd|,
    max |qdd|, max |tau| and max |d3q/dt3| (inf: none); ``velocity`` is the limit the plan
    keeps (the given one times 1 - ``velocity_margin``); ``sources`` says where each came from."""
    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray
    sources: dict = field(default_factory=dict)
    jerk: np.ndarray = field(default_factory=lambda: np.zeros(0))     # none given: inf for every coordinate
    velocity_margin: float = 0.0

    def __post_init__(self) -> None:
        if self.jerk.size == 0:
            self.jerk = np.full(len(self.names), np.inf)

    def assumptions(self) -> list[str]:
        """What the plan assumes where the robot's files give no limit, one line per kind."""
        out = []
        for kind, text in (("position", "no position limit in the file: +-pi rad / +-0.5 m assumed"),
                           ("velocity", "no velocity limit in the file: 2 rad/s / 0.5 m/s assumed"),
                           ("acceleration", "no acceleration limit given (--max-acceleration; a URDF has none): "
                                            "accelerations are not limited"),
                           ("torque", "no effort limit in the file or --max-torque: torques are not limited"),
                           ("jerk", "no jerk limit given (--max-jerk): jerks are not limited")):
            which = [n for n in self.names if self.sources.get(n, {}).get(kind) in ("default", "none")]
            if which:
                out.append(f"{text} ({', '.join(which)})")
        if self.velocity_margin:
            out.append(f"velocity margin {self.velocity_margin:g}: the plan keeps to {1 - self.velocity_margin:g} "
                       "of each velocity limit")
        return out

    def to_json(self) -> dict:
        def number(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None
        return {name: {"position": [float(self.lower[k]), float(self.upper[k])],
                       "velocity": number(self.velocity[k]), "acceleration": number(self.acceleration[k]),
                       "torque": number(self.torque[k]),
                       "jerk": number(self.jerk[k])}
                for k, name in enumerate(self.names)}


def drive_limits(mechanism: Mechanism) -> dict[str, dict[str, float]]:
    """{coordinate: {"velocity": v, "effort": e}} as the mechanism carries them (a URDF's
    ``<limit velocity effort>``, a mechanism file's ``drive_limits``)."""
    return {name: dict(values) for joint in mechanism.joints for name, values in joint.drive_limits.items()}


# option text numbers: ASCII digits, one sign, point and exponent (float() takes '1_0', Arabic-Indic
# digits, 'inf' and 'nan'); limits beyond MAX_LIMIT are no limits a motion is planned against
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
MAX_LIMIT = 1e9


def parse_values(text: str | None, names: tuple, option: str, pair: bool = False) -> dict:
    """``V`` (every coordinate) or ``COORD=V,COORD=V``; with ``pair`` each V is ``LO:HI``.
    Returns {coordinate: value}; InputError naming the option otherwise."""
    if text is None:
        return {}
    out = {}

    def number(text: str) -> float:
        """A number as option text is written (ASCII digits, sign, point, exponent: float()
        alone took '1_0' as 10, docs/cli.md), within MAX_LIMIT (1e308 overflowed to inf in the
        random starts: OverflowError)."""
        text = text.strip()
        if not _NUMBER.fullmatch(text):
            raise ValueError
        v = float(text)
        if not math.isfinite(v) or abs(v) > MAX_LIMIT:
            raise OverflowError
        return v

    def value(raw: str, where: str) -> float | tuple[float, float]:
        try:
            if pair:
                lo, hi = (number(v) for v in raw.split(":"))
                if lo >= hi:
                    raise ValueError
                return (lo, hi)
            v = number(raw)
            if v <= 0:
                raise ValueError
            return v
        except OverflowError:
            raise InputError(f"{raw!r} is beyond any physical limit (at most {MAX_LIMIT:g} in magnitude; leave "
                             f"{option} out for none)", key=option) from None
        except ValueError:
            form = "LO:HI with LO < HI" if pair else "a positive number"
            raise InputError(f"{raw!r} is not {form} (ASCII digits, sign, point and exponent)", key=option) from None

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
              acceleration: str | None = None, torque: str | None = None, jerk: str | None = None,
              velocity_margin: float = 0.0) -> Limits:
    """The limits of ``mechanism``'s independent coordinates, the options' overrides applied
    (positions: intersected with the file's range; velocities less ``velocity_margin``)."""
    if not 0 <= velocity_margin < 1:
        raise InputError(f"{velocity_margin!r}: a fraction of the limit in [0, 1)", key="--velocity-margin")
    names = independent_names(mechanism)
    drives = drive_limits(mechanism)
    ranges = parse_values(positions, names, "--position-range", pair=True)
    vel = parse_values(velocity, names, "--max-velocity")
    acc = parse_values(acceleration, names, "--max-acceleration")
    tau = parse_values(torque, names, "--max-torque")
    jer = parse_values(jerk, names, "--max-jerk")
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
        a_max[k] = acc.get(name, np.inf)
        if name in tau or "effort" in drives.get(name, {}):
            t_max[k] = tau.get(name, drives.get(name, {}).get("effort"))
        sources[name] = {"position": source,
                         "velocity": "option" if name in vel else "file" if "velocity" in drives.get(name, {})
                         else "default",
                         "acceleration": "option" if name in acc else "none",
                         "torque": "option" if name in tau else "file" if math.isfinite(t_max[k]) else "none",
                         "jerk": "option" if name in jer else "none"}
    jerks = np.array([jer.get(name, np.inf) for name in names], dtype=float)
    return Limits(names, lower, upper, v_max * (1 - velocity_margin), a_max, t_max, sources, jerks, velocity_margin)
