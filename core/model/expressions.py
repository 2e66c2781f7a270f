"""Exact arithmetic expressions from text, without eval and never through a float.

Geometry is written as decimal strings and small expressions (``"-(D12 + D13)"``).
Parsing goes through :mod:`ast`, but number literals are read from their source text
into exact rationals, so ``"0.3196"`` is ``799/2500`` and never ``0.31959999...``.
The result is a sympy expression: exact, symbolic when needed, and evaluable in any
arithmetic backend (see :mod:`baseparams.numeric.backends`).

Resource limits. Exact arithmetic has no overflow, so a hostile or mistyped file could
ask for numbers with billions of digits (``"1e999999999"``, ``"10**100000000"``,
``"2**2**2**2**2**2"``) and hang the program. Every limit below is checked *before* the
expensive step (the literal's digits and exponent are counted from its text, a power's
size is estimated from its operands), and a refusal is an :class:`ExpressionError` that
states the limit. The limits are generous for mechanism geometry:

- ``MAX_SIGNIFICANT_DIGITS`` = 100: measured geometry has at most ~10 digits; 100 lets a
  value be pasted from a multi-precision computation.
- ``MAX_DECIMAL_EXPONENT`` = 300: a non-zero number's magnitude lies in [1e-300, 1e300]
  (literals and final values). Double precision ends near 1e308, so anything outside
  cannot be evaluated by the ``dp`` solver anyway.
- ``MAX_EXPONENT`` = 64: a numeric exponent is an integer (or, in trajectories, a fraction
  p/q with q <= 64) of magnitude at most 64; no mechanism needs more than squares.
- ``MAX_TEXT_LENGTH`` = 1000 characters, ``MAX_NODES`` = 200 syntax-tree nodes (numbers,
  names, operations, calls) and ``MAX_DEPTH`` = 100 nesting levels: the longest built-in
  expression has ~60 characters and 13 nodes.
- ``MAX_FUNCTION_NESTING`` = 8 (``sin(cos(...))``): trajectories are differentiated twice,
  and the second derivative of 20 nested sines already takes half a second to build.
- ``MAX_BITS`` = 20000 bits (~6000 digits) for an exact numeric intermediate, and
  ``MAX_DEGREE`` = 256 for the polynomial degree in geometry names and ``t``: they bound
  what nested powers and products of names cost once the geometry values are substituted.

The limits are module constants, read at each call: a program that embeds baseparams and
truly needs more may raise them (``expressions.MAX_SIGNIFICANT_DIGITS = 200``) before it
loads a mechanism. The command line does not offer to raise them: no mechanism needs it.
"""

import ast
import math
import operator
import re
from collections.abc import Iterable
from decimal import Decimal
from fractions import Fraction

import sympy

FUNCTIONS = {"sin": sympy.sin, "cos": sympy.cos, "exp": sympy.exp, "sqrt": sympy.sqrt}

MAX_SIGNIFICANT_DIGITS = 100
MAX_DECIMAL_EXPONENT = 300
MAX_EXPONENT = 64
MAX_TEXT_LENGTH = 1000
MAX_NODES = 200
MAX_DEPTH = 100
MAX_FUNCTION_NESTING = 8
MAX_BITS = 20000
MAX_DEGREE = 256

_DIGITS = r"[0-9]+(?:_[0-9]+)*"
# A decimal literal as Python and Fraction() write it, or an exact ratio "p/q" (what
# exact_text writes). ASCII digits only: \d would accept other scripts' digits.
_NUMBER_RE = re.compile(
    rf"(?P<sign>[-+]?)(?:(?P<num>{_DIGITS})/(?P<den>{_DIGITS})"
    rf"|(?=[0-9]|\.[0-9])(?P<int>(?:{_DIGITS})?)(?:\.(?P<frac>(?:{_DIGITS})?))?"
    rf"(?:[eE](?P<exp>[-+]?{_DIGITS}))?)")
