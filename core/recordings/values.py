"""A description's numbers: decimals read exactly, expressions such as ``-pi/2`` as floats.

One home for the values a recording description gives (scales, offsets, gains, zero offsets,
windows, rates, gravity, held positions), so that every reader of a description's parts
(:mod:`.recording`, :mod:`.clocks`) reads them alike and names the key of a bad one.
"""

import math
import re
from decimal import Decimal
from fractions import Fraction

from baseparams.errors import InputError
from baseparams.model.expressions import ExpressionError, parse_expression

DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")   # read exactly, never through a float


def _exact(value: object, path: str, key: str) -> Fraction:
    """A decimal (a number, or a string such as "-6.9367") as its exact fraction; an expression
    such as ``pi/4`` to double precision."""
    if isinstance(value, (int, Decimal)):
        return Fraction(str(value))
    if isinstance(value, str) and DECIMAL.fullmatch(value.strip()):
        return Fraction(value.strip())
    return Fraction(_number(value, path, key))


def _number(value: object, path: str, key: str) -> float:
    """A number or an expression such as ``-pi/2``, as a float."""
    try:
        expr = parse_expression(value, (), time=True)
    except ExpressionError as exc:
        raise InputError(str(exc), file=path, key=key) from None
    if expr.free_symbols:
        raise InputError(f"{value!r} is not a number", file=path, key=key)
    result = float(expr)
    if not math.isfinite(result):
        raise InputError(f"{value!r} is not finite", file=path, key=key)
    return result
