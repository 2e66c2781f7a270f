"""Multipole-transfer rules (Ros et al. 2012): data that joint-type plugins supply.

A rule says which multipole may be moved between the two bodies a joint connects without
changing the Lagrangian, for every value of the joint's coordinates. Points and
directions are written in the joint frame (which both bodies share when the coordinates
are zero); the symbolic solver maps them into each body's frame with the joint's exact
placement.

- ``monopole``: a point mass at ``point``.
- ``dipole``: a first moment along ``direction`` placed at ``point``.
- ``quadrupole``: an inertia-tensor change. ``direction`` given: the axisymmetric tensor
  ``lambda (1 - u u^T)`` about that axis (transferable across a relative rotation about
  u); ``direction`` None: any symmetric tensor (the bodies share their angular velocity).

``condition`` is the number of the seed paper's transfer condition (1-6) the rule
instantiates, for derivation reports.
"""

from dataclasses import dataclass
from fractions import Fraction

Exact = Fraction | int             # an exact number of a rule's point or direction


@dataclass(frozen=True)
class TransferRule:
    multipole: str                   # "monopole" | "dipole" | "quadrupole"
    point: tuple[Exact, ...] = (0, 0, 0)           # in the joint frame
    direction: tuple[Exact, ...] | None = None    # in the joint frame
    condition: int = 0

    def __post_init__(self) -> None:
        if self.multipole not in ("monopole", "dipole", "quadrupole"):
            raise ValueError(f"unknown multipole {self.multipole!r}")
        if self.multipole == "dipole" and self.direction is None:
            raise ValueError("a dipole rule needs a direction")
