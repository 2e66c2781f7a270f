"""The one result type every solver returns, with its JSON and text forms.

A base-parameter result is the splitting phi = (phi_1, phi_2) (``kept`` and
``eliminated``) with ``phi_b = phi_1 + beta phi_2``. Each base parameter is stored twice:

- as text (``base``: parameter -> coefficient string, the JSON layout), rendered once by
  :func:`coefficient_text` when the result is made: an exact value as its exact string
  ("1", "0.20898125", "625/251"), a sympy expression in the geometry symbols as written
  (symbolic solver, with exact values in ``expression_values``), any other as a decimal
  with exactly the digits the solver trusts (dp, vp without recovered rationals);
- as data (``coefficients``, same layout): a :class:`Coefficient` per entry, its value a
  Fraction (exact, or the printed decimal) with the digits the solver trusts.

Every text output (text, CSV, legends, generated modules, frames' ``expression``) prints
those strings, combined by :func:`expression_text`: the same digits everywhere (issue 45).
The JSON writes each coefficient by :func:`coefficient_json`: an exact one as its string, any
other as a number (the double nearest its decimal) with the decimal beside it, under
``decimals``; :func:`entry_texts` reads either form back as the strings.

``diagnostics`` is a :class:`Diagnostics`: typed fields that several solvers share (a
rank tolerance, proven bounds around the ridge, the certificate, the summary lines the
CLI prints, a derivation) and a solver-specific ``details`` dict, all emitted under the
JSON key ``diagnostics`` (the derivation excepted).

Comparing two results (same base parameters?) is :mod:`baseparams.solvers.compare`'s job.
"""

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import mpmath
import sympy

from baseparams.model.expressions import exact_text

# Keys of the result's JSON object, emitted by every solver (null where they do not apply:
# digits and singular_values for dp/exact/symbolic, expression_values for all but symbolic).
JSON_KEYS = ("mechanism", "solver", "parameters", "rank", "base", "eliminated", "certified",
             "digits", "singular_values", "expression_values", "geometry", "warnings",
             "diagnostics", "elapsed_s")
# Present only when true (a symbolic count that ball arithmetic could not reach).
OPTIONAL_JSON_KEYS = ("rank_is_upper_bound",)


@dataclass(frozen=True)
class Coefficient:
    """One entry of a base parameter: its printed ``text`` and its value as data.

    ``value``: a Fraction (an exact coefficient, or exactly the printed decimal), or an
    mpmath number (an algebraic symbolic value to 50 digits). ``exact``: ``value`` is the
    coefficient itself: the exact solver, the symbolic solver's rational values, the
    parameter a base parameter keeps (1), and vp's rationals recovered from its balls and
    confirmed at twice the digits (``diagnostics.rational_recovery``). ``digits``: the
    significant digits of ``value`` the solver trusts when it is not exact (the printed
    ones for dp and vp); None when exact or unknown.
    """
    text: str
    value: Fraction | mpmath.mpf
    exact: bool = False
    digits: int | None = None

    @classmethod
    def of_exact(cls, value: Fraction, text: str | None = None) -> "Coefficient":
        return cls(text=str(value) if text is None else text, value=Fraction(value), exact=True)

    @classmethod
    def of_decimal(cls, text: str, rational: Fraction | None = None) -> "Coefficient":
        """A printed decimal carrying exactly its trusted digits (dp, vp); ``rational``: an
        exact value recovered for it (vp), which the printed digits round."""
        digits = significant_digits(text)
        if rational is not None:
            return cls(text=text, value=Fraction(rational), exact=True, digits=digits)
        return cls(text=text, value=Fraction(text), exact=False, digits=digits)

    @classmethod
    def of_text(cls, text: str, geometry: Mapping[str, str] | None = None) -> "Coefficient":
        """A coefficient known only by its text (a solver that gave no data): its value,
        neither exact nor with known digits."""
        return cls(text=str(text), value=parse_coefficient(text, geometry))


