"""Solve a URDF robot: its base inertial parameters in three lines.

Uses the UR5 of example-robot-data when that package is installed (pip install
example-robot-data), else the copy in examples/data/ur5.urdf; or give a URDF path:

    python examples/solve_urdf.py [ROBOT.urdf] [SOLVER]
"""

import sys
from pathlib import Path

import baseparams as bp

HERE = Path(__file__).resolve().parent


def ur5_urdf() -> Path:
    """The UR5 URDF of example-robot-data if installed, else the bundled copy."""
    try:
        from example_robot_data.robots_loader import UR5Loader, getModelPath
        subpath = f"{UR5Loader.path}/{UR5Loader.urdf_subpath}/{UR5Loader.urdf_filename}"
        path = Path(getModelPath(subpath)) / subpath
        if path.is_file():
            return path
    except (ImportError, AttributeError, OSError, TypeError):
        pass                                    # not installed, or another layout: the bundled copy
    return HERE / "data" / "ur5.urdf"


def main() -> None:
    urdf = Path(sys.argv[1]) if len(sys.argv) > 1 else ur5_urdf()
    solver = sys.argv[2] if len(sys.argv) > 2 else "vp"
    solution = bp.solve(urdf, solver)           # a Solution: rank, base, eliminated, to_json(), to_frame()
    print(f"{urdf.name}: {len(solution.parameters)} inertial parameters, rank {solution.rank}"
          + (" (certified)" if solution.certified else ""))
    for line in solution.legend()[:6]:
        print("  " + line)
    print(f"  ... {solution.rank} base parameters in all; eliminated: {len(solution.eliminated)}")


if __name__ == "__main__":
    main()