_NON_FINITE = {"nan", "inf", "infinity", "snan", "-nan", "+nan", "-inf", "+inf", "-infinity", "+infinity"}
NON_FINITE = frozenset(_NON_FINITE)
"""Words (lower case) that name a non-finite number: never a value, nor a name."""
_OPERATORS = {ast.FloorDiv: "//", ast.Mod: "%", ast.MatMult: "@", ast.LShift: "<<", ast.RShift: ">>",
              ast.BitOr: "|", ast.BitXor: "^", ast.BitAnd: "&"}
_T = sympy.Symbol("t")
_LOG2_10 = math.log2(10)


class ExpressionError(ValueError):
    """The text is not an allowed expression; the message says why."""


def parse_decimal(text: object) -> Fraction:
    """A decimal number (int, decimal string, "p/q", Decimal) as an exact Fraction, or raise.

    The digit count and the magnitude are checked from the text before any big number is
    built (see the module's limits).
    """
    if isinstance(text, bool):
        raise ExpressionError(f"{text!r} is not a number")
    if isinstance(text, int):
        return _checked_magnitude(Fraction(_checked_int(text)), str(text) if text.bit_length() < 4000 else None)
    if isinstance(text, Fraction):
        return _checked_magnitude(text, None)
    if isinstance(text, Decimal):
        if not text.is_finite():
            raise ExpressionError(f"{_non_finite_word(str(text))} is not a finite number")
        text = str(text)
    elif isinstance(text, float):
        if not math.isfinite(text):
            raise ExpressionError(f"{_non_finite_word(str(text))} is not a finite number")
        text = repr(text)
    elif not isinstance(text, str):
        raise ExpressionError(f"expected a number or a decimal string, got a {_type_word(text)}")
    source = text.strip()
    if source.lower() in _NON_FINITE:
        raise ExpressionError(f"{_non_finite_word(source)} is not a finite number")
    match = _NUMBER_RE.fullmatch(source)
    if match is None:
        raise ExpressionError(f"{_shown(text)} is not a decimal number")
    return _number_from_match(match, source)


def parse_expression(text: object, names: Iterable[str] = (), *, time: bool = False) -> sympy.Expr:
    """Parse ``text`` into an exact sympy expression, within the module's resource limits.

    ``names``: allowed symbol names (geometry parameters). With ``time=True`` the variable
    ``t``, the constant ``pi`` and the functions sin, cos, exp, sqrt are allowed too.
    TOML numbers (int or Decimal) are accepted and kept exact.
    """
    if isinstance(text, bool):
        raise ExpressionError(f"{text!r} is not a number or expression")
    if not isinstance(text, str):
        return sympy.Rational(parse_decimal(text))
    source = text.strip()
    if not source:
        raise ExpressionError("empty expression")
    if _NUMBER_RE.fullmatch(source) or source.lower() in _NON_FINITE:
        return sympy.Rational(parse_decimal(source))
    if len(source) > MAX_TEXT_LENGTH:
        raise ExpressionError(f"an expression of {len(source)} characters: at most {MAX_TEXT_LENGTH} "
                              f"are accepted")
    try:
        tree = ast.parse(source, mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError):
        raise ExpressionError(f"{_shown(source)} is not a valid expression") from None
    _check_tree_size(tree.body)
    value, _ = _Converter(source, set(names), time).convert(tree.body)
    if value.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise ExpressionError("division by zero")
    if value.has(sympy.I):
        raise ExpressionError(f"{_shown(source)} is not a real number")
    if value.is_Rational:
        _checked_magnitude(Fraction(int(value.p), int(value.q)), None)
    return value


def to_fraction(expr: sympy.Expr) -> Fraction:
    """An exact sympy rational as a Fraction; raise if it is not a finite rational in range."""
    if expr.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise ExpressionError("division by zero (after substituting the geometry values)")
    expr = sympy.nsimplify(expr) if not expr.is_Rational else expr
    if not expr.is_Rational:
        raise ExpressionError(f"{_shown(str(expr))} is not a rational number")
    return _checked_magnitude(Fraction(int(expr.p), int(expr.q)), None)


