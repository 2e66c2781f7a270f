"""diagnose on robots it was not tuned on: arms of example-robot-data simulated by an
independent simulator (Pinocchio's RNEA, with the URDF's damping and friction, which the
reader makes known effects), logged at 1 kHz with AR(1) noise, read through a recording
description (a gripper that does not move is not logged: it is held, ``[held]``) and diagnosed against each robot's own URDF through the command line
(docs/diagnosis.md, "Robots that are not the ones the project tuned on").

Scenarios: nothing hidden; viscous and smooth (tanh) Coulomb friction on every moving joint;
a power-law friction outside the catalogue; a payload run: friction on every joint in two
recordings of different motions, the second carrying a rigid payload (a fifth of the robot's
mass, off the last moving joint's axis), the first identified (``identify --effect
viscous_friction:* --effect coulomb_friction:*``) and the second diagnosed against that
result (``--params``); ``baseline`` / ``same`` (not in the default set): one motion recorded
twice with the same friction and other noise, the second with that payload / without,
diagnosed against the first (``--baseline``); ``other``: the payload's run along another motion,
diagnosed ``--baseline`` against the first (nothing cancels by pairing). Printed per run: exit code, CPU seconds of the command, verdict, gap,
the named effects (a correction of a known effect with the model's value) and the truth.

    pip install example-robot-data pin
    python benchmarks/bench_diagnose_robots.py [--robots panda ur10 ...] [--seed 1] [--seconds 30]
        [--rate 100] [--payload 0.48] [--noise 0.1]     # the issue's second make: 0.48 kg, 100 Hz

Each diagnose prints its CPU seconds and peak resident memory (a long log: ``--robots panda
--scenarios friction --seconds 120``); with ``--params`` or ``--baseline`` also the ratio to one
``identify`` of the same changed run (issue 42's speed yardstick), whole processes.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))                      # tests/ is not a package

from robot_runs import NOISE, RATE, SECONDS, record, with_payload  # noqa: E402
from urdf_reference import example_robot_data, robot_id  # noqa: E402

ROBOTS = {"panda": "panda_description/panda", "ur10": "ur_description/ur10_robot", "ur3": "ur_description/ur3_robot",
          "z1": "z1_description/z1", "kinova": "kinova_description/kinova", "so101": "so_arm_description/so101",
          "xarm7": "xarm_description/xarm7", "talos_arm": "talos_data/talos_left_arm",
          "ur5_gripper": "ur_description/ur5_gripper", "baxter": "baxter_description/baxter",
          "finger": "finger_edu_description/finger_edu"}
DEFAULT = ("panda", "ur10", "ur3", "z1", "kinova", "so101")        # the table in docs/diagnosis.md
def command(args: list[str]) -> tuple[subprocess.CompletedProcess, float, float, float]:
    """Run ``baseparams ARGS``: the process, its CPU seconds, its wall seconds and its peak
    resident memory (MB; the kernel's count for this one child, ``os.wait4``)."""
    start = time.time()
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen(["baseparams", *args], stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.time() - start
        out.seek(0)
        err.seek(0)
        done = subprocess.CompletedProcess(process.args, os.waitstatus_to_exitcode(status), out.read(), err.read())
    process.returncode = done.returncode                      # reaped by wait4: Popen must not wait again
    return done, usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


def run(urdf: Path, scenario: str, seed: int, folder: Path, seconds: float = SECONDS, rate: float = RATE,
        payload: float | None = None, noise: float = NOISE, law: str = "friction") -> dict:
    import pinocchio as pin
    model = pin.buildModelFromUrdf(str(urdf))
    extra: list[str] = []
    cpu_before = 0.0
    if scenario == "payload":
        friction = record(model, seed + 1000, folder, "empty", law, seconds=seconds, rate=rate, noise=noise)
        fitted, cpu_before, _, _ = command(["identify", str(urdf), str(folder / "empty.toml"), "--effect",
                                         "viscous_friction:*", "--effect", "coulomb_friction:*", "--format", "json",
                                         "-o", str(folder / "empty.json"), "--quiet"])
        if fitted.returncode != 0:
            return {"exit": fitted.returncode, "cpu": cpu_before, "wall": 0.0,
                    "error": "identify: " + (fitted.stderr.strip().splitlines() or ["no output"])[-1]}
        model, truth = with_payload(model, payload)
        # the same friction, another motion
        record(model, seed, folder, "rec", law, friction, seconds=seconds, rate=rate, noise=noise)
        extra = ["--params", str(folder / "empty.json")]
    elif scenario in ("baseline", "same", "other"):
        # the same motion recorded twice (other noise), the second with the payload (or not;
        # 'other': another motion with the payload): diagnose the second against the first (--baseline)
        first = seed + 1000 if scenario == "other" else seed
        friction = record(model, first, folder, "empty", law, seconds=seconds, rate=rate, noise=noise)
        truth = {}
        if scenario in ("baseline", "other"):
            model, truth = with_payload(model, payload)
        record(model, seed, folder, "rec", law, friction, noise_seed=seed + 2000, seconds=seconds, rate=rate,
               noise=noise)
        extra = ["--baseline", str(folder / "empty.toml")]
    else:
        truth = record(model, seed, folder, "rec", scenario, seconds=seconds, rate=rate, noise=noise)
    done, cpu, wall, memory = command(["diagnose", str(urdf), str(folder / "rec.toml"), "--format", "json", "--quiet",
                               *extra])
    out = {"exit": done.returncode, "cpu": cpu, "wall": wall, "memory": memory, "truth": truth,
           "identify_cpu": cpu_before}
    if extra:                     # issue 42's yardstick: one identify of the same (changed) run
        _, out["same_identify_cpu"], _, _ = command(["identify", str(urdf), str(folder / "rec.toml"), "--effect",
                                                     "viscous_friction:*", "--effect", "coulomb_friction:*",
                                                     "--format", "json", "--quiet"])
    try:
        report = json.loads(done.stdout)
    except json.JSONDecodeError:
        out["error"] = done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "no output"
        return out
    out["rows"] = (report["pairing"]["changed_samples"] if "changes" in report else report["samples"]["fit"],
                   len(report["coordinates"]))
    if "changes" in report:                                  # --baseline: a change report
        out.update(verdict=report["verdict"], gap=(report["gap"]["before"], report["gap"]["after"]),
                   named=[(e["kind"], e["coordinate"], e["value"] if not isinstance(e["value"], dict) else
                           {k: None if v is None else round(v, 4) for k, v in e["value"].items()}, None)
                          for e in report["changes"]],
                   ambiguous=len(report["ambiguous"]), unsupported=0)
        return out
    out.update(verdict=report["verdict"], gap=(report["gap"]["cv_before"], report["gap"]["cv_after"]),
               named=[(e["kind"], e["coordinate"], {k: None if v["value"] is None else round(v["value"], 4) for k, v in e["coefficients"].items()},
                       e.get("known")) for e in report["effects"]],
               ambiguous=len(report["ambiguous"]), unsupported=len(report["unsupported"]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=list(DEFAULT), choices=list(ROBOTS))
    parser.add_argument("--scenarios", nargs="+", default=["none", "friction", "power", "payload"],
                        choices=["none", "friction", "power", "payload", "baseline", "same", "other"],
                        help="baseline / same: one motion recorded twice, the second with the payload / "
                             "without, diagnosed against the first (--baseline); other: the payload's run "
                             "along another motion (--baseline)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=SECONDS,
                        help="length of each simulated log (s): memory and time on long recordings")
    parser.add_argument("--rate", type=float, default=RATE, help="the logs' sampling rate (Hz; default 1000)")
    parser.add_argument("--payload", type=float, default=None,
                        help="the payload's mass (kg; default a fifth of the robot's mass)")
    parser.add_argument("--noise", type=float, default=NOISE,
                        help="the torques' AR(1) noise, SD as a fraction of each joint's RMS torque (default 0.02)")
    parser.add_argument("--law", choices=["friction", "power"], default="friction",
                        help="the friction law both runs of payload / baseline / same / other share: 'friction' "
                             "(viscous and smooth Coulomb, near the catalogue's) or 'power' (outside it: a model "
                             "error common to both runs, which --params chases)")
    args = parser.parse_args()
    files = {robot_id(p): p for p in example_robot_data()}
    if not files:
        sys.exit("example-robot-data is not installed: pip install example-robot-data pin")
    with tempfile.TemporaryDirectory() as tmp:
        for robot in args.robots:
            for scenario in args.scenarios:
                folder = Path(tmp) / f"{robot}_{scenario}"
                folder.mkdir()
                r = run(files[ROBOTS[robot]], scenario, args.seed, folder, args.seconds, args.rate, args.payload,
                        args.noise, args.law)
                if "error" in r:
                    print(f"{robot:7s} {scenario:8s} exit {r['exit']} {r['cpu']:5.1f} CPU s: {r['error']}", flush=True)
                    continue
                print(f"{robot:7s} {scenario:8s} exit {r['exit']} {r['cpu']:5.1f} CPU s ({r['wall']:.1f} s, "
                      f"peak {r['memory']:.0f} MB): "
                      f"{r['verdict']}, gap {r['gap'][0]:.3f} -> {r['gap'][1]:.3f}, named {len(r['named'])}, "
                      f"ambiguous {r['ambiguous']}, unsupported {r['unsupported']}", flush=True)
                for kind, coordinate, values, known in r["named"]:
                    correction = f" correcting {known}" if known else ""
                    print(f"      {kind}:{coordinate} {values}{correction}", flush=True)
                if scenario in ("payload", "baseline", "other"):
                    spent = f" (identify of the payload-free run {r['identify_cpu']:.1f} CPU s)" \
                        if scenario == "payload" else ""
                    print(f"      truth: {r['truth']}{spent}", flush=True)
                if "same_identify_cpu" in r:
                    print(f"      speed: diagnose {r['cpu']:.1f} CPU s, one identify of the same run "
                          f"{r['same_identify_cpu']:.1f} CPU s: ratio {r['cpu'] / r['same_identify_cpu']:.2f} "
                          f"(issue 42: <= 5; the diagnosis on {r['rows'][0]} samples x {r['rows'][1]} joints)",
                          flush=True)
                elif r["truth"]:
                    rounded = {j: {k: round(v, 4) for k, v in c.items()} for j, c in r["truth"].items()}
                    print(f"      truth (per joint, fv fc): {rounded}", flush=True)


if __name__ == "__main__":
    main()
