"""Solve a URDF robot: its base inertial parameters in three lines.

Uses the UR5 of example-robot-data when that package is installed (pip install
example-robot-data: its files, found through the distribution's file list), else the copy
in examples/data/ur5.urdf, and says which; or give a URDF path:

    python examples/solve_urdf.py [ROBOT.urdf] [SOLVER]
"""

import sys
from importlib import metadata
from pathlib import Path

import baseparams as bp

HERE = Path(__file__).resolve().parent


def ur5_urdf() -> Path:
    """The UR5 URDF of example-robot-data if installed, else the bundled copy."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        return HERE / "data" / "ur5.urdf"
    for file in dist.files or ():
        if file.as_posix().endswith("robots/ur_description/urdf/ur5_robot.urdf"):
            path = Path(dist.locate_file(file))
            if path.is_file():
                return path
    return HERE / "data" / "ur5.urdf"          # another layout: the bundled copy


def main() -> None:
    urdf = Path(sys.argv[1]) if len(sys.argv) > 1 else ur5_urdf()
    solver = sys.argv[2] if len(sys.argv) > 2 else "vp"
    print(f"URDF: {urdf}")
    solution = bp.solve(urdf, solver)           # a Solution: rank, base, eliminated, to_json(), to_frame()
    print(f"{urdf.name}: {len(solution.parameters)} inertial parameters, rank {solution.rank}"
          + (" (certified)" if solution.certified else ""))
    for line in solution.legend()[:6]:
        print("  " + line)
    print(f"  ... {solution.rank} base parameters in all; eliminated: {len(solution.eliminated)}")


if __name__ == "__main__":
    main()
