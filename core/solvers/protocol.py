"""The contract between baseparams and a solver: what it declares, what it may be asked.

A solver is any object registered through the ``baseparams_solvers`` hook that satisfies
:class:`Solver`:

- ``name`` and ``description`` (text for ``baseparams plugins`` and ``solve --help``);
- ``capabilities``: a :class:`Capabilities` (what kind of mechanism it takes, what its
  result proves and holds), so that callers choose a solver by property, not by name;
- ``options``: a tuple of :class:`SolverOption`, every keyword ``solve`` accepts besides
  ``progress``; :func:`check_options` rejects any other and fills the defaults;
- ``applicable(mechanism)``: None when the solver can treat the mechanism, else the
  reason it cannot (a sentence for the user), found without solving;
- ``solve(mechanism, *, progress=None, **options)``: a
  :class:`~baseparams.solvers.result.BaseParameterResult`. ``options`` are keywords named
  in ``options`` (a solver spells them as typed keyword parameters with the declared
  defaults); ``progress``, when given, receives one-line messages.

The generic checks are not the solver's: :func:`baseparams.solvers.run.run_solver` (the one
sequence every caller uses) checks the options against the declarations
(:func:`check_options`: unknown names, types, ranges, the mechanism's bounds), refuses a
mechanism the solver does not take (:func:`require_applicable`: :class:`NotApplicable`)
and only then calls ``solve`` with every declared option. ``solve`` itself checks only
what depends on its own work (dp: a rank above W's row count, known once W is built) and
raises :class:`~baseparams.errors.InputError` for it.

The library call is ``run_solver("vp", mech, {"digits": 30, "recover": False})``;
``solver.solve(mech, digits=30, recover=False)`` skips the checks (values known valid).
"""

import builtins
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NoReturn, Protocol, runtime_checkable

from baseparams.errors import InputError
from baseparams.model.mechanism import MAX_SAMPLES, Mechanism
from baseparams.solvers.result import BaseParameterResult

Progress = Callable[[str], None]

_TRUE = ("true", "yes", "on", "1")
_FALSE = ("false", "no", "off", "0")
_TYPE_WORDS = {int: "an integer", float: "a number", bool: "true or false", str: "a string",
               tuple: "a list"}
# command-line numbers: ASCII digits only (int() would take "1_0" as 10 and Arabic-Indic digits)
_INT_TEXT = re.compile(r"[+-]?[0-9]+")
_FLOAT_TEXT = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")
MAX_DIGITS = 20000          # the working precision's cap, as the CLI's --digits
MAX_SEED = 2 ** 32 - 1       # seeds: 0 to 2^32 - 1 (numpy's range; Python's random takes them all)


@dataclass(frozen=True)
class Capabilities:
    """What a solver takes and what its result holds (all False unless declared).

    closed_loops: treats mechanisms with kinematic loops.
    needs_rational_geometry: needs geometry that stays rational in its arithmetic (unit
        axes with rational components, no square roots).
    certifies: ``certified`` can be true (the rank proven, not only estimated).
    exact_coefficients: its coefficients are exact numbers by construction.
    symbolic_coefficients: its coefficients are expressions in the geometry symbols.
    derivation: its result carries a derivation (``diagnostics.derivation``) that
        ``baseparams report`` renders.
    """
    closed_loops: bool = False
    needs_rational_geometry: bool = False
    certifies: bool = False
    exact_coefficients: bool = False
    symbolic_coefficients: bool = False
    derivation: bool = False


@dataclass(frozen=True)
class SolverOption:
    """One keyword ``solve`` accepts.

    ``type``: int, float, bool, str or tuple (a sequence of ``item``; a str is split on
    commas and spaces). ``default`` None means "automatic" and is always accepted.
    ``choices``: the allowed values of a str option (empty: any).

    The range lives here, in the declaration, so that :func:`check_options` refuses a
    degenerate value (a ladder step of 0 digits, a rank of 1000 on 10 parameters) before
    any work, for every solver alike:

    ``minimum``, ``maximum``: the least and greatest value of a number option, or of each
    item of a tuple of numbers. ``maximum`` may be a function of the mechanism (e.g. its
    number of parameters), checked when :func:`check_options` is given the mechanism;
    ``maximum_text`` then says what it is ("the number of parameters").
    ``length``: (least, greatest) number of items of a tuple option.
    ``increasing``: a tuple's items must be strictly increasing (a precision ladder).
    ``unique``: a tuple's items must be distinct.
    """
    name: str
    type: type
    default: Any = None
    help: str = ""
    item: builtins.type | None = None
    choices: tuple[str, ...] = ()
    minimum: int | float | None = None
    maximum: int | float | Callable[[Mechanism], int | float] | None = None
    maximum_text: str = ""
    length: tuple[int, int] | None = None
    increasing: bool = False
    unique: bool = False

    def bounds_text(self) -> str:
        """``10 to 20000``-style range words for help texts ("" when unbounded)."""
        low = "" if self.minimum is None else str(self.minimum)
        if callable(self.maximum):
            high = self.maximum_text or "a limit of the mechanism"
        else:
            high = "" if self.maximum is None else str(self.maximum)
        if not low and not high:
            return ""
        if low and high:
            return f"{low} to {high}"
        return f"at least {low}" if low else f"at most {high}"

    def describe(self) -> str:
        """``type, default ...: help`` for help texts (an automatic default: in the help)."""
        kind = "|".join(self.choices) if self.choices else (
            f"list of {self.item.__name__}" if self.type is tuple and self.item else self.type.__name__)
        default = "" if self.default is None else f", default {_show(self.default) or 'none'}"
        bounds = self.bounds_text()
        bounds = f", {'items ' if self.type is tuple else ''}{bounds}" if bounds else ""
        return f"{kind}{bounds}{default}" + (f": {self.help}" if self.help else "")


