"""Identify a robot from a recording, then ask what its model still misses.

    python examples/identify_recording.py [MECH DATA...]

Without arguments: the Staubli TX40 of examples/data/tx40 (raw motor logs, gear ratios,
the coupled wrist; every 10th row of the real 5 kHz recording, carried in the project with its
attribution). MECH is a registered name, a TOML or a URDF file; DATA are CSV files or
recording descriptions (.toml). Takes about 20 s of CPU on the TX40.
"""

import sys
from pathlib import Path

import baseparams as bp

HERE = Path(__file__).resolve().parent
TX40 = HERE / "data" / "tx40"


def main() -> int:
    if len(sys.argv) > 2:
        mech, data = sys.argv[1], sys.argv[2:]
    else:
        mech, data = TX40 / "tx40_mdh_modified.urdf", [TX40 / "recording.toml"]
    # base parameters and friction on every joint, weighted least squares
    fit = bp.identify(mech, data, effects=["viscous_friction:*", "coulomb_friction:*"], solver="dp")
    print(fit.to_text())
    # every candidate effect tested against what the fit leaves: the missing one named
    report = bp.diagnose(mech, data)
    print(report.to_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