@dataclass(kw_only=True)
class Diagnostics(Mapping):
    """How a solver reached its result: typed fields, then solver-specific ``details``.

    Typed fields (None where a solver has nothing to say):

    - ``summary``: lines the CLI prints under the text result;
    - ``rank_tolerance`` (dp): singular values above it count towards the rank;
    - ``sigma_r_lower`` / ``tail_bound`` (vp): proven s_r >= sigma_r_lower and
      s_(r+1) <= tail_bound, decimal strings (they may lie far below float range);
    - ``ridge_decades`` (vp): log10(sigma_r_lower / tail_bound), a proven ridge (inf when
      the tail is exactly zero);
    - ``certificate``: in words, what ``certified`` rests on (vp, exact);
    - ``derivation``: the symbolic solver's Derivation, for ``baseparams report`` (not JSON).

    The JSON object is ``details`` plus every typed field that is set (ridge_decades
    rounded to 2 decimals, "inf" for infinity), ``summary`` always. Reading it as a mapping
    (``diagnostics["runs"]``) reads that JSON object.
    """
    summary: list[str] = field(default_factory=list)
    rank_tolerance: float | None = None
    sigma_r_lower: str | None = None
    tail_bound: str | None = None
    ridge_decades: float | None = None
    certificate: str | None = None
    derivation: Any = None
    details: dict = field(default_factory=dict)

    _TYPED = ("rank_tolerance", "sigma_r_lower", "tail_bound", "ridge_decades", "certificate")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Diagnostics":
        """An untyped diagnostics dict (older solvers): ``summary`` typed, the rest details."""
        data = dict(data)
        return cls(summary=list(data.pop("summary", [])), details=data)

    def to_json(self) -> dict[str, Any]:
        out = dict(self.details)
        for name in self._TYPED:
            value = getattr(self, name)
            if value is None:
                continue
            if name in out:
                raise ValueError(f"diagnostics: {name!r} is both a typed field and a detail")
            out[name] = _json_decades(value) if name == "ridge_decades" else value
        if "summary" in out:
            raise ValueError("diagnostics: 'summary' is both a typed field and a detail")
        out["summary"] = list(self.summary)
        return out

    # read-only mapping over the JSON object
    def __getitem__(self, key: str) -> Any:
        return self.to_json()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_json())

    def __len__(self) -> int:
        return len(self.to_json())


def _json_decades(x: float) -> float | str:
    x = float(x)
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return round(x, 2)


