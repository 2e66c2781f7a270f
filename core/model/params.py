"""Inertial parameter names and order: ten per moving body, as in the seed paper.

For body ``i``: ``m{i} mx{i} my{i} mz{i} Ixx{i} Ixy{i} Ixz{i} Iyy{i} Iyz{i} Izz{i}``,
about the body origin, in body axes; ``Ixy`` is the inertia-tensor entry ``-∫xy dm``.
A mechanism whose bodies are named for the user (a URDF's links) names them by the body's
name instead of its label: ``m_forearm_link ... Izz_forearm_link`` (since issue 45). Names
are made by :func:`parameter_name` and read back by :func:`split_name`, in one place.
"""

from collections.abc import Iterable, Sequence
from fractions import Fraction
from typing import TypeVar, Union

Number = TypeVar("Number", Fraction, float)   # exact (the builder) or float (simulate)
BodyKey = Union[int, str]                     # what names a body in parameter names: its label or its name

PARAMETER_KINDS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")


def parameter_name(kind: str, body: BodyKey) -> str:
    """The one rendering of a parameter's name: ('Iyy', 12) -> 'Iyy12' (a numbered body),
    ('Iyy', 'forearm') -> 'Iyy_forearm' (a named body: the underscore keeps 'm_x1' apart from
    'mx1')."""
    return f"{kind}{body}" if isinstance(body, int) else f"{kind}_{body}"


def body_parameter_names(body: BodyKey) -> list[str]:
    return [parameter_name(kind, body) for kind in PARAMETER_KINDS]


def parameter_names(bodies: Iterable[BodyKey]) -> list[str]:
    """The full parameter vector's names, body after body, in body order."""
    names: list[str] = []
    for body in bodies:
        names.extend(body_parameter_names(body))
    return names


def split_name(name: str) -> tuple[str, BodyKey]:
    """'Iyy12' -> ('Iyy', 12); 'Iyy_forearm' -> ('Iyy', 'forearm'). ValueError otherwise."""
    for kind in sorted(PARAMETER_KINDS, key=len, reverse=True):
        if not name.startswith(kind):
            continue
        rest = name[len(kind):]
        if rest.isdigit() and rest.isascii():
            return kind, int(rest)
        if rest.startswith("_") and len(rest) > 1:
            return kind, rest[1:]
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
