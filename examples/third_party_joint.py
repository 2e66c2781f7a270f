"""Validate a third party's joint type: a planar joint registered from this script.

A distribution would name its module in the ``baseparams`` entry-point group
(``[project.entry-points.baseparams] planar = "my_package.plugin"``); here the module
registers itself at run time, through the same hooks. Every solver then runs on a
mechanism that uses the new joint, and ``validate`` cross-checks them (ranks, base
parameter spaces, the model's energy balance and the joint's transfer rule).

    python examples/third_party_joint.py
"""

import sys
from pathlib import Path

import baseparams as bp
from baseparams import registry
from baseparams.hookspecs import hookimpl
from baseparams.model.joints import JointType
from baseparams.model.multipoles import TransferRule

PLANAR = JointType(
    name="Planar", description="planar: translations along x and y, then rotation about z",
    motions=(("P", "x"), ("P", "y"), ("R", "z")), suffixes=("x", "y", "theta"),
    closure=(("dot", "z", "x"), ("dot", "z", "y"), ("gap", "z")),    # parallel z axes, no gap along z
)


@hookimpl
def baseparams_joint_types() -> list[JointType]:
    return [PLANAR]


@hookimpl
def baseparams_transfer_rules(joint_type: str) -> list[TransferRule] | None:
    if joint_type != "Planar":
        return None
    # the bodies' angular velocities differ only along z: the quadrupole symmetric about z
    # crosses (validate checks that it is a null direction of W, in ball arithmetic)
    return [TransferRule("quadrupole", (0, 0, 0), (0, 0, 1), 5)]


PUCK = Path(__file__).resolve().parent / "data" / "puck.toml"     # a puck on a tilted table, with a pendulum


def main() -> int:
    registry.plugin_manager().register(sys.modules[__name__], name="planar-example")
    registry.reset()
    print(bp.solve(PUCK, "exact").to_text())
    report = bp.validate([str(PUCK)], solvers=["dp", "vp", "exact", "symbolic"])
    print(report.to_text())
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