@dataclass
class BaseParameterResult:
    mechanism: str
    solver: str
    parameters: list[str]
    rank: int
    base: list[dict[str, Any]]          # [{"name": "phi_b01", "expression": {param: str}}]
    eliminated: list[str]
    certified: bool = False
    digits: int | None = None
    singular_values: list[str] | None = None  # decimal strings, largest first
    geometry: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    expression_values: list[dict[str, str]] | None = None  # symbolic: [{param: "625/251"}], same layout as base
    rank_is_upper_bound: bool = False
    diagnostics: Diagnostics = field(default_factory=Diagnostics)
    coefficients: list[dict[str, Coefficient]] | None = None    # [{param: Coefficient}], same layout as base

    def __post_init__(self) -> None:
        if not isinstance(self.diagnostics, Diagnostics):
            self.diagnostics = Diagnostics.from_dict(self.diagnostics or {})
        if self.coefficients is None:
            self.coefficients = coefficient_rows(self.base, lambda p, t: Coefficient.of_text(t, self.geometry))
        self.coefficients = [{p: dataclasses.replace(c, text=coefficient_text(c)) for p, c in row.items()}
                             for row in self.coefficients]
        self.base = rendered_base(self.base, self.coefficients)
        if self.expression_values is not None:
            self.expression_values = [{p: value_text(t) for p, t in row.items()} for row in self.expression_values]

    @property
    def derivation(self) -> Any:
        """The symbolic derivation (``diagnostics.derivation``), or None."""
        return self.diagnostics.derivation

    @property
    def kept(self) -> list[str]:
        return [p for p in self.parameters if p not in self.eliminated
                and any(p in b["expression"] and _is_one(b["expression"][p]) for b in self.base)]

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "mechanism": self.mechanism, "solver": self.solver,
            "parameters": list(self.parameters), "rank": self.rank,
            "base": base_json(self.base, self.coefficients or []),
            "eliminated": list(self.eliminated), "certified": bool(self.certified),
            "digits": self.digits,
            "singular_values": None if self.singular_values is None else list(self.singular_values),
            "expression_values": (None if self.expression_values is None
                                  else [dict(v) for v in self.expression_values]),
            "geometry": dict(self.geometry),
            "warnings": list(self.warnings),
        }
        if self.rank_is_upper_bound:
            out["rank_is_upper_bound"] = True
        out["diagnostics"] = self.diagnostics.to_json()
        out["elapsed_s"] = round(self.elapsed_s, 3)
        return out

    def to_text(self) -> str:
        lines = [f"{self.mechanism}: {self.solver} solver, {len(self.parameters)} parameters, "
                 f"rank {self.rank}" + (" (certified)" if self.certified else "")
                 + (" (upper bound)" if self.rank_is_upper_bound else "")
                 + (f", {self.digits} digits" if self.digits else "")]
        for b in self.base:
            lines.append(f"  {b['name']} = {expression_text(b['expression'])}")
        if self.eliminated:
            lines.append(f"  eliminated ({len(self.eliminated)}): {' '.join(self.eliminated)}")
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        lines.append(f"  elapsed: {self.elapsed_s:.2f} s")
        return "\n".join(lines)

    def coefficient_matrix(self, values: bool = False) -> list[list[Fraction | mpmath.mpf]]:
        """Rows of coefficients over ``parameters``, parsed from the text: Fractions when exact
        (or exact decimals), else mpmath numbers. ``values``: the symbolic solver's exact
        values instead of its expressions."""
        rows = self.expression_values if values and self.expression_values else [b["expression"] for b in self.base]
        zero = Fraction(0)          # most of a large result's entries (TIAGo: 148 800, of which 52 700 written)
        return [[parse_coefficient(row[p], self.geometry) if p in row else zero for p in self.parameters]
                for row in rows]


def coefficient_rows(base: list[dict[str, Any]],
                     entry: Callable[[str, str], Coefficient]) -> list[dict[str, Coefficient]]:
    """``[{parameter: Coefficient}]`` in the layout of ``base``: a row's first entry (the
    parameter it keeps, "1") is exactly 1, every other is ``entry(parameter, text)``."""
    rows = []
    for b in base:
        row: dict[str, Coefficient] = {}
        for k, (param, text) in enumerate(b["expression"].items()):
            row[param] = (Coefficient.of_exact(Fraction(1), text) if k == 0 and _is_one(text)
                          else entry(param, text))
        rows.append(row)
    return rows


def coefficient_text(coefficient: Coefficient) -> str:
    """The one rendering of a coefficient (text, JSON, frames, CSV, legends): an exact value
    as its exact string (a decimal where it has one, "0.20898125", else "625/251"), whatever
    digits the solver printed it with; a symbolic expression as written; any other as the
    solver's decimal, with exactly the digits it trusts. Why: vp's rationals, confirmed at
    twice the digits, printed as "1.00000000000000000000000000000" in JSON and "1" in text,
    and the text cut every decimal at 6 or 8 digits (issue 45)."""
    if coefficient.exact and isinstance(coefficient.value, Fraction) and _is_plain_number(coefficient.text):
        return exact_text(coefficient.value)
    return str(coefficient.text)


def coefficient_json(coefficient: Coefficient) -> str | float:
    """A coefficient as the JSON writes it: a string when exact (its exact string, "625/251")
    or not a decimal (a symbolic expression, a "p/q" fraction), else the double nearest its
    value, a number to compute with; its digits go beside it (:func:`expression_json`). Why:
    a user's ``json.load`` gets floats as floats, while an exact value stays exact (issue
    45). A value beyond the doubles' range stays a string."""
    text = coefficient_text(coefficient)
    if coefficient.exact or "/" in text or not _is_plain_number(text):
        return text
    try:
        return float(coefficient.value)
    except OverflowError:
        return text


