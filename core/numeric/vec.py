"""3-vectors and 3x3 matrices as plain lists, generic over the number type.

Plain lists (not numpy arrays) let the same code run on floats, arrays of samples,
flint balls, rationals and sympy expressions: the entries are typed ``Any``.
"""

from collections.abc import Sequence
from typing import Any

Vec = Sequence[Any]                 # a 3-vector
Mat = Sequence[Sequence[Any]]       # a 3x3 matrix, as rows


def add(a: Vec, b: Vec) -> list[Any]:
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a: Vec, b: Vec) -> list[Any]:
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def scale(a: Vec, s: Any) -> list[Any]:
    return [a[0] * s, a[1] * s, a[2] * s]


def dot(a: Vec, b: Vec) -> Any:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec, b: Vec) -> list[Any]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def matvec(m: Mat, v: Vec) -> list[Any]:
    return [m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]]


def tmatvec(m: Mat, v: Vec) -> list[Any]:
    """m^T v."""
    return [m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
            m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
            m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2]]


def matmul(a: Mat, b: Mat) -> list[list[Any]]:
    return [[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)]
            for i in range(3)]


def matmul_t(a: Mat, b: Mat) -> list[list[Any]]:
    """a b^T."""
    return [[a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2] for j in range(3)]
            for i in range(3)]


def column(m: Mat, k: int) -> list[Any]:
    return [m[0][k], m[1][k], m[2][k]]
