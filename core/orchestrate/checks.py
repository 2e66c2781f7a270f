"""Cross-solver checks on one mechanism, each the strongest comparison its pair allows.

Results arrive as JSON (they may come from other processes or machines). From each the
checks read what it claims:

- **exact rows**: the exact solver's coefficients, the symbolic solver's
  ``expression_values`` and vp's rationals recovered from its balls and confirmed at twice
  the digits (``diagnostics.rational_recovery.base``): Fractions, compared exactly
  (rational rank of the stacked rows, :func:`baseparams.solvers.compare.same_row_space`);
- **decimal rows** (dp; vp when it recovered no rationals): compared with the reference
  space by the largest principal angle between the two row spaces, against the tolerance
  the solver states for itself: its printed coefficients (``decimals`` beside the numbers of
  ``expression``, or older results' strings) carry ``d`` trusted significant
  digits, so each row moves by at most ``10^(1-d)`` relative; dp also states a first-order
  error estimate of beta. The tolerance is ``10 sqrt(n)`` times the larger of the two
  (never below the 1e-13 float64 floor of the angle computation).

The reference space is the first exact result (exact, then symbolic values, then vp's
rationals); failing those, the first certified numeric result. A certified rank outranks
an uncertified one. dp disagreeing with the reference is a failure when it said nothing,
and "dp unreliable here, warned" when its own warnings flagged the weakness.
"""

import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import Any

import numpy as np
import sympy

from baseparams.orchestrate.model_checks import Check
from baseparams.solvers.compare import same_row_space
from baseparams.solvers.result import entry_texts, parse_coefficient

ANGLE_FLOOR = 1e-13


def exact_rows(result: Mapping[str, Any], capabilities: Any = None) -> list[list[Fraction]] | None:
    """The result's base parameters as exact rows over ``parameters``, or None if it has none:
    vp's confirmed rationals, the symbolic values, or coefficients a solver declares exact
    (``capabilities.exact_coefficients``). Algebraic (irrational) values are not rows here."""
    recovery = (result.get("diagnostics") or {}).get("rational_recovery") or {}
    if recovery.get("succeeded"):
        layout = [r["expression"] for r in recovery["base"]]
    elif result.get("expression_values"):
        layout = result["expression_values"]
    elif getattr(capabilities, "exact_coefficients", False):
        layout = [entry_texts(b) for b in result["base"]]
    else:
        return None
    rows = _rows(layout, result["parameters"])
    return rows if all(isinstance(v, Fraction) for row in rows for v in row) else None


def decimal_rows(result: Mapping[str, Any]) -> list[list[Fraction]]:
    """The printed coefficients as Fractions (exactly the printed decimals)."""
    layout = result.get("expression_values") or [entry_texts(b) for b in result["base"]]
    return _rows(layout, result["parameters"], result.get("geometry"))


def stated_tolerance(result: Mapping[str, Any]) -> float:
    """The relative accuracy a numeric solver states for its printed coefficients."""
    digits = [_significant_digits(c) for b in result["base"] for c in entry_texts(b).values()
              if not _is_one(c)]
    worst = 10.0 ** (1 - min(digits)) if digits else 0.0
    estimate = float((result.get("diagnostics") or {}).get("beta_error_estimate") or 0.0)
    n = len(result["parameters"])
    return max(ANGLE_FLOOR, 10 * math.sqrt(n) * max(worst, estimate))


def largest_principal_angle_sine(a: Sequence[Sequence[Fraction]], b: Sequence[Sequence[Fraction]]) -> float:
    """sin of the largest principal angle between the row spaces of a and b (float64)."""
    A, B = (np.array([[float(v) for v in row] for row in m], dtype=float) for m in (a, b))
    if A.size == 0 or B.size == 0:
        return 0.0 if A.size == B.size else 1.0
    qa, _ = np.linalg.qr(A.T)
    qb, _ = np.linalg.qr(B.T)
    if qa.shape[1] != qb.shape[1]:
        return 1.0
    residual = qb - qa @ (qa.T @ qb)
    return float(np.linalg.norm(residual, 2))


