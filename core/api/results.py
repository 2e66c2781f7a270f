"""What the public functions return: the objects the command line prints.

Every result has ``to_json()`` (exactly the object ``baseparams VERB --format json``
prints), ``to_text()`` (what the verb prints without it), ``to_frame()`` (a pandas
DataFrame where a table fits; pandas is optional and imported on use) and a notebook view
(``_repr_markdown_``). The underlying objects stay reachable (``.result``,
``.identification``, ``.diagnosis``, ...) for work the summary does not cover.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from baseparams.errors import InputError

if TYPE_CHECKING:       # the heavy modules load when a verb runs, not on `import baseparams`
    import numpy as np
    import pandas

    from baseparams.excite.plan import Plan
    from baseparams.recordings.data import MeasuredData
    from baseparams.diagnose.change import ChangeDiagnosis
    from baseparams.diagnose.workflow import Diagnosis
    from baseparams.identify.fit import Identification, Prediction
    from baseparams.model.mechanism import Mechanism
    from baseparams.orchestrate.validate import Report
    from baseparams.solvers.result import BaseParameterResult


def _pandas() -> Any:
    """pandas, or an ImportError that says how to install it (it is an optional extra)."""
    try:
        import pandas
    except ImportError:
        raise ImportError("to_frame() needs pandas, an optional dependency: pip install pandas") from None
    return pandas


def plural(count: int, word: str, many: str | None = None) -> str:
    """``1 hidden effect``, ``2 hidden effects``."""
    return f"{count} {word if count == 1 else (many or word + 's')}"


class Result:
    """The shared face of every result: JSON, text, a frame and a notebook view."""

    def to_json(self) -> dict[str, Any]:
        """The object ``--format json`` prints (docs/design.md, "Results as JSON")."""
        raise NotImplementedError

    def to_text(self) -> str:
        """What the verb prints as text."""
        raise NotImplementedError

    def rows(self) -> list[dict[str, Any]]:
        """The table :meth:`to_frame` shows (one dict per row); empty when none fits."""
        return []

    def to_frame(self) -> "pandas.DataFrame":
        """The result's table as a pandas DataFrame (pandas is optional: an ImportError
        saying how to install it when missing)."""
        pandas = _pandas()
        return pandas.DataFrame(self.rows())

    def __str__(self) -> str:
        return self.to_text()

    def _repr_markdown_(self) -> str:
        """Jupyter: the text report, preformatted."""
        return "```\n" + self.to_text() + "\n```"

    def _repr_html_(self) -> str:
        return "<pre>" + html.escape(self.to_text()) + "</pre>"


# ----- solve ---------------------------------------------------------------------------
@dataclass
class Solution(Result):
    """A solver's base parameters of one mechanism (``baseparams solve``). Attribute access
    falls through to the solver's :class:`~baseparams.solvers.result.BaseParameterResult`
    (``rank``, ``base``, ``eliminated``, ``certified`` ...)."""
    result: "BaseParameterResult"
    mechanism: "Mechanism"

    def __getattr__(self, name: str) -> Any:
        if name in ("result", "mechanism"):      # not yet set (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.result, name)

    def to_json(self) -> dict[str, Any]:
        return self.result.to_json()

    def to_text(self) -> str:
        lines = [self.result.to_text()]
        lines += [f"  {line}" for line in self.result.diagnostics.summary]
        return "\n".join(lines)

    def rows(self) -> list[dict[str, Any]]:
        """One row per base parameter: its name, its expression (as the text and ``solve
        --format csv`` write it) and a float column per standard parameter (``parameters``
        order): its coefficient, ``base_matrix()``'s row, the numbers of ``to_json()``
        (exact values rounded once: their exact strings are in ``expression``)."""
        params = list(self.result.parameters)
        return [{"name": b["name"], "expression": expression_text(b["expression"]),
                 **dict(zip(params, map(float, row)))} for b, row in zip(self.result.base, self.base_matrix())]

    def legend(self) -> list[str]:
        """``phi_b01 = m1 + 0.5*mx2`` lines: what each base parameter stands for (the digits of
        ``str()``, ``to_json()`` and ``to_frame()``)."""
        return legend_lines(self.result.base)

    def base_matrix(self) -> np.ndarray:
        """B (rank, P), float64: row i holds base parameter i's coefficients over the
        standard parameters (``parameters``, in that order), so phi_b = B phi. Exact solvers'
        rows are their exact values rounded once; for the exact rows use
        ``coefficient_matrix()``."""
        import numpy as np
        rows = self.result.coefficient_matrix(values=True)
        return np.array([[float(v) for v in row] for row in rows], dtype=float).reshape(len(rows), -1)

    def to_base(self, standard: Mapping[str, float] | Sequence[float]) -> np.ndarray:
        """The base parameters (rank,) of a vector of standard parameters (a simulation's
        truth, a CAD model's inertias): by name (``{"m1": 2.0, ...}``, absent names 0) or as a
        sequence in ``parameters`` order. Why: to compare an identification with a known
        truth, the truth must be mapped onto what the data can determine."""
        import numpy as np
        names = list(self.result.parameters)
        if isinstance(standard, Mapping):
            unknown = sorted(set(standard) - set(names))
            if unknown:
                raise InputError(f"not standard parameters of {self.mechanism.name}: {', '.join(unknown[:5])}"
                                 f"{' ...' if len(unknown) > 5 else ''} (they are {', '.join(names[:4])}, ...)")
            phi = np.array([float(standard.get(name, 0.0)) for name in names])
        else:
            phi = np.asarray(standard, dtype=float).reshape(-1)
            if len(phi) != len(names):
                raise InputError(f"{len(phi)} values for the {len(names)} standard parameters of "
                                 f"{self.mechanism.name}")
        return self.base_matrix() @ phi


def expression_text(expression: Mapping[str, object]) -> str:
    """:func:`baseparams.solvers.result.expression_text`, the one rendering of a base
    parameter (kept importable here)."""
    from baseparams.solvers.result import expression_text as text
    return text(expression)


def legend_lines(base: list[dict[str, Any]]) -> list[str]:
    """``phi_b01 = m1 + 0.5*mx2``: each base parameter's expression, one line each, with the
    digits of the text, JSON and frames."""
    return [f"{b['name']} = {expression_text(b['expression'])}" for b in base]


# ----- simulate ------------------------------------------------------------------------
@dataclass
class Simulation(Result):
    """Synthetic measured data (``baseparams simulate``) and the truth that produced it."""
    data: "MeasuredData"
    truth: dict[str, Any]
    effects: int
    output: str | None = None
    truth_path: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"output": self.output, "truth": self.truth_path, "samples": self.data.count,
                "coordinates": list(self.data.coordinates), "effects": self.effects}

    def to_text(self) -> str:
        where = f"wrote {self.output}" if self.output else "simulated"
        return (f"{where} ({self.data.count} samples, coordinates {', '.join(self.data.coordinates)}, "
                f"{plural(self.effects, 'hidden effect')})" + (f"; truth in {self.truth_path}" if self.truth_path else ""))

    def rows(self) -> list[dict[str, Any]]:
        """One row per sample: t, q_*, qd_*, qdd_*, tau_* (the CSV's columns)."""
        motion, rows = self.data.motion, []
        names = self.data.coordinates
        for k in range(self.data.count):
            row: dict[str, Any] = {"t": float(motion.t[k])}
            for prefix, values in (("q", motion.q), ("qd", motion.qd), ("qdd", motion.qdd), ("tau", self.data.tau)):
                if values is not None:
                    row.update({f"{prefix}_{c}": float(values[k, j]) for j, c in enumerate(names)})
            rows.append(row)
        return rows


# ----- identify ------------------------------------------------------------------------
@dataclass
class Fit(Result):
    """An identification (``baseparams identify``): estimates with standard deviations, the
    residual per coordinate, predictions on the recordings given with ``validate``, and with
    ``physical`` the physically consistent standard parameters and the programme's status."""
    identification: "Identification"
    fitted: "Prediction"
    predictions: list["Prediction"] = field(default_factory=list)
    written: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)       # the solver's, impossible estimates (stderr in the CLI)

    def to_json(self) -> dict[str, Any]:
        return self.identification.to_json()

    def to_text(self) -> str:
        ident, fitted = self.identification, self.fitted
        lines = [ident.to_text()]
        lines.append(f"  RMS residual overall {fitted.overall_rms:.4g}; per coordinate: "
                     + ", ".join(f"{c} {r:.4g}" for c, r in zip(fitted.coordinates, fitted.rms)))
        raw = ident.extras.get("nrms_unfiltered")
        if raw and any(abs(raw[c] - n) > 1e-12 for c, n in zip(ident.coordinates, ident.nrms)):
            lines.append("  NRMS on the unfiltered torques (the fit's rows, without its filter): "
                         + ", ".join(f"{c} {v:.4g}" for c, v in raw.items()))
        if ident.base.expressions:
            lines.append("  base parameters (what each estimate stands for):")
            lines += [f"    {line}" for line in legend_lines(self.base_rows())]
        if ident.physical is not None:
            info = ident.extras["physical_fit"]
            lines.append(f"  physically consistent parameters (prior: {info['prior']}; {info['solver']} status "
                         f"{info['status']}; the base estimates reproduced within {info['max_deviation_std']:.3g} std):")
            for warning in info.get("warnings", []):
                lines.append(f"    warning: {warning}")
            lines += [f"    {k} = {v}" for k, v in ident.physical.items()]
        lines += [p.to_text() for p in self.predictions]
        lines += [f"wrote {path}" for path in self.written]
        return "\n".join(lines)

    def base_rows(self) -> list[dict[str, Any]]:
        base = self.identification.base
        return [{"name": name, "expression": dict(expression)} for name, expression in zip(base.names, base.expressions)]

    def rows(self) -> list[dict[str, Any]]:
        """One row per unknown: name, kind (base, effect, gain), estimate, std, std %."""
        ident, out = self.identification, []
        for k, name in enumerate(ident.names):
            rel = float(ident.relative_std[k])
            out.append({"name": name, "kind": ident.kinds[k], "estimate": float(ident.estimates[k]),
                        "std": float(ident.std[k]), "std_percent": rel if math.isfinite(rel) else None})
        return out


# ----- diagnose ------------------------------------------------------------------------
@dataclass
class Diagnosed(Result):
    """A diagnosis (``baseparams diagnose``): the verdict, the named effects, the gap before
    and after. ``closed`` is the verb's exit status (0 when true). ``kinds``: what each
    coordinate and motor measures ('angle' or 'length'), for the units of the text report."""
    diagnosis: "Diagnosis"
    written: str | None = None
    kinds: dict[str, str] = field(default_factory=dict)

    @property
    def closed(self) -> bool:
        return self.diagnosis.closed

    def to_json(self) -> dict[str, Any]:
        out = self.diagnosis.to_json()
        out["written"] = self.written
        return out

    def to_text(self, verbose: bool = False) -> str:
        """The report read in a minute (at most 25 lines: the verdict, the gap, each named
        effect on one line with its unit, where the gap remains, counts of the rest);
        ``verbose``: the whole report (every candidate not named with its reason, the
        residual's statistics, every note)."""
        from baseparams.api.render import diagnosis_text
        return diagnosis_text(self.diagnosis, self.written, verbose=verbose, kinds=self.kinds)

    def rows(self) -> list[dict[str, Any]]:
        """One row per named effect's coefficient: kind, coordinate, coefficient, value, std."""
        out = []
        for e in self.diagnosis.effects:
            for name, c in e["coefficients"].items():
                out.append({"kind": e["kind"], "coordinate": e["coordinate"], "coefficient": name,
                            "value": c["value"], "std": c["std"], "pvalue_holm": e["test"]["pvalue_holm"]})
        return out


# ----- validate ------------------------------------------------------------------------
@dataclass
class Validation(Result):
    """Cross-validation of solvers (``baseparams validate``); ``ok`` is the exit status."""
    report: "Report"

    @property
    def ok(self) -> bool:
        return self.report.ok

    def to_json(self) -> dict[str, Any]:
        return self.report.to_json()

    def to_text(self) -> str:
        from baseparams.orchestrate.validate import render_text
        return render_text(self.report)

    def to_markdown(self) -> str:
        from baseparams.orchestrate.validate import render_markdown
        return render_markdown(self.report)

    def _repr_markdown_(self) -> str:
        return self.to_markdown()

    def rows(self) -> list[dict[str, Any]]:
        """One row per mechanism and check: mechanism, check, ok, detail."""
        return [{"mechanism": m.name, "check": c.name, "ok": c.ok, "detail": c.detail}
                for m in self.report.mechanisms for c in m.checks]


# ----- excite --------------------------------------------------------------------------
@dataclass
class Excitation(Result):
    """A planned exciting motion (``baseparams excite``) and the files written."""
    plan: "Plan"
    mechanism: "Mechanism"
    output: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    written: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        out = self.plan.to_json()
        out["output"] = self.output
        out.update(self.extra)
        return out

    def to_text(self) -> str:
        lines = [self.plan.to_text()]
        lines += [f"wrote {p}" for p in ([self.output] if self.output else []) + self.written]
        return "\n".join(lines)

    def toml(self) -> str:
        """The mechanism file with the planned motion as its ``[trajectory]``."""
        from baseparams.excite.plan import with_trajectory
        from baseparams.io.toml_writer import mechanism_toml
        return mechanism_toml(with_trajectory(self.mechanism, self.plan))


# ----- export and convert --------------------------------------------------------------
@dataclass
class Export(Result):
    """A standalone numpy module of a mechanism's regressor (``baseparams export``)."""
    source: str
    solution: Solution
    output: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"mechanism": self.solution.mechanism.name, "solver": self.solution.result.solver,
                "base_parameters": len(self.solution.result.base), "output": self.output}

    def to_text(self) -> str:
        """A summary; the module itself is ``source`` (printing 300 lines of code for
        ``print(bp.export(...))`` told nothing)."""
        where = f"written to {self.output}" if self.output else "in .source"
        return (f"regressor and base_regressor of {self.solution.mechanism.name} "
                f"({len(self.solution.result.base)} base parameters, solver {self.solution.result.solver}): "
                f"{len(self.source.splitlines())} lines of Python, {where}")