def exact_text(value: Fraction | int) -> str:
    """An exact rational as a decimal string when it has one ("0.3196"), else "p/q".

    The inverse of :func:`parse_decimal`: geometry written back (JSON, reports) stays exact.
    """
    value = Fraction(value)
    d, twos, fives = value.denominator, 0, 0
    while d % 2 == 0:
        d, twos = d // 2, twos + 1
    while d % 5 == 0:
        d, fives = d // 5, fives + 1
    if d != 1:
        return f"{value.numerator}/{value.denominator}"
    places = max(twos, fives)
    if places == 0:
        return str(value.numerator)
    scaled = abs(value.numerator) * 10 ** places // value.denominator
    digits = str(scaled).rjust(places + 1, "0")
    return ("-" if value < 0 else "") + digits[:-places] + "." + digits[-places:]


# ----- numbers ---------------------------------------------------------------

def _number_from_match(match: re.Match, source: str) -> Fraction:
    """The exact value of a matched literal, after checking its digits and magnitude."""
    sign = -1 if match["sign"] == "-" else 1
    if match["num"] is not None:
        num = _checked_digits(match["num"].replace("_", ""), source)
        den = _checked_digits(match["den"].replace("_", ""), source)
        if int(den) == 0:
            raise ExpressionError("division by zero")
        return _checked_magnitude(Fraction(sign * int(num), int(den)), source)
    int_part = (match["int"] or "").replace("_", "")
    frac_part = (match["frac"] or "").replace("_", "")
    digits = _checked_digits(int_part + frac_part, source)
    if not digits.strip("0"):
        return Fraction(0)
    exp_text = (match["exp"] or "0").replace("_", "")
    if len(exp_text.lstrip("+-").lstrip("0")) > 9:
        raise _out_of_range(source, None)
    exponent = int(exp_text)
    lead = int_part.lstrip("0")
    adjusted = exponent + len(lead) - 1 if lead else exponent - (len(frac_part) - len(frac_part.lstrip("0"))) - 1
    if abs(adjusted) > MAX_DECIMAL_EXPONENT:
        raise _out_of_range(source, adjusted)
    scale = exponent - len(frac_part)
    coefficient = sign * int(digits)
    return Fraction(coefficient * 10 ** scale) if scale >= 0 else Fraction(coefficient, 10 ** -scale)


def _checked_digits(digits: str, source: str) -> str:
    """``digits`` if its significant digits (from the first non-zero one) are within the limit."""
    significant = len(digits.lstrip("0"))
    if significant > MAX_SIGNIFICANT_DIGITS:
        raise ExpressionError(f"a number with {significant} significant digits: at most "
                              f"{MAX_SIGNIFICANT_DIGITS} are accepted")
    if len(source) > MAX_TEXT_LENGTH:
        raise ExpressionError(f"a number with {len(digits)} digits: at most {MAX_TEXT_LENGTH} "
                              f"characters are accepted")
    return digits


def _checked_int(value: int) -> int:
    if value.bit_length() > (MAX_DECIMAL_EXPONENT + 1) * _LOG2_10 + 1:
        raise _out_of_range(None, int(value.bit_length() / _LOG2_10))
    return value


def _checked_magnitude(value: Fraction, source: str | None) -> Fraction:
    """``value`` if it is 0 or its magnitude lies in [10^-MAX_DECIMAL_EXPONENT, 10^MAX_DECIMAL_EXPONENT]."""
    if value == 0:
        return value
    num, den = abs(value.numerator), value.denominator
    estimate = (num.bit_length() - den.bit_length()) / _LOG2_10       # log10 |value|, +-1
    if abs(estimate) > MAX_DECIMAL_EXPONENT + 2:
        raise _out_of_range(source, round(estimate))
    limit = 10 ** MAX_DECIMAL_EXPONENT
    if num >= limit * 10 * den or num * limit < den:
        raise _out_of_range(source, round(estimate))
    return value


def _out_of_range(source: str | None, adjusted: int | None) -> ExpressionError:
    what = _shown(source) if source is not None else "the value"
    about = f" (about 1e{adjusted})" if adjusted is not None else ""
    return ExpressionError(f"{what} is out of range{about}: non-zero numbers must lie between "
                           f"1e-{MAX_DECIMAL_EXPONENT} and 1e{MAX_DECIMAL_EXPONENT} in magnitude")


def _non_finite_word(text: str) -> str:
    low = text.strip().lower().lstrip("+")
    if "nan" in low:
        return "nan"
    return "-inf" if low.startswith("-") else "inf"


