"""``excite --check PLAN``: a motion someone means to run (a plan CSV, or a recording
through its description) checked before it runs: every limit, the distances between links
and to the keep-out geometry (between samples too), and the condition number identify
would report on it. Exit 1 when something does not hold."""

from __future__ import annotations

import csv
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baseparams.errors import InputError
from baseparams.excite import design
from baseparams.model.mechanism import Mechanism


@dataclass
class MotionCheck:
    """The figures of a given motion (``check``) and what they rest on."""
    mechanism: str
    path: str
    solver: str
    samples: int
    duration: float
    problem: design.Problem
    check: design.Check
    peaks: dict[str, dict[str, float]]
    assumptions: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.check.feasible

    def to_json(self) -> dict[str, Any]:
        return {"mechanism": self.mechanism, "plan": self.path, "solver": self.solver, "samples": self.samples,
                "duration_s": self.duration, "ok": self.ok, "limits": self.problem.limits.to_json(),
                "peaks": self.peaks, **self.check.to_json(), "assumptions": self.assumptions, "notes": self.notes}

    def to_text(self) -> str:
        c = self.check
        lines = [f"{self.mechanism}: {self.path}, {self.samples} samples over {self.duration:g} s: "
                 + ("every check holds" if self.ok else c.reason or "a check fails"),
                 f"  condition number {c.condition:.4g} on the {self.solver} solver's base",
                 "  margins (>= 0: the limit holds): " + ", ".join(f"{k} {v:.4g}" for k, v in c.margins.items())]
        for name, peak in self.peaks.items():
            lines.append(f"  {name}: " + ", ".join(f"{k} {v:.4g}" for k, v in peak.items()))
        if c.collision is not None:
            d = c.collision
            lines.append(f"  smallest distance {d['smallest_distance']:.3g} m ({d['where']}, sample {d['sample']}); "
                         f"guaranteed between samples {d['guaranteed_between_samples']:.3g} m; clearance "
                         f"{d['clearance']:g} m; above the planes "
                         + ", ".join(f"{k} {v:.3g} m" for k, v in d["above_planes"].items()))
        else:
            lines.append("  collisions: not checked")
        lines += [f"  assumed: {a}" for a in self.assumptions] + [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def read_plan_csv(path: str, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(t, q, qd, qdd, notes) of a CSV with ``t`` and ``q_C`` (``qd_C``, ``qdd_C`` optional,
    then estimated by central differences on a uniform ``t``) for every coordinate C."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", file=path) from None
    if len(rows) < 3:
        raise InputError("needs a header row and at least two samples", file=path)
    header = [h.strip() for h in rows[0]]
    need = ["t"] + [f"q_{n}" for n in names]
    missing = [h for h in need if h not in header]
    if missing:
        raise InputError(f"missing columns {', '.join(missing)} (the mechanism's coordinates: {', '.join(names)})",
                         file=path, key="header")
    values = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise InputError(f"{len(row)} fields, the header has {len(header)}", file=path, key=f"row {r}")
        for c, text in enumerate(row):
            try:
                values[r - 2, c] = float(text)
            except ValueError:
                raise InputError(f"{text!r} is not a number", file=path, key=f"row {r}, column {header[c]}") from None
            if not math.isfinite(values[r - 2, c]):
                raise InputError(f"{text!r} is not finite", file=path, key=f"row {r}, column {header[c]}")
    t = values[:, header.index("t")]
    if np.any(np.diff(t) <= 0):
        raise InputError("t must increase strictly", file=path, key="column t")

    def block(prefix: str) -> np.ndarray | None:
        cols = [f"{prefix}_{n}" for n in names]
        return values[:, [header.index(c) for c in cols]] if all(c in header for c in cols) else None

    q = block("q")
    assert q is not None
    notes = []
    qd, qdd = block("qd"), block("qdd")
    if qd is None or qdd is None:
        step = np.diff(t)
        if np.ptp(step) > 1e-6 * np.mean(step):
            raise InputError("qd_ and qdd_ columns are absent and t is not uniform: give them, or sample uniformly",
                             file=path, key="header")
        qd = np.gradient(q, t, axis=0) if qd is None else qd
        qdd = np.gradient(qd, t, axis=0) if qdd is None else qdd
        notes.append("velocities or accelerations estimated by central differences of the positions")
    return t, q, qd, qdd, notes


def check_motion(mechanism: Mechanism, problem: design.Problem, path: str, solver: str,
                 motion: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], notes: list[str]) -> MotionCheck:
    """The figures of the sampled ``motion`` (t, q, qd, qdd) under ``problem``'s limits and scene."""
    t, q, qd, qdd = motion
    pieces = np.split(np.arange(len(t)), np.nonzero(np.diff(t) <= 0)[0] + 1)   # runs, each on its own clock
    if len(pieces) > 1:
        notes.append(f"{len(pieces)} runs (the time starts again): each is checked on its own, between its samples")
    whole = design.check(dataclasses.replace(problem, scene=None), q, qd, qdd)
    margins = dict(whole.margins)
    collision, nearest = None, np.inf
    for rows in pieces:
        part = _piece(problem, t[rows], q[rows], qd[rows], qdd[rows], notes)
        for key, value in part.margins.items():
            margins[key] = min(margins.get(key, np.inf), value)
        if part.collision is not None and part.margins["collision"] < nearest:
            collision, nearest = part.collision, part.margins["collision"]
    bad = [k for k, v in margins.items() if v < 0]
    result = dataclasses.replace(whole, margins=margins, feasible=not bad and whole.feasible, collision=collision,
                                 reason=f"outside the {', '.join(bad)} limits" if bad else whole.reason)
    peaks = {name: {"q_min": float(q[:, k].min()), "q_max": float(q[:, k].max()),
                    "qd_peak": float(np.abs(qd[:, k]).max()), "qdd_peak": float(np.abs(qdd[:, k]).max())}
             for k, name in enumerate(problem.limits.names)}
    if result.margins.get("torque") is not None and problem.model.phi is not None:
        notes.append("torques: the model's inverse dynamics (K phi) with the mechanism file's inertial parameters")
    duration = sum(float(t[rows][-1] - t[rows][0]) for rows in pieces)
    return MotionCheck(mechanism.name, str(path), solver, len(t), duration, problem, result, peaks,
                       problem.limits.assumptions(), notes)