@dataclass
class Conversion(Result):
    """A mechanism read by one plugin and written by another (``baseparams convert``);
    ``notes``: what the target cannot hold or what was approximated."""
    mechanism: "Mechanism"
    output: str
    writer: str
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        m = self.mechanism
        return {"output": self.output, "writer": self.writer, "bodies": len(m.bodies), "joints": len(m.joints),
                "coordinates": len(m.coordinates), "notes": list(self.notes)}

    def to_text(self) -> str:
        m = self.mechanism
        return (f"wrote {self.output} ({self.writer}): {len(m.bodies)} bodies, {len(m.joints)} joints, "
                f"{len(m.coordinates)} coordinates")


@dataclass
class ChangeDiagnosed(Result):
    """What changed between a baseline and changed runs (``baseparams diagnose CHANGED...
    --baseline BASE...``): the verdict, each change in physical terms, the gap between the
    two sides before and after. ``closed`` is the verb's exit status (0 when true: nothing
    changed, or the named changes explain the difference)."""
    diagnosis: "ChangeDiagnosis"
    kinds: dict[str, str] = field(default_factory=dict)

    @property
    def closed(self) -> bool:
        return self.diagnosis.closed

    def to_json(self) -> dict[str, Any]:
        return self.diagnosis.to_json()

    def to_text(self, verbose: bool = False) -> str:
        """At most 25 lines (``verbose``: every note and the first step's candidates too)."""
        from baseparams.api.render import change_text
        return change_text(self.diagnosis, verbose=verbose, kinds=self.kinds)

    def rows(self) -> list[dict[str, Any]]:
        """One row per named change's coefficient: kind, place, coefficient, value, std."""
        return [{"kind": e["kind"], "coordinate": e["coordinate"], "coefficient": name, "value": c["value"],
                 "std": c["std"], "pvalue_holm": e["test"]["pvalue_holm"]}
                for e in self.diagnosis.changes for name, c in e["coefficients"].items()]