def _type_word(value: object) -> str:
    return {list: "list", dict: "table", tuple: "list", type(None): "missing value"}.get(
        type(value), type(value).__name__)


def _shown(text: str, limit: int = 40) -> str:
    """``text`` quoted for a message; a long text is cut and its length said (never echoed whole)."""
    digits = sum(c.isdigit() for c in text)
    if len(text) <= limit:
        return repr(text)
    if digits > len(text) // 2:
        return f"a number with {digits} digits ({text[:12]!r}...)"
    return f"{text[:limit - 10]!r}... ({len(text)} characters)"


# ----- expressions -----------------------------------------------------------

def _check_tree_size(root: ast.AST) -> None:
    """Refuse trees with too many nodes, too deep, or too many nested functions, before any
    evaluation (operator and context nodes are not counted)."""
    count = sum(isinstance(node, ast.expr) for node in ast.walk(root))
    if count > MAX_NODES:
        raise ExpressionError(f"an expression with {count} terms and operators: at most {MAX_NODES} "
                              f"are accepted")
    stack = [(root, 1, 0)]
    while stack:
        node, depth, calls = stack.pop()
        if depth > MAX_DEPTH:
            raise ExpressionError(f"an expression nested more than {MAX_DEPTH} levels deep: at most "
                                  f"{MAX_DEPTH} are accepted")
        calls += isinstance(node, ast.Call)
        if calls > MAX_FUNCTION_NESTING:
            raise ExpressionError(f"functions nested more than {MAX_FUNCTION_NESTING} deep: at most "
                                  f"{MAX_FUNCTION_NESTING} are accepted (derivatives grow with the nesting)")
        stack.extend((child, depth + 1, calls) for child in ast.iter_child_nodes(node)
                     if isinstance(child, ast.expr))


def _bits(value: sympy.Rational) -> int:
    return max(abs(int(value.p)).bit_length(), int(value.q).bit_length())


def _plain_angle(arg: sympy.Expr) -> bool:
    """Is ``arg`` a sum or product of rationals and t (at least one t) that sympy's sin and cos
    leave as they are? Such an angle has no pi, no imaginary unit and no function to simplify,
    is not identically zero, and no minus sign comes out of it (sympy would move it in front):
    ``sin(arg)`` is then ``sin(arg, evaluate=False)``, the same expression without the
    assumption queries of sympy's evaluation (0.4 ms a call: 0.06 CPU s of the 144 angles of
    TIAGo's default trajectory; tests/test_expression_programs.py compares the two)."""
    found = False
    stack = [arg]
    while stack:
        node = stack.pop()
        if node is _T:
            found = True
        elif node.is_Add or node.is_Mul:
            stack.extend(node.args)
        elif not node.is_Rational:
            return False
    return found and not arg.could_extract_minus_sign()


