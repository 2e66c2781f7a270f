"""Every URDF of example-robot-data that Pinocchio loads, unedited (docs/urdf.md, "Robots as
users have them"): Pinocchio's rank (its joint-torque regressor of the uncoupled tree
projected onto the mimic couplings, tests/urdf_reference.py) beside dp's and vp's base-parameter
counts, K phi against rnea, and CPU seconds: dp, vp (robots up to --vp-bodies bodies, and
always Talos full and Romeo) and the yardstick, Pinocchio's own stacked regressor and SVD
in the same run (ratio dp / yardstick).

    pip install example-robot-data pin
    python benchmarks/bench_urdf_robots.py [--vp-bodies 60] [--only NAME ...] [--floating]
"""

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))                      # tests/ is not a package

from urdf_reference import Reference, example_robot_data, robot_id, torque_check  # noqa: E402

from baseparams import registry  # noqa: E402
from baseparams.errors import InputError  # noqa: E402
from baseparams.io.loader import load_mechanism  # noqa: E402
from baseparams.plugins.urdf.reader import read_urdf  # noqa: E402

ALWAYS_VP = ("talos_data/talos_full_v2", "romeo_description/romeo")
FLOATING = ("hector_description/quadrotor_base", "solo_description/solo12", "anymal_b_simple_description/anymal",
            "hyq_description/hyq_no_sensors", "go1_description/go1", "b1_description/b1",
            "anymal_b_simple_description/anymal-kinova", "talos_data/talos_full_v2", "romeo_description/romeo")


def cpu(function):
    start = time.process_time()
    out = function()
    return out, time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vp-bodies", type=int, default=60, help="vp on robots with at most this many bodies")
    parser.add_argument("--only", nargs="*", default=(), help="robot ids containing one of these texts")
    parser.add_argument("--floating", action="store_true", help="also the floating-base robots (free flyer)")
    parser.add_argument("--start", default="", help="skip the robot ids sorted before this text (resume a run)")
    args = parser.parse_args()
    paths = example_robot_data()
    if not paths:
        sys.exit("example-robot-data is not installed (pip install example-robot-data)")
    solvers = registry.solvers()
    dp, vp = solvers["dp"].item, solvers["vp"].item
    print("| robot | base | bodies | dof | mimic | Pinocchio rank | dp | vp | K phi - rnea | "
          "Pinocchio s | dp s | dp / Pinocchio | vp s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    disagree = 0
    cases = [(p, False) for p in paths] + ([(p, True) for p in paths if robot_id(p) in FLOATING]
                                          if args.floating else [])
    for path, floating in cases:
        name = robot_id(path)
        if args.only and not any(text in name for text in args.only) or (name < args.start and not floating):
            continue
        try:
            ref = Reference(path, floating)
        except Exception as exc:                              # noqa: BLE001 (Pinocchio's refusal)
            print(f"| {name} | {'free' if floating else 'fixed'} | Pinocchio does not load it: "
                  f"{str(exc).splitlines()[0][:60]} |||||||||||")
            continue
        if ref.model.nv == 0:
            try:
                load_mechanism(path)
                verdict = "loads (no degree of freedom?)"
            except InputError as exc:
                verdict = "refused: " + str(exc).split(": ", 2)[-1][:70]
            print(f"| {name} | fixed | nothing moves in Pinocchio (nv = 0); ours {verdict} |||||||||||")
            continue
        mech = read_urdf(path, floating_base=floating).mechanism
        (rank, gap), t_pin = cpu(ref.rank)
        # at the defaults: dp builds a W above the memory limit in row blocks (issue 47)
        result, t_dp = cpu(lambda: dp.solve(mech))
        error, _ = torque_check(ref, mech)
        vp_rank, t_vp = "-", None
        if len(mech.bodies) <= args.vp_bodies or name in ALWAYS_VP:
            found, t_vp = cpu(lambda: vp.solve(mech))
            vp_rank = found.rank if found.certified else f"{found.rank} (not certified)"
        ok = result.rank == rank and vp_rank in ("-", rank)
        gap_note = "" if gap >= 1e6 else f" (Pinocchio's gap only {gap:.2g})"
        disagree += not ok
        print(f"| {name} | {'free' if floating else 'fixed'} | {len(mech.bodies)} | {len(mech.independent)} | "
              f"{len(mech.couplings)} | {rank} | {result.rank} | {vp_rank} | {error:.1e} | {t_pin:.2f} | "
              f"{t_dp:.2f} | {t_dp / max(t_pin, 1e-3):.0f} | {'-' if t_vp is None else f'{t_vp:.1f}'} |"
              + ("" if ok else " DISAGREE") + gap_note, flush=True)
    print(f"\n{disagree} disagreement(s)")


if __name__ == "__main__":
    main()
