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
diagnosed against the first (``--baseline``). Printed per run: exit code, CPU seconds of the command, verdict, gap,
the named effects (a correction of a known effect with the model's value) and the truth.

    pip install example-robot-data pin
    python benchmarks/bench_diagnose_robots.py [--robots panda ur10 ...] [--seed 1] [--seconds 30]

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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))                      # tests/ is not a package

from urdf_reference import example_robot_data, robot_id  # noqa: E402

ROBOTS = {"panda": "panda_description/panda", "ur10": "ur_description/ur10_robot", "ur3": "ur_description/ur3_robot",
          "z1": "z1_description/z1", "kinova": "kinova_description/kinova", "so101": "so_arm_description/so101",
          "xarm7": "xarm_description/xarm7", "talos_arm": "talos_data/talos_left_arm",
          "ur5_gripper": "ur_description/ur5_gripper", "baxter": "baxter_description/baxter",
          "finger": "finger_edu_description/finger_edu"}
DEFAULT = ("panda", "ur10", "ur3", "z1", "kinova", "so101")        # the table in docs/diagnosis.md
RATE, SECONDS, RHO, NOISE = 1000.0, 30.0, 0.95, 0.02       # Hz, s, AR(1) per sample, SD / RMS torque
STILL = ("finger_joint", "ripper")                           # grippers are held still