class _Converter:
    """AST -> (sympy expression, degree bound). The degree bound is the polynomial degree in
    the names (and t): what substituting geometry values can cost later."""

    def __init__(self, source: str, names: set[str], time: bool) -> None:
        self.source, self.names, self.time = source, names, time

    def convert(self, node: ast.AST) -> tuple[sympy.Expr, int]:
        if isinstance(node, ast.Constant):
            return self.constant(node), 0
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            value, degree = self.convert(node.operand)
            return (-value if isinstance(node.op, ast.USub) else value), degree
        if isinstance(node, ast.BinOp):
            return self.binop(node)
        if isinstance(node, ast.Call) and self.time and isinstance(node.func, ast.Name):
            return self.call(node)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS:
            raise ExpressionError(f"function {node.func.id!r} is only allowed in trajectory expressions; "
                                  f"geometry stays rational")
        raise ExpressionError(f"{_shown(ast.unparse(node))} is not allowed in an expression")

    def constant(self, node: ast.Constant) -> sympy.Expr:
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            shown = _shown(node.value) if isinstance(node.value, str) else repr(node.value)
            raise ExpressionError(f"{shown} is not a number")
        literal = ast.get_source_segment(self.source, node) or repr(node.value)
        return sympy.Rational(parse_decimal(literal))

    def name(self, node: ast.Name) -> tuple[sympy.Expr, int]:
        if node.id in self.names:
            return sympy.Symbol(node.id), 1
        if self.time and node.id == "t":
            return _T, 1
        if self.time and node.id == "pi":
            return sympy.pi, 0
        if node.id.lower() in _NON_FINITE:
            raise ExpressionError(f"{_non_finite_word(node.id)} is not a finite number")
        known = ", ".join(sorted(self.names)) or "none"
        raise ExpressionError(f"unknown name {_shown(node.id)} (geometry names: {known})")

    def call(self, node: ast.Call) -> tuple[sympy.Expr, int]:
        assert isinstance(node.func, ast.Name)          # convert() sends only calls of a name
        fname = node.func.id
        if fname not in FUNCTIONS or len(node.args) != 1 or node.keywords:
            raise ExpressionError(f"function {_shown(fname)} with these arguments is not allowed "
                                  f"(use sin, cos, exp, sqrt of one argument)")
        arg, degree = self.convert(node.args[0])
        if fname == "sqrt" and arg.is_Rational and arg < 0:
            raise ExpressionError("the square root of a negative number is not real")
        if fname in ("sin", "cos") and _plain_angle(arg):
            return FUNCTIONS[fname](arg, evaluate=False), max(1, degree)
        return FUNCTIONS[fname](arg), max(1, degree)

    def binop(self, node: ast.BinOp) -> tuple[sympy.Expr, int]:
        op = type(node.op)
        if op not in (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow):
            raise ExpressionError(f"the operator {_OPERATORS.get(op, op.__name__)} is not allowed "
                                  f"(use + - * / **)")
        left, ldeg = self.convert(node.left)
        right, rdeg = self.convert(node.right)
        if op is ast.Pow:
            return self.power(left, ldeg, right, rdeg)
        if op is ast.Div and right == 0:
            raise ExpressionError("division by zero")
        value = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
                 ast.Div: operator.truediv}[op](left, right)
        degree = max(ldeg, rdeg) if op in (ast.Add, ast.Sub) else ldeg + rdeg
        return self.checked(value, degree)

    def power(self, base: sympy.Expr, bdeg: int, exponent: sympy.Expr, edeg: int) -> tuple[sympy.Expr, int]:
        if exponent.free_symbols:
            if not (self.time and _T in exponent.free_symbols):
                raise ExpressionError("an exponent must be a number" + (" or depend on t" if self.time else ""))
            return base ** exponent, bdeg + edeg
        if not exponent.is_Rational:
            raise ExpressionError("a constant exponent must be a rational number")
        if not (exponent.is_Integer or self.time):
            raise ExpressionError("only integer powers keep geometry exact")
        if abs(exponent) > MAX_EXPONENT or exponent.q > MAX_EXPONENT:
            raise ExpressionError(f"the exponent {exponent} is too large: at most {MAX_EXPONENT} in "
                                  f"magnitude" + (f", with a denominator at most {MAX_EXPONENT}" if self.time else ""))
        times = math.ceil(abs(exponent))
        if base.is_Rational:
            if base == 0 and exponent < 0:
                raise ExpressionError("division by zero")
            if base < 0 and not exponent.is_Integer:
                raise ExpressionError("a negative number to a fractional power is not real")
            if _bits(base) * times > MAX_BITS:
                raise ExpressionError(f"a power with about {int(_bits(base) * times / _LOG2_10)} digits: "
                                      f"exact intermediate values are limited to about "
                                      f"{int(MAX_BITS / _LOG2_10)} digits")
        return self.checked(base ** exponent, bdeg * times)

    @staticmethod
    def checked(value: sympy.Expr, degree: int) -> tuple[sympy.Expr, int]:
        if degree > MAX_DEGREE:
            raise ExpressionError(f"an expression of degree {degree} in its names: at most {MAX_DEGREE} "
                                  f"is accepted (nested powers or long products)")
        if value.is_Rational and _bits(value) > MAX_BITS:
            raise ExpressionError(f"an intermediate value with about {int(_bits(value) / _LOG2_10)} digits: "
                                  f"exact intermediate values are limited to about {int(MAX_BITS / _LOG2_10)} digits")
        return value, degree
