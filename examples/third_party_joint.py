"""Validate a third party's joint type: a cylindrical joint registered from this script.

A distribution would name its module in the ``baseparams`` entry-point group
(``[project.entry-points.baseparams] cylindrical = "my_package.plugin"``); here the module
registers itself at run time, through the same hooks. Every solver then runs on a
mechanism that uses the new joint, and ``validate`` cross-checks them (ranks, base
parameter spaces, the model's energy balance and the joint's transfer rule).

    python examples/third_party_joint.py
"""

import sys
import tempfile
from pathlib import Path

import baseparams as bp
from baseparams import registry
from baseparams.hookspecs import hookimpl
from baseparams.model.joints import JointType
from baseparams.model.multipoles import TransferRule

CYLINDRICAL = JointType(
    name="C", description="cylindrical: translation along z, then rotation about z",
    motions=(("P", "z"), ("R", "z")), suffixes=("s", "theta"),
    closure=(("dot", "z", "x"), ("dot", "z", "y"), ("gap", "x"), ("gap", "y")),
)


@hookimpl
def baseparams_joint_types() -> list[JointType]:
    return [CYLINDRICAL]


@hookimpl
def baseparams_transfer_rules(joint_type: str) -> list[TransferRule] | None:
    if joint_type != "C":
        return None
    # the bodies' angular velocities differ only along z: the axisymmetric quadrupole crosses
    return [TransferRule("quadrupole", (0, 0, 0), (0, 0, 1), 5)]


# A collar sliding and turning on a tilted post (C joint), carrying a pendulum (R joint).
COLLAR = """\
[mechanism]
name = "collar"

[[bodies]]
label = 1
name = "collar"

[[bodies]]
label = 2
name = "bob"

[[joints]]
name = "post"
type = "C"
parent = 0
child = 1
parent_frame = { point = ["0", "0", "0"], axis = ["0", "0.6", "0.8"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"] }

[[joints]]
name = "swing"
type = "R"
parent = 1
child = 2
parent_frame = { point = ["0.2", "0", "0"], axis = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0.3"], axis = ["1", "0", "0"] }

[trajectory]
t_start = "0"
t_end = "10"
samples = 200
q = { post_s = "0.2*sin(0.9*t)", post_theta = "1.1*sin(1.3*t + 0.5)", swing = "0.8*sin(2.1*t) + 0.3*sin(3.7*t)" }
"""


def main() -> int:
    registry.plugin_manager().register(sys.modules[__name__], name="cylindrical-example")
    registry.reset()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "collar.toml"
        path.write_text(COLLAR, encoding="utf-8")
        print(bp.solve(path, "exact").to_text())
        report = bp.validate([str(path)], solvers=["dp", "vp", "exact", "symbolic"])
        print(report.to_text())
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