def motion(model, rng, t):
    """A 5-harmonic Fourier series per joint (0.1 Hz base) inside 60 % of its range."""
    import pinocchio as pin
    nv = model.nv
    q, qd, qdd = (np.zeros((len(t), nv)) for _ in range(3))
    names = [model.names[i] for i in range(1, model.njoints)]
    w0 = 2 * np.pi * 0.1
    for joint, name in zip(model.joints[1:], names):
        j = joint.idx_v
        if joint.nq == 1:
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            lo, hi = (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and hi > lo else (-np.pi, np.pi)
        else:                                                # continuous: (cos, sin)
            lo, hi = -np.pi, np.pi
        centre, span = (lo + hi) / 2, min((hi - lo) / 2, np.pi) * 0.6
        a, b = rng.standard_normal(5) / np.arange(1, 6), rng.standard_normal(5) / np.arange(1, 6)
        for k in range(1, 6):
            s, c = np.sin(k * w0 * t), np.cos(k * w0 * t)
            q[:, j] += a[k - 1] * s + b[k - 1] * c
            qd[:, j] += k * w0 * (a[k - 1] * c - b[k - 1] * s)
            qdd[:, j] -= (k * w0) ** 2 * (a[k - 1] * s + b[k - 1] * c)
        scale = 0.0 if any(word in name for word in STILL) else span / max(np.max(np.abs(q[:, j])), 1e-9)
        q[:, j] = centre + scale * q[:, j]
        qd[:, j] *= scale
        qdd[:, j] *= scale
    configuration = (lambda v: v) if model.nq == model.nv else (lambda v: pin.integrate(model, pin.neutral(model), v))
    return names, q, qd, qdd, configuration


def record(model, seed: int, folder: Path, name: str, friction: str, given: dict | None = None,
           noise_seed: int | None = None) -> dict:
    """Simulate ``model`` along a motion of ``seed`` with the URDF's own damping and friction,
    the ``friction`` scenario's ('none', 'friction', 'power'; its coefficients ``given`` by
    joint name, else drawn from this run's torques) and AR(1) noise (drawn from ``noise_seed``
    when given: the same motion recorded again); write ``name``.csv and its recording
    description ``name``.toml; return the hidden friction."""
    import pinocchio as pin
    data = model.createData()
    rng = np.random.default_rng(seed)
    t = np.arange(0, SECONDS, 1 / RATE)
    names, q, qd, qdd, configuration = motion(model, rng, t)
    tau = np.array([pin.rnea(model, data, configuration(q[i]), qd[i], qdd[i]) for i in range(len(t))])
    tau += qd * np.asarray(model.damping) + np.sign(qd) * np.asarray(model.friction)    # the URDF's own
    rms = np.sqrt(np.mean(tau ** 2, axis=0)) + 1e-3
    truth = {}
    for j in (j for j in range(model.nv) if friction != "none" and np.std(qd[:, j]) > 0):
        fv, fc, vs = 0.05 * rms[j], 0.08 * rms[j], 0.02 * np.std(qd[:, j])
        if given:
            fv, fc = given[names[j]]["fv"], given[names[j]]["fc"]
        shape = np.tanh(qd[:, j] / vs) if friction == "friction" else \
            np.sign(qd[:, j]) * (np.abs(qd[:, j]) / np.std(qd[:, j])) ** 0.4
        tau[:, j] += fv * qd[:, j] + fc * shape
        truth[names[j]] = {"fv": float(fv), "fc": float(fc)}       # unrounded: a second run given them has the same
    e = (rng if noise_seed is None else np.random.default_rng(noise_seed)).standard_normal(tau.shape)
    for i in range(1, len(e)):
        e[i] += RHO * e[i - 1]
    tau += e * NOISE * rms / e.std(axis=0)
    header = ["t"] + [f"q_{n}" for n in names] + [f"tau_{n}" for n in names]
    np.savetxt(folder / f"{name}.csv", np.column_stack([t, q, tau]), delimiter=",", header=",".join(header),
               comments="", fmt="%.9g")
    # a gripper held still is not logged, as on a real arm: held at its value ([held]), a mimic
    # joint (panda_finger_joint2) listed with it at the value it follows
    still = [n for n in names if any(word in n for word in STILL)]
    listed = [n for n in names if n not in still and n != "panda_finger_joint2"]
    (folder / f"{name}.toml").write_text(f'[recording]\ntime = "t"\n[[runs]]\nfile = "{name}.csv"\n[position]\n'
                                         + "".join(f'{n} = "q_{n}"\n' for n in listed) + "[torque]\n"
                                         + "".join(f'{n} = "tau_{n}"\n' for n in listed) + "[held]\n"
                                         + "".join(f"{n} = {float(q[0, names.index(n)])!r}\n" for n in still))
    return truth


def with_payload(model) -> tuple[object, dict]:
    """A copy of ``model`` carrying a rigid payload of a fifth of its mass on the last moving
    joint's body, its centre (0.05, 0.03, 0.08) m off that joint's frame, and the truth."""
    import pinocchio as pin
    loaded = model.copy()
    last = max(j for j in range(1, model.njoints) if not any(word in model.names[j] for word in STILL))
    mass = 0.2 * sum(model.inertias[j].mass for j in range(1, model.njoints))
    centre = np.array([0.05, 0.03, 0.08])
    loaded.inertias[last] = loaded.inertias[last] + pin.Inertia(mass, centre, np.diag([1.0, 1.0, 0.5]) * 1e-3 * mass)
    return loaded, {"joint": model.names[last], "mass": round(float(mass), 4), "centre": centre.tolist()}


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


def run(urdf: Path, scenario: str, seed: int, folder: Path) -> dict:
    import pinocchio as pin
    model = pin.buildModelFromUrdf(str(urdf))
    extra: list[str] = []
    cpu_before = 0.0
    if scenario == "payload":
        friction = record(model, seed + 1000, folder, "empty", "friction")
        fitted, cpu_before, _, _ = command(["identify", str(urdf), str(folder / "empty.toml"), "--effect",
                                         "viscous_friction:*", "--effect", "coulomb_friction:*", "--format", "json",
                                         "-o", str(folder / "empty.json"), "--quiet"])
        if fitted.returncode != 0:
            return {"exit": fitted.returncode, "cpu": cpu_before, "wall": 0.0,
                    "error": "identify: " + (fitted.stderr.strip().splitlines() or ["no output"])[-1]}
        model, truth = with_payload(model)
        record(model, seed, folder, "rec", "friction", friction)      # the same friction, another motion
        extra = ["--params", str(folder / "empty.json")]
    elif scenario in ("baseline", "same"):
        # the same motion recorded twice (other noise), the second with the payload (or not):
        # diagnose the second against the first (--baseline)
        friction = record(model, seed, folder, "empty", "friction")
        truth = {}
        if scenario == "baseline":
            model, truth = with_payload(model)
        record(model, seed, folder, "rec", "friction", friction, noise_seed=seed + 2000)
        extra = ["--baseline", str(folder / "empty.toml")]
    else:
        truth = record(model, seed, folder, "rec", scenario)
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
    global SECONDS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=list(DEFAULT), choices=list(ROBOTS))
    parser.add_argument("--scenarios", nargs="+", default=["none", "friction", "power", "payload"],
                        choices=["none", "friction", "power", "payload", "baseline", "same"],
                        help="baseline / same: one motion recorded twice, the second with the payload / "
                             "without, diagnosed against the first (--baseline)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=SECONDS,
                        help="length of each simulated log (s, at 1 kHz): memory and time on long recordings")
    args = parser.parse_args()
    SECONDS = args.seconds
    files = {robot_id(p): p for p in example_robot_data()}
    if not files:
        sys.exit("example-robot-data is not installed: pip install example-robot-data pin")
    with tempfile.TemporaryDirectory() as tmp:
        for robot in args.robots:
            for scenario in args.scenarios:
                folder = Path(tmp) / f"{robot}_{scenario}"
                folder.mkdir()
                r = run(files[ROBOTS[robot]], scenario, args.seed, folder)
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
                if scenario in ("payload", "baseline"):
                    spent = f" (identify of the payload-free run {r['identify_cpu']:.1f} CPU s)" \
                        if scenario == "payload" else ""
                    print(f"      truth: {r['truth']}{spent}", flush=True)
                if "same_identify_cpu" in r:
                    print(f"      speed: diagnose {r['cpu']:.1f} CPU s, one identify of the same run "
                          f"{r['same_identify_cpu']:.1f} CPU s: ratio {r['cpu'] / r['same_identify_cpu']:.2f} "
                          "(issue 42: <= 5)", flush=True)
                elif r["truth"]:
                    rounded = {j: {k: round(v, 4) for k, v in c.items()} for j, c in r["truth"].items()}
                    print(f"      truth (per joint, fv fc): {rounded}", flush=True)


if __name__ == "__main__":
    main()