Sampled = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _piece(problem: design.Problem, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
           notes: list[str]) -> design.Check:
    """One run's margins: jerk by differences, distances between samples through the cubic
    through its positions and velocities (a controller's interpolation)."""
    jerk = np.gradient(qdd, t, axis=0) if len(t) > 2 else None
    between = None
    if problem.scene is not None and len(t) > 1:
        from scipy.interpolate import CubicHermiteSpline
        spline = CubicHermiteSpline(t, q, qd, axis=0)

        def between(times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return spline(times), spline(times, 1), spline(times, 2)
        text = ("between samples the motion is taken as the cubic through the samples' positions and "
                "velocities (a controller's interpolation), sampled densely where the speed bound alone "
                "does not show the clearance")
        if text not in notes:
            notes.append(text)
    return design.check(problem, q, qd, qdd, jerk=jerk, times=t if len(t) > 1 else None, motion=between)


def _is_recording(path: str) -> bool:
    """A recording description (``[recording]`` or ``[[runs]]``), not a mechanism file."""
    import tomllib
    try:
        with open(path, "rb") as handle:
            keys = tomllib.load(handle).keys()
    except (OSError, tomllib.TOMLDecodeError):
        return True                                    # the recording reader says what is wrong
    return "recording" in keys or "runs" in keys


def planned_motion(path: str, names: tuple[str, ...]) -> tuple[Sampled, list[str]]:
    """A mechanism file's ``[trajectory]`` (a written plan) at ten times its samples, from its
    own expressions."""
    from baseparams.dynamics.trajectory import values_at
    from baseparams.io.loader import load_mechanism
    from baseparams.numeric.backends import Float64
    spec = load_mechanism(path).trajectory
    if spec is None:
        raise InputError("a mechanism file without a [trajectory]: nothing to check", file=path, key="trajectory")
    missing = [n for n in names if n not in spec.expressions]
    if missing:
        raise InputError(f"no trajectory for {', '.join(missing)}", file=path, key="trajectory")
    t = np.linspace(float(spec.t_start), float(spec.t_end), 10 * (spec.samples - 1) + 1)
    values = [values_at(spec.expressions[n], Float64(), t) for n in names]
    q, qd, qdd = (np.stack([np.broadcast_to(np.asarray(v[k], float), t.shape) for v in values], axis=1)
                  for k in range(3))
    return (t, q, qd, qdd), [f"the file's [trajectory] at ten times its {spec.samples} samples"]


def read_motion(mechanism: Mechanism, path: str, names: tuple[str, ...]) -> tuple[Sampled, list[str]]:
    """The motion in ``path``: a CSV (:func:`read_plan_csv`), a mechanism file's
    ``[trajectory]`` (a written plan), or a recording description as identify reads it."""
    if not Path(path).is_file():
        raise InputError("no such file", file=path, key="--check")
    if Path(path).suffix.lower() == ".csv":
        t, q, qd, qdd, notes = read_plan_csv(path, names)
        return (t, q, qd, qdd), notes
    if Path(path).suffix.lower() == ".toml" and not _is_recording(path):
        return planned_motion(path, names)
    from baseparams.recordings.recording import read_data
    data = read_data([path], mechanism)[0]
    m = data.motion
    return (np.asarray(m.t, float), np.asarray(m.q, float), np.asarray(m.qd, float), np.asarray(m.qdd, float)), \
        list(data.notes)
