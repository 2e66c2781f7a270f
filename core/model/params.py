"""Inertial parameter names and order: ten per moving body, as in the seed paper.

For body ``i``: ``m{i} mx{i} my{i} mz{i} Ixx{i} Ixy{i} Ixz{i} Iyy{i} Iyz{i} Izz{i}``,
about the body origin, in body axes; ``Ixy`` is the inertia-tensor entry ``-∫xy dm``.
"""

from collections.abc import Iterable, Sequence
from fractions import Fraction
from typing import TypeVar

Number = TypeVar("Number", Fraction, float)   # exact (the builder) or float (simulate)

PARAMETER_KINDS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")


def body_parameter_names(label: int) -> list[str]:
    return [f"{kind}{label}" for kind in PARAMETER_KINDS]


def parameter_names(body_labels: Iterable[int]) -> list[str]:
    """The full parameter vector's names, body after body, in body order."""
    names: list[str] = []
    for label in body_labels:
        names.extend(body_parameter_names(label))
    return names


def split_name(name: str) -> tuple[str, int]:
    """'Iyy12' -> ('Iyy', 12)."""
    for kind in sorted(PARAMETER_KINDS, key=len, reverse=True):
        if name.startswith(kind) and name[len(kind):].isdigit():
            return kind, int(name[len(kind):])
    raise ValueError(f"not an inertial parameter name: {name!r}")


def from_mass_properties(mass: Number, com: Sequence[Number], inertia_com: Sequence[Number]) -> list[Number]:
    """Ten parameters about the body origin from mass, centre of mass and the tensor at the COM.

    Exact for exact inputs: ``I_O = I_G + m (|c|^2 1 - c c^T)`` in tensor-entry form.
    ``inertia_com`` is (Ixx, Ixy, Ixz, Iyy, Iyz, Izz) as tensor entries.
    """
    x, y, z = com
    ixx, ixy, ixz, iyy, iyz, izz = inertia_com
    m = mass
    return [
        m, m * x, m * y, m * z,
        ixx + m * (y * y + z * z),
        ixy - m * x * y,
        ixz - m * x * z,
        iyy + m * (x * x + z * z),
        iyz - m * y * z,
        izz + m * (x * x + y * y),
    ]
