"""Helpers for solver authors: base-parameter rows in the result's layout (as text and as
:class:`~baseparams.solvers.result.Coefficient` data), progress messages, and the warnings
every Gautier-type solver words the same way."""

from collections.abc import Callable, Sequence
from fractions import Fraction
from typing import Any

from baseparams.model.mechanism import Mechanism
from baseparams.solvers.result import Coefficient, coefficient_rows


def base_rows(parameters: Sequence[str], kept: Sequence[int], eliminated: Sequence[int],
              coefficient: Callable[[int, int], str | None]) -> list[dict[str, Any]]:
    """[{"name": "phi_b01", "expression": {kept: "1", eliminated: coeff, ...}}] in kept order.

    ``coefficient(a, b)``: the string for row a (kept[a]) and column b (eliminated[b]), or
    None for a zero coefficient.
    """
    rows = []
    width = max(2, len(str(len(kept))))
    for a, i in enumerate(kept):
        expression = {parameters[i]: "1"}
        for b, j in enumerate(eliminated):
            text = coefficient(a, b)
            if text is not None:
                expression[parameters[j]] = text
        rows.append({"name": f"phi_b{a + 1:0{width}d}", "expression": expression})
    return rows


def decimal_coefficients(base: list[dict[str, Any]],
                         rationals: list[dict[str, Fraction]] | None = None) -> list[dict[str, Coefficient]]:
    """Coefficient data of rows printed as decimals with exactly their trusted digits (dp,
    vp). ``rationals``: ``[{parameter: Fraction}]`` in the same layout, exact values
    recovered for the printed decimals (vp's rational recovery)."""
    def entry(a: int) -> Callable[[str, str], Coefficient]:
        return lambda param, text: Coefficient.of_decimal(
            text, None if rationals is None else rationals[a].get(param))
    return [coefficient_rows([b], entry(a))[0] for a, b in enumerate(base)]


def exact_coefficients(base: list[dict[str, Any]]) -> list[dict[str, Coefficient]]:
    """Coefficient data of rows printed as exact rationals (``exact_text``: "0.6", "625/251")."""
    return coefficient_rows(base, lambda param, text: Coefficient.of_exact(Fraction(text), text))


def say(progress: Callable[[str], None] | None, message: str) -> None:
    if progress:
        progress(message)


def untrusted_warning(items: Sequence[object]) -> str:
    return (f"{len(items)} nonzero coefficients have no trusted digit: omitted from the base "
            f"parameter expressions and listed in diagnostics.untrusted")


def raised_warning(mechanism: Mechanism, before: int, after: int, states: int,
                   double_precision: bool = False) -> str:
    cause = (f"the trajectory does not excite {mechanism.name}, or double precision lost a small "
             f"singular value of W" if double_precision else f"the trajectory does not excite {mechanism.name}")
    return (f"{cause}: rank raised from {before} to {after} by an independent random batch ({states} "
            f"random positions, velocities and accelerations), analysed together with W; use more "
            f"samples or a richer trajectory" + (", or vp" if double_precision else ""))


# ----- estimates of long work ----------------------------------------------------------------
def size_text(n: float) -> str:
    """Bytes in GiB or MiB, as the memory-limit messages word them."""
    n = max(n, 1024 ** 2)           # "about 1 MiB" for anything small
    return f"{n / 1024 ** 3:.1f} GiB" if n >= 1024 ** 3 else f"{n / 1024 ** 2:.0f} MiB"


def seconds_text(s: float) -> str:
    s = max(s, 1.0)
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.0f} min" if s < 7200 else f"{s / 3600:.1f} h"


def check_memory(need: float, what: str, advice: str, file: str | None = None, key: str | None = None) -> None:
    """Refuse (InputError) work whose estimated memory ``need`` exceeds the budget that
    ``BASEPARAMS_MAX_MEMORY`` sets (the same limit the float64 stage uses), before it is
    allocated: the process would otherwise grow for minutes and be killed by the system."""
    from baseparams.dynamics.trajectory import MEMORY_VARIABLE, memory_limit
    from baseparams.errors import InputError
    limit = memory_limit()
    if need > limit:
        raise InputError(f"{what} needs about {size_text(need)} of memory, above the limit of {size_text(limit)}: "
                         f"{advice}, or raise the limit with the environment variable {MEMORY_VARIABLE} "
                         f"(e.g. {MEMORY_VARIABLE}=16G)", file=file, key=key)
