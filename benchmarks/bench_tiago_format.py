"""identify and diagnose on logs in the TIAGo export's format (FIGAROH's published TIAGo
recordings: examples/tiago/data/identification in thanhndv212/figaroh-examples), simulated by
an independent simulator (Pinocchio's RNEA on example-robot-data's tiago.urdf, with its own
damping and Coulomb friction), so that the truth is known.

What the format has that the project's own simulations did not: one file per quantity
(``tiago_position.csv``, ``_velocity.csv``, ``_effort.csv``) on one ROS clock ``t`` (100 Hz,
steps 7.7-12.3 ms), columns named ``- <joint>_position``, efforts in the drive's unit rounded
to 0.001 (the wrist's steps are 0.2 N m here: most of its values a few steps), a logged
velocity that is a first-order filter of the position difference (not used), and a model of
48 joints of which the log has 8 (hand, head and wheels held: ``"*" = 0``). Noise: AR(1) 0.5,
2 % of each joint's RMS torque.

Scenarios: ``none`` (the URDF is the truth), ``friction`` (the robot's Coulomb friction is 0.6
of the URDF's and its viscous friction twice it), ``payload`` (a run without load identified,
``identify``, then a run of the same path carrying 0.489 kg 0.15 m down arm_7's axis, as the
published ``calibration_weight`` run, diagnosed against it with ``--params``). Printed per run:
exit code, CPU seconds, verdict, gap, named effects.

    pip install example-robot-data pin
    python benchmarks/bench_tiago_format.py [--seeds 1 2 3] [--scenarios none friction payload]
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))                      # tests/ is not a package
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_diagnose_robots import command  # noqa: E402
from urdf_reference import example_robot_data  # noqa: E402

MOVING = ["torso_lift_joint"] + [f"arm_{k}_joint" for k in range(1, 8)]
GAIN = {"torso_lift_joint": 1.0, "arm_1_joint": 10.0, "arm_2_joint": 10.0, "arm_3_joint": 7.0,
        "arm_4_joint": 7.0, "arm_5_joint": 200.0, "arm_6_joint": 200.0, "arm_7_joint": 200.0}  # N m per unit
PAYLOAD = 0.489                                               # kg, as the F/T sensor read in the real run
SECONDS, RHO, NOISE = 80.0, 0.5, 0.02


def tiago_urdf() -> Path:
    return next(p for p in example_robot_data() if p.name == "tiago.urdf")


def record(folder: Path, seed: int, *, motion_seed: int, friction: tuple[float, float] = (1.0, 1.0),
           payload: float = 0.0) -> None:
    """A run in the export's format in ``folder`` and its recording description: the URDF's
    viscous and Coulomb friction scaled by ``friction``, ``payload`` kg on arm_7_link."""
    import pinocchio as pin
    model = pin.buildModelFromUrdf(str(tiago_urdf()))
    if payload:
        j = model.getJointId("arm_7_joint")
        model.inertias[j] = model.inertias[j] + pin.Inertia(payload, np.array([0.0, 0.0, 0.15]), np.eye(3) * 1e-4)
    rng, paths = np.random.default_rng(seed), np.random.default_rng(motion_seed)
    t = np.r_[0.0, np.cumsum(np.clip(0.010 + 0.0012 * rng.standard_normal(int(SECONDS / 0.01) + 100), 0.0077,
                                     0.0123))]
    t = t[t <= SECONDS]
    n = len(t)
    q, qd, qdd = np.tile(pin.neutral(model), (n, 1)), np.zeros((n, model.nv)), np.zeros((n, model.nv))
    w0 = 2 * np.pi * 0.05
    for name in MOVING:                                       # 5 harmonics, half the joint's range
        joint = model.joints[model.getJointId(name)]
        lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
        a, b = paths.standard_normal(5) / np.arange(1, 6), paths.standard_normal(5) / np.arange(1, 6)
        k = np.arange(1, 6)[:, None] * w0
        s, c = np.sin(k * t), np.cos(k * t)
        x, xd, xdd = a @ s + b @ c, (a[:, None] * k * c - b[:, None] * k * s).sum(0), -(a[:, None] * k ** 2 * s
                                                                                       + b[:, None] * k ** 2 * c).sum(0)
        scale = (hi - lo) / 4 / np.max(np.abs(x))
        q[:, joint.idx_q], qd[:, joint.idx_v], qdd[:, joint.idx_v] = (lo + hi) / 2 + scale * x, scale * xd, scale * xdd
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[i], qd[i], qdd[i]) for i in range(n)])
    tau += friction[0] * qd * np.asarray(model.damping) + friction[1] * np.sign(qd) * np.asarray(model.friction)
    index = [model.joints[model.getJointId(name)].idx_v for name in MOVING]
    torque = tau[:, index]
    e = rng.standard_normal(torque.shape)
    for i in range(1, n):
        e[i] += RHO * e[i - 1]
    torque += e / e.std(axis=0) * NOISE * np.sqrt(np.mean(torque ** 2, axis=0))
    gains = np.array([GAIN[name] for name in MOVING])
    position = q[:, [model.joints[model.getJointId(name)].idx_q for name in MOVING]]
    velocity = np.zeros_like(position)                       # the controller's filtered derivative
    for i in range(1, n):
        velocity[i] = 0.95 * velocity[i - 1] + 0.05 * (position[i] - position[i - 1]) / (t[i] - t[i - 1])
    folder.mkdir(parents=True, exist_ok=True)
    for what, values in (("position", position), ("velocity", velocity), ("effort", np.round(torque / gains, 3))):
        np.savetxt(folder / f"tiago_{what}.csv", np.column_stack([t, values]), delimiter=",", comments="",
                   header="t," + ",".join(f"- {name}_{what}" for name in MOVING), fmt="%.17g")
    (folder / "recording.toml").write_text(
        '[recording]\ntime = "t"\n\n[[runs]]\nfiles = { pos = "tiago_position.csv", eff = "tiago_effort.csv" }\n'
        "\n[position]\n" + "".join(f'{name} = "pos:- {name}_position"\n' for name in MOVING)
        + "\n[torque]\n" + "".join(f'{name} = {{ column = "eff:- {name}_effort", gain = {GAIN[name]} }}\n'
                                   for name in MOVING)
        + '\n[held]                      # hand, head and wheels: not logged, did not move\n"*" = 0\n')


def diagnosed(folder: Path, extra: list[str]) -> dict:
    done, cpu, _, memory = command(["diagnose", str(tiago_urdf()), str(folder / "recording.toml"), "--format",
                                    "json", "--quiet", *extra])
    out = {"exit": done.returncode, "cpu": cpu, "memory": memory}
    try:
        report = json.loads(done.stdout)
    except json.JSONDecodeError:
        out["error"] = (done.stderr.strip().splitlines() or ["no output"])[-1]
        return out
    out.update(verdict=report["verdict"], gap=(report["gap"]["cv_before"], report["gap"]["cv_after"]),
               named=[(e["kind"], e["coordinate"], {k: None if v["value"] is None else round(v["value"], 4)
                                                    for k, v in e["coefficients"].items()})
                      for e in report["effects"]],
               ambiguous=[a.get("members", a) for a in report["ambiguous"]],
               quantised=sorted(report["unexplained"].get("quantised", {})))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--scenarios", nargs="+", default=["none", "friction", "payload"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for scenario in args.scenarios:
                folder = Path(tmp) / f"{scenario}{seed}"
                extra: list[str] = []
                identify_cpu = 0.0
                if scenario == "payload":
                    record(folder / "empty", 100 + seed, motion_seed=seed)
                    fitted, identify_cpu, _, _ = command(["identify", str(tiago_urdf()),
                                                          str(folder / "empty" / "recording.toml"), "--format",
                                                          "json", "-o", str(folder / "empty.json"), "--quiet"])
                    if fitted.returncode != 0:
                        print(f"seed {seed} {scenario}: identify exit {fitted.returncode}: {fitted.stderr[-300:]}")
                        continue
                    record(folder, seed, motion_seed=seed, payload=PAYLOAD)
                    extra = ["--params", str(folder / "empty.json")]
                else:
                    record(folder, seed, motion_seed=seed, friction=(2.0, 0.6) if scenario == "friction" else (1, 1))
                out = diagnosed(folder, extra)
                truth = {"none": "nothing", "friction": "viscous x2, Coulomb x0.6 on every arm joint",
                         "payload": f"{PAYLOAD} kg on arm_7_link, 0.15 m down its axis"}[scenario]
                print(f"seed {seed} {scenario:8s} exit {out['exit']} diagnose {out['cpu']:.1f} CPU s "
                      f"(identify {identify_cpu:.1f}) peak {out.get('memory', 0):.0f} MB: "
                      f"{out.get('verdict', out.get('error'))}; gap {out.get('gap')}; truth: {truth}")
                for named in out.get("named", []):
                    print(f"    named {named}")
                for group in out.get("ambiguous", []):
                    print(f"    ambiguous {group}")
                print(f"    quantised (not judged): {out.get('quantised')}")


if __name__ == "__main__":
    main()
