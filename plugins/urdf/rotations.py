"""URDF roll-pitch-yaw angles as exact rational rotations, and back.

The mechanism model holds geometry as exact rationals (frames are rational vectors), so
a rotation must have rational entries to be held exactly. URDF gives decimal angles:

- an angle within 1e-9 of a multiple of pi/2 is taken as that multiple: cos and sin are
  0 or +-1 and the rotation is an exact signed permutation (reported as a note when the
  text was not exactly 0);
- any other angle theta is replaced by the rational point of the unit circle nearest to
  it with a small denominator: ``t = tan(theta/2)`` is computed from the decimal text at
  40 digits and rationalised to within ``TAN_HALF_TOLERANCE``, then ``cos = (1-t^2)/(1+t^2)``,
  ``sin = 2t/(1+t^2)``. The rotation is then exactly orthogonal and rational, within
  2e-17 rad of the written angle (below float64 resolution), and every solver, exact
  included, applies; the reader reports it as approximate.

``R = Rz(yaw) Ry(pitch) Rx(roll)`` (fixed axes x, then y, then z: the URDF convention).
"""

from decimal import Decimal
from collections.abc import Sequence
from fractions import Fraction
from typing import Any

import mpmath

SNAP_TOLERANCE = 1e-9          # |theta - k pi/2| below this: exactly k pi/2
TAN_HALF_TOLERANCE = Fraction(1, 10 ** 17)
DIGITS = 40

Rotation = tuple[tuple[Fraction, ...], ...]      # 3 x 3, rows
"""Rows of a 3x3 rotation matrix with exact rational entries."""
Matrix = Sequence[Sequence[Fraction | int]]       # 3 x 3 exact, rows (ints where an entry is 0 or 1)

_QUARTER = ((Fraction(1), Fraction(0)), (Fraction(0), Fraction(1)),
            (Fraction(-1), Fraction(0)), (Fraction(0), Fraction(-1)))


def cos_sin(angle: Decimal) -> tuple[Fraction, Fraction, str]:
    """Exact rational (cos, sin) for a decimal angle, and how it was taken: ``"exact"``,
    ``"snapped"`` (a multiple of pi/2 within 1e-9) or ``"rational"`` (tan(theta/2) rationalised)."""
    with mpmath.workdps(DIGITS):
        theta = mpmath.mpf(str(angle))
        k = int(mpmath.nint(theta / (mpmath.pi / 2)))
        if abs(theta - k * mpmath.pi / 2) <= SNAP_TOLERANCE:
            c, s = _QUARTER[k % 4]
            return c, s, "exact" if angle == 0 else "snapped"
        t = _rationalise(mpmath.tan(theta / 2))
    t2 = t * t
    return (1 - t2) / (1 + t2), 2 * t / (1 + t2), "rational"


def _rationalise(x: Any) -> Fraction:
    """The fraction of smallest denominator (by continued fractions) within the tolerance of x."""
    exact = Fraction(mpmath.nstr(x, DIGITS, min_fixed=-mpmath.inf, max_fixed=mpmath.inf))
    bound = 1
    while True:
        bound *= 1000
        candidate = exact.limit_denominator(bound)
        if abs(candidate - exact) < TAN_HALF_TOLERANCE:
            return candidate


def rpy_matrix(roll: Decimal, pitch: Decimal, yaw: Decimal) -> tuple[Rotation, list[str]]:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` exactly, and per angle how it was taken."""
    (cr, sr, h1), (cp, sp, h2), (cy, sy, h3) = (cos_sin(a) for a in (roll, pitch, yaw))
    how = [h1, h2, h3]
    rx = ((1, 0, 0), (0, cr, -sr), (0, sr, cr))
    ry = ((cp, 0, sp), (0, 1, 0), (-sp, 0, cp))
    rz = ((cy, -sy, 0), (sy, cy, 0), (0, 0, 1))
    return matmul(rz, matmul(ry, rx)), how


def matmul(a: Matrix, b: Matrix) -> Rotation:
    # zero terms skipped (most entries of joint and link rotations are 0): exact either way
    return tuple(tuple(Fraction(sum(a[i][k] * b[k][j] for k in range(3) if a[i][k] and b[k][j])) for j in range(3))
                 for i in range(3))


def transpose(a: Rotation) -> Rotation:
    return tuple(tuple(a[j][i] for j in range(3)) for i in range(3))


def matvec(a: Matrix, v: Sequence[Fraction]) -> tuple[Fraction, ...]:
    return tuple(sum((a[i][k] * v[k] for k in range(3)), Fraction(0)) for i in range(3))


IDENTITY: Rotation = tuple(tuple(Fraction(int(i == j)) for j in range(3)) for i in range(3))


# ----- back: a rotation (any exact or numeric entries) to rpy text ------------------------------
def matrix_rpy(rows: Sequence[Sequence[Any]]) -> tuple[Any, Any, Any]:
    """(roll, pitch, yaw) as mpmath numbers at 40 digits for a rotation matrix (rows of
    numbers mpmath accepts); exact multiples of pi/2 for a signed permutation."""
    with mpmath.workdps(DIGITS):
        r = [[mpmath.mpf(v) if not isinstance(v, Fraction) else mpmath.mpf(v.numerator) / v.denominator
              for v in row] for row in rows]
        s = -r[2][0]
        if abs(abs(s) - 1) < mpmath.mpf(10) ** (-30):
            # gimbal lock: pitch +-pi/2, only yaw - roll (or yaw + roll) is defined; take roll 0
            pitch = mpmath.pi / 2 if s > 0 else -mpmath.pi / 2
            yaw = mpmath.atan2(-r[0][1], r[1][1])
            return mpmath.mpf(0), pitch, yaw
        pitch = mpmath.asin(max(min(s, 1), -1))
        roll = mpmath.atan2(r[2][1], r[2][2])
        yaw = mpmath.atan2(r[1][0], r[0][0])
        return roll, pitch, yaw


# ----- keeping exact numbers small -----------------------------------------------------------------
LONG = 40          # digits in a numerator or denominator above which a value is rounded
ROUNDED = 30       # significant digits it is rounded to


def is_long(value: Fraction) -> bool:
    return max(len(str(abs(value.numerator))), len(str(value.denominator))) > LONG


def rounded(value: Fraction) -> Fraction:
    """``value`` to 30 significant digits (a decimal) when its exact form is long, else itself.
    Used for inertial parameters turned by an approximate (rational) rotation: they are then
    approximate anyway, and a mechanism file holds at most 100 digits per number."""
    if not is_long(value) or value == 0:
        return value
    with mpmath.workdps(ROUNDED + 10):
        x = mpmath.mpf(value.numerator) / value.denominator
        return Fraction(mpmath.nstr(x, ROUNDED, min_fixed=-mpmath.inf, max_fixed=mpmath.inf))


def bounded_rotation(rot: Rotation) -> Rotation:
    """A product of rational rotations whose entries grew long, taken again through its rpy
    angles (each within 2e-17 rad): exactly orthogonal with short entries."""
    if not any(is_long(v) for row in rot for v in row):
        return rot
    with mpmath.workdps(DIGITS):
        angles = [Decimal(mpmath.nstr(a, 30, min_fixed=-mpmath.inf, max_fixed=mpmath.inf)) for a in matrix_rpy(rot)]
    return rpy_matrix(*angles)[0]