def cross_checks(results: Mapping[str, Mapping[str, Any]],
                 capabilities: Mapping[str, Any] | None = None) -> list[Check]:
    """Checks between the successful results of one mechanism (solver name -> result JSON);
    ``capabilities``: solver name -> its declared capabilities (which results are exact)."""
    capabilities = capabilities or {}
    if not results:
        return []
    checks = []
    reference_rank, reference = _reference_rank(results)
    for name, r in results.items():
        if r["rank"] == reference_rank:
            continue
        warned = name == "dp" and bool(r.get("warnings"))
        checks.append(Check(f"rank {name}", False if not warned else True,
                            f"{name} gives rank {r['rank']}, {reference} gives {reference_rank}"
                            + (" (certified)" if results[reference].get("certified") else "")
                            + ("; dp unreliable here, warned: " + r["warnings"][0] if warned else ""),
                            warned=warned, about=name))
    if len(results) > 1 and not checks:
        checks.append(Check("ranks", True, f"all give rank {reference_rank}: "
                                          + ", ".join(f"{n}{' (certified)' if r.get('certified') else ''}"
                                                      for n, r in results.items())))
    checks += _space_checks(results, reference_rank, capabilities)
    if "symbolic" in results:
        checks.append(_symbolic_values_check(results["symbolic"]))
    return checks


def _reference_rank(results: Mapping[str, Mapping[str, Any]]) -> tuple[int, str]:
    certified = [n for n, r in results.items() if r.get("certified")]
    name = certified[0] if certified else next(iter(results))
    return results[name]["rank"], name


def _space_checks(results: Mapping[str, Mapping[str, Any]], rank: int, capabilities: Mapping[str, Any]) -> list[Check]:
    exact: dict[str, list[list[Any]]] = {}
    for name, r in results.items():
        if r["rank"] != rank:
            continue
        rows = exact_rows(r, capabilities.get(name))
        if rows is not None:
            exact[name] = rows
    checks = []
    ref_name = _majority(exact)
    for other in exact:
        if ref_name is None or other == ref_name:
            continue
        same = same_row_space(exact[ref_name], exact[other])
        checks.append(Check(f"space {ref_name} = {other}", same,
                            "exact comparison (rational rank of the stacked rows): "
                            + ("the same base-parameter space" if same else "DIFFERENT base-parameter spaces"),
                            about=other))
    for name, r in results.items():
        if name in exact or r["rank"] != rank:
            continue
        if ref_name is None:
            candidates = [n for n in results if n != name and results[n]["rank"] == rank]
            if not candidates:
                continue
            ref_rows, ref_label = decimal_rows(results[candidates[0]]), candidates[0]
            tol = max(stated_tolerance(r), stated_tolerance(results[candidates[0]]))
        else:
            ref_rows, ref_label = exact[ref_name], ref_name
            tol = stated_tolerance(r)
        sine = largest_principal_angle_sine(ref_rows, decimal_rows(r))
        ok = sine <= tol
        warned = not ok and name == "dp" and bool(r.get("warnings"))
        detail = (f"largest principal angle between the row spaces: sin = {sine:.2g}, {name}'s stated "
                  f"tolerance {tol:.2g}")
        if warned:
            detail += "; dp unreliable here, warned: " + r["warnings"][0]
        checks.append(Check(f"space {ref_label} ~ {name}", ok or warned, detail, warned=warned, about=name))
    return checks


def _majority(exact: Mapping[str, Any]) -> str | None:
    """The exact result that the most others agree with (the first such in solver order):
    with three exact results, one wrong one is then named, not the reference."""
    if not exact:
        return None
    names = list(exact)
    agree = {a: sum(same_row_space(exact[a], exact[b]) for b in names if b != a) for a in names}
    return max(names, key=lambda a: (agree[a], -names.index(a)))


def _symbolic_values_check(result: Mapping[str, Any]) -> Check:
    """The symbolic expressions at the file's geometry equal the exact values it lists."""
    name = "symbolic expressions = values"
    values = result.get("expression_values")
    if not values:
        return Check(name, False, "the symbolic result lists no expression_values", about="symbolic")
    geometry = {sympy.Symbol(k): sympy.Rational(v) for k, v in (result.get("geometry") or {}).items()}
    bad = []
    for row, vals in zip(result["base"], values):
        for param, text in entry_texts(row).items():
            expr = sympy.sympify(text).subs(geometry)
            value = sympy.sympify(vals.get(param, "0"))
            if sympy.simplify(expr - value) != 0:
                bad.append(f"{row['name']}: {param}: {text} -> {sympy.nsimplify(expr)} but listed {vals.get(param)}")
    return Check(name, not bad, about="symbolic", detail="every expression, evaluated exactly at the file's geometry, equals its listed value"
                 if not bad else f"{len(bad)} differ: " + "; ".join(bad[:3]))


def _rows(layout: Sequence[Mapping[str, str]], params: Sequence[str], geometry: Mapping[str, Any] | None = None) -> list[list[Any]]:
    return [[parse_coefficient(row[p], geometry) if p in row else Fraction(0) for p in params] for row in layout]


def _is_one(text: Any) -> bool:
    return str(text).strip() == "1"


def _significant_digits(text: Any) -> int:
    digits = str(text).lower().split("e")[0].lstrip("+-").replace(".", "").lstrip("0")
    return max(1, len(digits))
