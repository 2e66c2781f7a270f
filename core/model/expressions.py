"""Exact arithmetic expressions from text, without eval and never through a float.

Geometry is written as decimal strings and small expressions (``"-(D12 + D13)"``).
Parsing goes through :mod:`ast`, but number literals are read from their source text
into exact rationals, so ``"0.3196"`` is ``799/2500`` and never ``0.31959999...``.
The result is a sympy expression: exact, symbolic when needed, and evaluable in any
arithmetic backend (see :mod:`baseparams.numeric.backends`).
"""

import ast
from fractions import Fraction

import sympy

FUNCTIONS = {"sin": sympy.sin, "cos": sympy.cos, "exp": sympy.exp, "sqrt": sympy.sqrt}


class ExpressionError(ValueError):
    """The text is not an allowed expression; the message says why."""


def parse_decimal(text):
    """A decimal number (int, decimal string, Decimal) as an exact Fraction, or raise."""
    if isinstance(text, bool):
        raise ExpressionError(f"{text!r} is not a number")
    if isinstance(text, int):
        return Fraction(text)
    try:
        value = Fraction(str(text).strip())
    except (ValueError, ZeroDivisionError):
        raise ExpressionError(f"{text!r} is not a decimal number") from None
    return value


def parse_expression(text, names=(), *, time=False):
    """Parse ``text`` into an exact sympy expression.

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
    try:
        tree = ast.parse(source, mode="eval")
    except SyntaxError:
        raise ExpressionError(f"{text!r} is not a valid expression") from None
    allowed = set(names)
    return _convert(tree.body, source, allowed, time)


def _convert(node, source, names, time):
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"{node.value!r} is not a number")
        literal = source[node.col_offset:node.end_col_offset]
        return sympy.Rational(parse_decimal(literal))
    if isinstance(node, ast.Name):
        if node.id in names:
            return sympy.Symbol(node.id)
        if time and node.id == "t":
            return sympy.Symbol("t")
        if time and node.id == "pi":
            return sympy.pi
        known = ", ".join(sorted(names)) or "none"
        raise ExpressionError(f"unknown name {node.id!r} (geometry names: {known})")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        value = _convert(node.operand, source, names, time)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BinOp):
        left = _convert(node.left, source, names, time)
        right = _convert(node.right, source, names, time)
        if isinstance(node.op, ast.Add):
            return left + right
        if isinstance(node.op, ast.Sub):
            return left - right
        if isinstance(node.op, ast.Mult):
            return left * right
        if isinstance(node.op, ast.Div):
            if right == 0:
                raise ExpressionError("division by zero")
            return left / right
        if isinstance(node.op, ast.Pow):
            if not (right.is_Integer or time):
                raise ExpressionError("only integer powers keep geometry exact")
            return left ** right
        raise ExpressionError(f"operator {type(node.op).__name__} is not allowed")
    if isinstance(node, ast.Call) and time and isinstance(node.func, ast.Name):
        if node.func.id in FUNCTIONS and len(node.args) == 1 and not node.keywords:
            return FUNCTIONS[node.func.id](_convert(node.args[0], source, names, time))
        raise ExpressionError(f"function {node.func.id!r} is not allowed (use sin, cos, exp, sqrt)")
    raise ExpressionError(f"{ast.unparse(node)!r} is not allowed in an expression")


def to_fraction(expr):
    """An exact sympy rational as a Fraction; raise if it is not rational."""
    expr = sympy.nsimplify(expr) if not expr.is_Rational else expr
    if not expr.is_Rational:
        raise ExpressionError(f"{expr} is not a rational number")
    return Fraction(int(expr.p), int(expr.q))


def exact_text(value):
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