def expression_json(row: Mapping[str, Coefficient]) -> dict[str, dict[str, Any]]:
    """``{"expression": {param: str | float}, "decimals": {param: str}}``: a base parameter's
    coefficients as :func:`coefficient_json` writes them, and for each one written as a
    number its decimal with exactly the trusted digits (dp's trailing zeros, vp's digits
    beyond a double): nothing the text shows is lost."""
    expression = {p: coefficient_json(c) for p, c in row.items()}
    decimals = {p: coefficient_text(row[p]) for p, v in expression.items() if not isinstance(v, str)}
    return {"expression": expression, "decimals": decimals}


def base_json(base: list[dict[str, Any]], coefficients: list[dict[str, Coefficient]]) -> list[dict[str, Any]]:
    """The JSON's ``base`` list: ``{"name", "expression", "decimals"}`` per base parameter
    (:func:`expression_json`). The text is what the result says: an entry whose data do not
    print as its text (none, or ``base`` changed after the result was made) is read from it."""
    out = []
    for k, b in enumerate(base):
        texts = {p: str(t) for p, t in b["expression"].items()}
        row = coefficients[k] if k < len(coefficients) else {}
        if {p: coefficient_text(c) for p, c in row.items()} != texts:
            row = coefficient_rows([b], lambda p, t: Coefficient.of_text(t))[0]
        out.append({"name": b["name"], **expression_json(row)})
    return out


def entry_texts(entry: Mapping[str, Any]) -> dict[str, str]:
    """A JSON base entry's coefficients as strings, the text's: a string as written, a number
    by its decimal under ``decimals`` (else its shortest decimal). Reads results written
    before numbers were numbers (2026-11-28, issue 45: every coefficient a string) too."""
    decimals = entry.get("decimals") or {}
    out = {}
    for param, value in entry["expression"].items():
        if isinstance(value, str):
            out[param] = value
        elif isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{param}: a coefficient is a number or a string, not {type(value).__name__}")
        else:
            out[param] = str(decimals[param]) if param in decimals else (str(value) if isinstance(value, int)
                                                                         else repr(float(value)))
    return out


def value_text(text: object) -> str:
    """An exact value's string ("1/2" -> "0.5", "625/251" stays): :func:`exact_text` of a
    plain number, anything else as it is."""
    return exact_text(Fraction(str(text).strip())) if _is_plain_number(text) else str(text)


def rendered_base(base: list[dict[str, Any]], coefficients: list[dict[str, Coefficient]]) -> list[dict[str, Any]]:
    """``base`` with every coefficient's text that of its data, rendered by
    :func:`coefficient_text` (an entry the data does not hold keeps its text)."""
    out = []
    for b, row in zip(base, coefficients):
        expression = {p: coefficient_text(row[p]) if p in row else str(t) for p, t in b["expression"].items()}
        out.append({**b, "expression": expression})
    return out + [dict(b) for b in base[len(coefficients):]]


def expression_text(expression: Mapping[str, object]) -> str:
    """``m2 + 0.5*mx3 - 625/251*Iyy1 + (L**2)*Izz1``: a base parameter from its rendered
    coefficients, each with all its digits (symbolic ones in parentheses); the one form of
    the text, legends, frames and CSV."""
    terms = []
    for param, coeff in expression.items():
        text = str(coeff).strip()
        if _is_plain_number(text):
            sign, body = ("-" if text.startswith("-") else "+"), text.lstrip("+-")
        else:                               # an expression keeps its own signs
            sign, body = "+", f"({text})"
        terms.append((sign, param if body == "1" else f"{body}*{param}"))
    return " ".join(f"{s} {t}" for s, t in terms).lstrip("+ ") or "0"


def significant_digits(text: str) -> int:
    """Significant digits written in a decimal string ("0.50000" -> 5, "-3.3e-21" -> 2)."""
    mantissa = str(text).strip().lower().split("e")[0].lstrip("+-").replace(".", "").lstrip("0")
    return max(1, len(mantissa))


def _is_one(text: object) -> bool:
    return str(text).strip() == "1"


def parse_coefficient(text: object, geometry: Mapping[str, str] | None = None) -> Fraction | mpmath.mpf:
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


def _is_plain_number(text: object) -> bool:
    try:
        Fraction(str(text).strip())
        return True
    except (ValueError, ZeroDivisionError):
        return False
