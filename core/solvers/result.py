"""The one result type every solver returns, with its JSON and text forms.

A base-parameter result is the splitting phi = (phi_1, phi_2) (``kept`` and
``eliminated``) with ``phi_b = phi_1 + beta phi_2``. Each base parameter is stored as a
mapping parameter -> coefficient string: decimal digits the solver trusts (numeric
solvers), an exact rational ("625/251"), or a sympy expression in the geometry symbols
(symbolic solver, with exact values in ``expression_values``).

Comparing two results (same base parameters?) is :mod:`baseparams.solvers.compare`'s job.
"""

from dataclasses import dataclass, field
from fractions import Fraction

import mpmath
import sympy


@dataclass
class BaseParameterResult:
    mechanism: str
    solver: str
    parameters: list
    rank: int
    base: list                          # [{"name": "phi_b01", "expression": {param: str}}]
    eliminated: list
    certified: bool = False
    digits: int | None = None
    singular_values: list | None = None  # decimal strings, largest first
    geometry: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    elapsed_s: float = 0.0
    expression_values: list | None = None  # symbolic: [{param: "625/251"}], same layout as base
    rank_is_upper_bound: bool = False
    diagnostics: dict = field(default_factory=dict)

    @property
    def kept(self):
        return [p for p in self.parameters if p not in self.eliminated
                and any(p in b["expression"] and _is_one(b["expression"][p]) for b in self.base)]

    def to_json(self):
        out = {
            "mechanism": self.mechanism, "solver": self.solver,
            "parameters": list(self.parameters), "rank": self.rank,
            "base": [{"name": b["name"], "expression": dict(b["expression"])} for b in self.base],
            "eliminated": list(self.eliminated), "certified": bool(self.certified),
        }
        if self.digits is not None:
            out["digits"] = self.digits
        if self.singular_values is not None:
            out["singular_values"] = list(self.singular_values)
        if self.expression_values is not None:
            out["expression_values"] = [dict(v) for v in self.expression_values]
        out["geometry"] = dict(self.geometry)
        out["warnings"] = list(self.warnings)
        if self.rank_is_upper_bound:
            out["rank_is_upper_bound"] = True
        if self.diagnostics:
            out["diagnostics"] = self.diagnostics
        out["elapsed_s"] = round(self.elapsed_s, 3)
        return out

    def to_text(self, max_digits=8):
        lines = [f"{self.mechanism}: {self.solver} solver, {len(self.parameters)} parameters, "
                 f"rank {self.rank}" + (" (certified)" if self.certified else "")
                 + (" (upper bound)" if self.rank_is_upper_bound else "")
                 + (f", {self.digits} digits" if self.digits else "")]
        for b in self.base:
            lines.append(f"  {b['name']} = {format_expression(b['expression'], max_digits)}")
        if self.eliminated:
            lines.append(f"  eliminated ({len(self.eliminated)}): {' '.join(self.eliminated)}")
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        lines.append(f"  elapsed: {self.elapsed_s:.2f} s")
        return "\n".join(lines)

    def coefficient_matrix(self, values=False):
        """Rows of coefficients over ``parameters``: Fractions when exact, else mpmath numbers."""
        rows = self.expression_values if values and self.expression_values else [b["expression"] for b in self.base]
        return [[parse_coefficient(row.get(p, "0"), self.geometry) for p in self.parameters] for row in rows]


def _is_one(text):
    return str(text).strip() == "1"


def parse_coefficient(text, geometry=None):
    """A coefficient string -> Fraction (exact rational or exact decimal) or sympy-evaluated Fraction."""
    text = str(text).strip()
    try:
        return Fraction(text)
    except ValueError:
        pass
    expr = sympy.sympify(text)
    if geometry:
        expr = expr.subs({sympy.Symbol(k): sympy.Rational(v) for k, v in geometry.items()})
    expr = sympy.nsimplify(expr) if not expr.is_Rational else expr
    if expr.is_Rational:
        return Fraction(int(expr.p), int(expr.q))
    with mpmath.workdps(60):            # keep the 50 digits (mpf rounds to the working precision)
        return mpmath.mpf(str(sympy.N(expr, 50)))


def format_number(value, max_digits=8):
    """Short decimal for text tables."""
    if isinstance(value, Fraction):
        if value.denominator == 1:
            return str(value.numerator)
        value = mpmath.mpf(value.numerator) / value.denominator
    return mpmath.nstr(mpmath.mpf(value), max_digits)


def format_expression(expression, max_digits=8):
    parts = []
    for param, coeff in expression.items():
        # symbolic coefficients (geometry symbols) are printed as they are, never evaluated
        symbolic = isinstance(coeff, str) and not _is_plain_number(coeff)
        value = None if symbolic else parse_coefficient(coeff)
        if not symbolic:
            num = value
            sign = "-" if num < 0 else "+"
            mag = abs(num)
            text = param if mag == 1 else f"{format_number(mag, max_digits)}*{param}"
        else:
            sign, text = "+", f"({coeff})*{param}"
        parts.append((sign, text))
    if not parts:
        return "0"
    first_sign, first = parts[0]
    out = ("-" if first_sign == "-" else "") + first
    for sign, text in parts[1:]:
        out += f" {sign} {text}"
    return out


def _is_plain_number(text):
    try:
        Fraction(str(text))
        return True
    except ValueError:
        return False
