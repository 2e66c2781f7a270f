"""Built-in joint types R, P, S, U, Fixed and Free, registered like any third party's.

Transfer rules follow from Delta L = 0 (seed paper, section 3.3): a multipole may cross a
joint when it is fixed in both bodies and the bodies' velocities (monopole, dipole) or
angular velocities (quadrupole) agree where and along what it acts. Each rule is checked
by the test suite as a null vector of the observation matrix.
"""

from baseparams.hookspecs import hookimpl
from baseparams.model.joints import JointType
from baseparams.model.multipoles import TransferRule

POINT = ("gap", "x"), ("gap", "y"), ("gap", "z")

REVOLUTE = JointType(
    name="R", description="revolute: rotation about the frames' common z axis",
    motions=(("R", "z"),), suffixes=("",),
    closure=POINT + (("dot", "z", "x"), ("dot", "z", "y"))
)
PRISMATIC = JointType(
    name="P", description="prismatic: translation along the frames' common z axis",
    motions=(("P", "z"),), suffixes=("",),
    closure=(("dot", "z", "x"), ("dot", "z", "y"), ("dot", "x", "y"), ("gap", "x"), ("gap", "y")),
)
SPHERICAL = JointType(
    name="S", description="spherical: rotations about x, y, z (Cardan angles a, b, c)",
    motions=(("R", "x"), ("R", "y"), ("R", "z")), suffixes=("a", "b", "c"),
    closure=POINT, uses_axis=False,
)
UNIVERSAL = JointType(
    name="U", description="universal: rotation about z (fixed in parent), then x (fixed in child)",
    motions=(("R", "z"), ("R", "x")), suffixes=("1", "2"),
    closure=POINT + (("dot", "z", "x"),),
)
FIXED = JointType(
    name="Fixed", description="rigid connection",
    closure=POINT + (("dot", "z", "x"), ("dot", "z", "y"), ("dot", "x", "y")),
)
FREE = JointType(
    name="Free", description="floating base: translations along x, y, z, then rotations about x, y, z "
    "(Cardan angles a, b, c; singular at b = +-pi/2)",
    motions=(("P", "x"), ("P", "y"), ("P", "z"), ("R", "x"), ("R", "y"), ("R", "z")),
    suffixes=("x", "y", "z", "a", "b", "c"), closure=(), uses_axis=False,
)

# Multipoles that may cross each joint (joint-frame coordinates).
ORIGIN = (0, 0, 0)
Z = (0, 0, 1)
RULES: dict[str, tuple[TransferRule, ...]] = {
    # Points of the z axis share velocity: mass at the origin and a dipole along z (cond. 1, 2);
    # the bodies' angular velocities differ along z: the axisymmetric quadrupole (cond. 5).
    "R": (TransferRule("monopole", ORIGIN, None, 1), TransferRule("dipole", ORIGIN, Z, 2),
          TransferRule("quadrupole", ORIGIN, Z, 5)),
    # Same angular velocity: any quadrupole (cond. 6). The seed's condition 3 (a dipole along
    # the sliding direction) is NOT a null direction in general: see tests/test_transfer_rules.py.
    "P": (TransferRule("quadrupole", ORIGIN, None, 6),),
    "S": (TransferRule("monopole", ORIGIN, None, 1),),
    "U": (TransferRule("monopole", ORIGIN, None, 1),),
    # A rigid connection lets everything cross (cond. 1, 4, 6).
    "Fixed": (TransferRule("monopole", ORIGIN, None, 1),
              TransferRule("dipole", ORIGIN, (1, 0, 0), 4), TransferRule("dipole", ORIGIN, (0, 1, 0), 4),
              TransferRule("dipole", ORIGIN, Z, 4), TransferRule("quadrupole", ORIGIN, None, 6)),
    # Nothing crosses a free joint: every multipole transfer needs some velocity (of a point,
    # along a direction, or the angular velocity) shared by the two bodies, and a free joint
    # constrains none. An empty list is a complete answer, not an unknown: the symbolic
    # result stays exact.
    "Free": (),
}


@hookimpl
def baseparams_joint_types() -> list[JointType]:
    return [REVOLUTE, PRISMATIC, SPHERICAL, UNIVERSAL, FIXED, FREE]


@hookimpl
def baseparams_transfer_rules(joint_type: str) -> list[TransferRule] | None:
    rules = RULES.get(joint_type)
    return None if rules is None else list(rules)