@runtime_checkable
class Solver(Protocol):
    """What every registered solver provides (see the module docstring)."""
    name: str
    description: str
    capabilities: Capabilities
    options: tuple[SolverOption, ...]

    def applicable(self, mechanism: Mechanism) -> str | None:
        """None if this solver takes ``mechanism``, else the reason it does not."""

    def solve(self, mechanism: Mechanism, *args: Any, **options: Any) -> BaseParameterResult:
        """The base parameters of ``mechanism``: called as ``solve(mechanism,
        progress=..., **options)`` with every option declared in ``options``, checked
        (``*args: Any, **options: Any`` lets each solver spell its options as typed
        keyword parameters)."""


class NotApplicable(InputError):
    """A solver asked for a mechanism it does not take (exit code 2 in the CLI)."""

    def __init__(self, solver: str, reason: str, file: str | None = None):
        self.solver = solver
        self.why = reason
        super().__init__(f"solver {solver!r} is not applicable: {reason}", file=file)


def require_applicable(solver: Solver, mechanism: Mechanism) -> None:
    """Raise :class:`NotApplicable` (naming the mechanism's file) unless ``solver`` takes it."""
    reason = solver.applicable(mechanism)
    if reason is not None:
        raise NotApplicable(solver.name, reason, file=mechanism.path)


def check_options(solver: Solver, given: Mapping[str, Any],
                  mechanism: Mechanism | None = None) -> dict[str, Any]:
    """Every declared option of ``solver``: the given values (checked, sequences as tuples)
    and the defaults for the rest.

    InputError (naming the solver, the option and the accepted ones) for an unknown
    option, a value of the wrong type, a value outside its choices or its declared range
    (:class:`SolverOption`). A maximum that depends on the mechanism is checked only when
    ``mechanism`` is given (a solver's ``solve`` passes it), so a solver never starts on a
    degenerate setting.
    """
    declared = {o.name: o for o in solver.options}
    out = {name: o.default for name, o in declared.items()}
    for name, value in given.items():
        if name not in declared:
            raise InputError(f"solver {solver.name!r} has no option {name!r}; its options: "
                             f"{', '.join(declared) or '(none)'}")
        out[name] = _checked(solver.name, declared[name], value, mechanism)
    return out


def options_from_text(solver: Solver, pairs: Iterable[str]) -> dict[str, Any]:
    """``["seed=3", "recover=false"]`` (command-line text) -> typed values for
    :func:`check_options`. InputError for a pair without ``=``, an unknown option or a value
    that does not parse as the option's type."""
    declared = {o.name: o for o in solver.options}
    out = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name:
            raise InputError(f"option {pair!r}: expected NAME=VALUE")
        if name not in declared:
            raise InputError(f"solver {solver.name!r} has no option {name!r}; its options: "
                             f"{', '.join(declared) or '(none)'}")
        if name in out:
            raise InputError(f"option {name!r} given twice")
        out[name] = _parse(solver.name, declared[name], text)
    return out


def parameter_count(mechanism: Mechanism) -> int:
    """The number of inertial parameters: a rank's upper bound (``maximum=parameter_count``)."""
    return len(mechanism.parameters)


def last_parameter_index(mechanism: Mechanism) -> int:
    """The largest column index of W (``maximum`` of an option holding column indices)."""
    return len(mechanism.parameters) - 1


def describe_solver(solver: Solver) -> dict[str, Any]:
    """Capabilities and options as plain data (``baseparams plugins --format json``)."""
    caps = solver.capabilities
    return {"capabilities": {k: bool(getattr(caps, k)) for k in Capabilities.__dataclass_fields__},
            "options": [{"name": o.name, "type": o.type.__name__, "default": _json_default(o.default),
                         "help": o.help, **_json_range(o)} for o in solver.options]}


