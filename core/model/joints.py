"""Joint types: coordinates, motion, loop-closure equations, and multipole-transfer rules.

A joint type moves the child's joint frame relative to the parent's joint frame by a
sequence of *elementary motions*, each a rotation about or a translation along one axis
(x, y or z) of the frame as moved so far. Describing joints this way lets the kinematics
engine compute positions, Jacobians and acceleration terms for every joint type with one
piece of code, in every arithmetic backend; a plugin only states what its joint does.

Loop-closure equations are dot products between the two joint frames, evaluated in
world axes: ``("gap", u)`` is ``(P_child - P_parent) . u_parent`` and ``("dot", u, w)``
is ``u_parent . w_child``, for axis names u, w in "x", "y", "z". When all coordinates are
zero the two frames coincide, so every equation is zero there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

from baseparams.numeric import vec
from baseparams.model.multipoles import TransferRule

if TYPE_CHECKING:
    from baseparams.numeric.backends import Backend

AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class JointType:
    name: str
    description: str
    motions: tuple[tuple[str, str], ...] = ()   # (("R" | "P", "x" | "y" | "z"), ...)
    suffixes: tuple[str, ...] = ()  # coordinate name suffixes, one per motion
    closure: tuple[tuple[str, ...], ...] = ()   # (("gap", u) | ("dot", u, w), ...)
    uses_axis: bool = True         # whether the frames' axes matter to this joint

    def __post_init__(self) -> None:
        if len(self.suffixes) != len(self.motions):
            raise ValueError(f"joint type {self.name}: one suffix per motion")
        for kind, axis in self.motions:
            if kind not in ("R", "P") or axis not in AXES:
                raise ValueError(f"joint type {self.name}: bad motion {(kind, axis)!r}")
        for eq in self.closure:
            if eq[0] == "gap" and len(eq) == 2 and eq[1] in AXES:
                continue
            if eq[0] == "dot" and len(eq) == 3 and eq[1] in AXES and eq[2] in AXES:
                continue
            raise ValueError(f"joint type {self.name}: bad closure equation {eq!r}")

    @property
    def dof(self) -> int:
        return len(self.motions)

    @property
    def coordinate_kinds(self) -> tuple[str, ...]:
        return tuple("angle" if kind == "R" else "length" for kind, _ in self.motions)

    def transform(self, q: Sequence[Any], backend: Backend) -> tuple[list[list[Any]], list[Any]]:
        """Child joint frame in the parent joint frame: (R, p), R as 3 rows, p as 3 numbers."""
        one, zero = backend.rational(Fraction(1)), backend.rational(Fraction(0))
        rot = [[one, zero, zero], [zero, one, zero], [zero, zero, one]]
        pos = [zero, zero, zero]
        for (kind, axis), value in zip(self.motions, q):
            k = AXES[axis]
            column = [rot[0][k], rot[1][k], rot[2][k]]
            if kind == "P":
                pos = [pos[i] + column[i] * value for i in range(3)]
            else:
                c, s = backend.cos_sin(value)
                rot = vec.matmul(rot, elementary_rotation(k, c, s, one, zero))
        return rot, pos


def elementary_rotation(axis: int, c: Any, s: Any, one: Any, zero: Any) -> list[list[Any]]:
    """Rotation matrix about coordinate axis ``axis`` with cos c and sin s (rows)."""
    if axis == 0:
        return [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    if axis == 1:
        return [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    return [[c, -s, zero], [s, c, zero], [zero, zero, one]]


__all__ = ["JointType", "TransferRule", "AXES", "elementary_rotation"]