# ----- values -----------------------------------------------------------------------
def _fail(solver: str, option: SolverOption, value: object, want: str) -> NoReturn:
    raise InputError(f"solver {solver!r}: option {option.name!r} must be {want}, got {value!r}")


def _checked(solver: str, option: SolverOption, value: Any, mechanism: Mechanism | None = None) -> Any:
    if value is None:
        if option.default is None:
            return None
        _fail(solver, option, value, _TYPE_WORDS.get(option.type, option.type.__name__))
    kind = option.type
    if kind is tuple:
        if isinstance(value, str):
            value = [v for v in value.replace(",", " ").split() if v]
        if not isinstance(value, (list, tuple)):
            _fail(solver, option, value, "a list")
        item = option.item
        if item is not None:
            for v in value:
                if not _is_a(v, item):
                    _fail(solver, option, value, f"a list of {item.__name__} values")
        value = tuple(value)
        if option.length is not None:
            low, high = option.length
            if not low <= len(value) <= high:
                want = f"{low} item" + ("s" if low != 1 else "") if low == high else f"{low} to {high} items"
                _fail(solver, option, _show(value) or "(empty)", f"a list of {want}")
        if item in (int, float):
            for v in value:
                _in_range(solver, option, v, mechanism, value, " (every item)")
        if option.increasing and any(b <= a for a, b in zip(value, value[1:])):
            _fail(solver, option, _show(value), "strictly increasing")
        if option.unique and len(set(value)) != len(value):
            _fail(solver, option, _show(value), "a list without repeats")
        return value
    if not _is_a(value, kind):
        _fail(solver, option, value, _TYPE_WORDS.get(kind, kind.__name__))
    if option.choices and value not in option.choices:
        _fail(solver, option, value, "one of " + ", ".join(map(str, option.choices)))
    if kind in (int, float):
        _in_range(solver, option, value, mechanism, value)
    return float(value) if kind is float else value


def _in_range(solver: str, option: SolverOption, v: int | float, mechanism: Mechanism | None, shown: object,
              each: str = "") -> None:
    """Refuse a number outside the option's declared range (and any non-finite float)."""
    if isinstance(v, float) and not math.isfinite(v):
        _fail(solver, option, _show(shown), f"a finite number{each}")
    if option.minimum is not None and v < option.minimum:
        _fail(solver, option, _show(shown), f"at least {option.minimum}{each}")
    high = option.maximum
    if callable(high):
        if mechanism is None:
            return
        high = high(mechanism)
        if v > high:
            what = f" ({option.maximum_text} of {mechanism.name})" if option.maximum_text else ""
            _fail(solver, option, _show(shown), f"at most {high}{what}{each}")
    elif high is not None and v > high:
        _fail(solver, option, _show(shown), f"at most {high}{each}")


def _is_a(value: object, kind: type) -> bool:
    if kind is int:             # bool is an int subclass, but True is no sample count
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, kind)


def _parse(solver: str, option: SolverOption, text: str) -> Any:
    kind = option.type
    if text.lower() in ("none", "auto", "automatic") and option.default is None:
        return None
    if kind is bool:
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        _fail(solver, option, text, "true or false")
    if kind is tuple:
        parts = [v for v in text.replace(",", " ").split() if v]
        return tuple(_parse_scalar(solver, option, option.item or str, p) for p in parts)
    return _parse_scalar(solver, option, kind, text)


def _parse_scalar(solver: str, option: SolverOption, kind: type, text: str) -> Any:
    if kind in (int, float):
        pattern = _INT_TEXT if kind is int else _FLOAT_TEXT
        if not pattern.fullmatch(text) or len(text) > 400:
            _fail(solver, option, text[:40], _TYPE_WORDS[kind]
                  + (" (ASCII digits, no underscores)" if kind is int else " (finite, ASCII digits)"))
        try:
            return kind(text)
        except (ValueError, OverflowError):
            _fail(solver, option, text[:40], _TYPE_WORDS[kind])
    return text


def _show(value: object) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return ",".join(map(str, value))
    return str(value)


def _json_range(option: SolverOption) -> dict[str, Any]:
    """minimum/maximum (a number, or the text of a mechanism-dependent bound) and length."""
    out: dict[str, Any] = {}
    if option.minimum is not None:
        out["minimum"] = option.minimum
    if option.maximum is not None:
        out["maximum"] = (option.maximum_text or "mechanism-dependent") if callable(option.maximum) else option.maximum
    if option.length is not None:
        out["length"] = list(option.length)
    return out


def _json_default(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value
