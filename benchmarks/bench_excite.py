"""The figures of docs/excite.md: `baseparams excite` on the TX40, the UR5 and the SLA, the
discrimination campaign with `diagnose`, and the speed (one 6-dof start, multistart on 1
and 2 worker processes in the same run).

    python benchmarks/bench_excite.py [--parts condition,sla,separate,speed,robots,never_worse] [--data ../shared/data/tx40]

Issue 43 (plans a robot can run): ``--parts robots`` plans the UR5 (example-robot-data, its
SRDF) and the TX40 at the defaults and checks the written files independently with Pinocchio
+ coal on the original meshes at ten times their sampling (lowest point above the base plane,
smallest distance between links the SRDF leaves in, every URDF limit, efforts by RNEA),
with the CPU seconds, the collision check's share and a yardstick measured in the same run;
``--parts never_worse`` runs the four-bar and the SLA with every solver.

Condition numbers are those identify reports (equal noise weights, unit-norm columns, on the
base the dp solver gives for the file it is computed on); "before" is the file's own
trajectory, "recorded" the TX40's real recording read through examples/tx40/recording.toml,
"random" as many independent random states inside the same limits as the motion has samples.
Every limit is checked again here on the written file's own expressions at ten times its
sampling. The discrimination campaign simulates data with one hidden effect (ratio 5 to the
noise, noise 2 % of each coordinate's RMS inertial force, random physical inertias) on a
motion that cannot tell the pair apart and on the motion planned with --separate, and counts
how often `diagnose` names the hidden effect and nothing else.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")     # small matrices: BLAS threads only contend
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from click.testing import CliRunner  # noqa: E402

from baseparams import registry  # noqa: E402
from baseparams.cli import main as cli  # noqa: E402
from baseparams.dynamics.trajectory import values_at  # noqa: E402
from baseparams.excite import design  # noqa: E402
from baseparams.excite.limits import limits_of  # noqa: E402
from baseparams.excite.plan import Settings, plan  # noqa: E402
from baseparams.identify.base import BaseModel  # noqa: E402
from baseparams.diagnose.problem import prepare  # noqa: E402
from baseparams.diagnose.workflow import diagnose  # noqa: E402
from baseparams.identify.fit import identify  # noqa: E402
from baseparams.dynamics.forces import Motion, design as model_design, evaluate  # noqa: E402
from baseparams.recordings.recording import read_data  # noqa: E402
from baseparams.recordings.simulate import random_physical_inertia  # noqa: E402
from baseparams.io.loader import load_mechanism, resolve  # noqa: E402
from baseparams.model.mechanism import EffectSpec  # noqa: E402
from baseparams.numeric.backends import Float64  # noqa: E402
from baseparams.orchestrate.jobs import MechanismText  # noqa: E402
from baseparams.orchestrate.runners import InProcess, Processes  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _base(mechanism, solver="dp"):
    return BaseModel.from_result(registry.solvers()[solver].item.solve(mechanism), mechanism)


def ur5_path() -> Path:
    """example_robot_data's UR5 (its installed files), else the project's test copy."""
    try:
        from importlib.metadata import files
        for f in files("example-robot-data") or ():
            if str(f).endswith("ur_description/urdf/ur5_robot.urdf"):
                return Path(f.locate())
    except Exception:
        pass
    return ROOT / "tests" / "data" / "urdf" / "ur5.urdf"


def excite(*args) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        report = Path(folder) / "r.json"
        out = Path(folder) / "m.toml"
        result = CliRunner().invoke(cli, ["excite"] + [str(a) for a in args] + ["-o", str(out), "--report", str(report), "--quiet"])
        if result.exit_code != 0:
            raise SystemExit(f"excite failed: {result.output}")
        data = json.loads(report.read_text())
        data["written"] = out.read_text()
        return data


def limits_hold(text: str, suffix: str, limits, factor: int = 10) -> float:
    """The smallest margin (>= 0: every limit holds) of the written file's trajectory at
    ``factor`` times its sampling, from its own expressions."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"m{suffix}"
        path.write_text(text)
        mech = load_mechanism(path)
    spec = mech.trajectory
    t = np.linspace(float(spec.t_start), float(spec.t_end), factor * (spec.samples - 1) + 1)
    worst = np.inf
    for k, name in enumerate(limits.names):
        q, qd, qdd = (np.broadcast_to(v, t.shape) for v in values_at(spec.expressions[name], Float64(), t))
        worst = min(worst, np.min(q - limits.lower[k]), np.min(limits.upper[k] - q),
                    limits.velocity[k] - np.max(np.abs(qd)), limits.acceleration[k] - np.max(np.abs(qdd)))
    return float(worst)


def identify_condition(text: str, suffix=".toml") -> float:
    """identify's condition number on noisy data simulated along the file's trajectory."""
    from baseparams.recordings.simulate import simulate
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"m{suffix}"
        path.write_text(text)
        mech = load_mechanism(path)
    data, _ = simulate(mech, noise_sd=0.05, seed=1)
    return identify(mech, data, base=_base(mech)).condition_number


def recorded_condition(data_dir: Path) -> float:
    mechanism = load_mechanism(data_dir / "tx40_mdh_modified.urdf")
    text = (ROOT / "examples" / "tx40" / "recording.toml").read_text()
    text = text.replace("../../../shared/data/tx40/", f"{data_dir}/")
    with tempfile.TemporaryDirectory() as folder:
        description = Path(folder) / "recording.toml"
        description.write_text(text)
        data, model = read_data([str(description)], mechanism)
        return identify(model, data, base=_base(mechanism)).condition_number


def part_condition(args):
    print("## condition numbers (identify's definition)\n")
    print("| robot | before | after | identify on the written file | random states | recorded | "
          "margin at 10x (>= 0) | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    tx40 = Path(args.data) / "tx40_mdh_modified.urdf"
    if not tx40.exists():
        tx40 = ROOT / "tests" / "data" / "tx40" / "tx40_mdh_modified.urdf"
    robots = [("TX40 (URDF limits)", tx40, []),
              ("UR5 (example_robot_data), +-pi", ur5_path(), ["--position-range", "-3.14159:3.14159"])]
    for label, path, extra in robots:
        start = time.process_time()
        report = excite(path, "--starts", str(args.starts), *extra)
        cpu = time.process_time() - start
        mech = load_mechanism(path)
        limits = limits_of(mech, positions=extra[1] if extra else None)
        margin = limits_hold(report["written"], ".toml", limits)
        recorded = recorded_condition(Path(args.data)) if "TX40" in label and Path(args.data).exists() else None
        print(f"| {label} | {report['before']['condition_number']:.3g} | {report['after']['condition_number']:.3g} | "
              f"{identify_condition(report['written']):.3g} | {report['random_states']['condition_number']:.3g} | "
              f"{'-' if recorded is None else f'{recorded:.3g}'} | {margin:.3g} | {cpu:.0f} |")


def part_sla(args):
    print("\n## SLA suspension\n")
    print("| singularity margin | before | after | random states | nearest 1/cond reached | vp rank (certified) | "
          "CPU s |")
    print("|---|---|---|---|---|---|---|")
    for margin in args.margins:
        start = time.process_time()
        report = excite("sla_suspension", "--starts", "1", "--singularity-margin", str(margin))
        cpu = time.process_time() - start
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "sla.toml"
            path.write_text(report["written"])
            result = registry.solvers()["vp"].item.solve(load_mechanism(path))
        reached = report["verified"]["margins"]["singularity"] + margin
        print(f"| {margin} | {report['before']['condition_number']:.3g} | {report['after']['condition_number']:.3g} | "
              f"{report['random_states']['condition_number']:.3g} | {reached:.3g} | {result.rank} "
              f"({result.certified}) | {cpu:.0f} |")
        for note in report["notes"]:
            print(f"  note: {note}")


# ----- discrimination --------------------------------------------------------------------------
def _outcome(d, truth) -> str:
    """'right' (the truth named, nothing else), 'right+extra' (the truth named and another
    effect too), 'ambiguous' (the truth in an ambiguous group, no name), 'wrong' (another
    effect named instead), 'none'."""
    out = d.to_json()
    named = {(e["kind"], e["coordinate"]) for e in out["effects"]}
    groups = [{(c["kind"], c["coordinate"]) for c in a["candidates"]} for a in out["ambiguous"]]
    if truth in named:
        return "right" if named == {truth} else "right+extra"
    if named:
        return "wrong"
    if any(truth in g for g in groups):
        return "ambiguous"
    return "none"


def campaign(mechanism, motion: Motion, truth: tuple, runs: int, seed: int = 0) -> dict:
    """``runs`` datasets on ``motion`` with the effect ``truth`` hidden at ratio 5."""
    sample = evaluate(mechanism, motion)
    inertial, columns = model_design(mechanism, motion, [EffectSpec(*truth)], sample)
    problem = prepare(mechanism, motion, sample)
    counts = {"right": 0, "right+extra": 0, "ambiguous": 0, "wrong": 0, "none": 0}
    rng = np.random.default_rng(seed)
    q = motion.q[:, list(mechanism.independent or mechanism.coordinates).index(truth[1])]
    for _ in range(runs):
        clean = inertial.matrix @ random_physical_inertia(mechanism, rng)
        sd = 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        theta = rng.uniform(0.5, 1.5, size=columns.matrix.shape[-1])
        if truth[0] == "offset":
            theta *= rng.choice([-1, 1])
        if truth[0] == "spring":
            theta[1] = theta[0] * (np.mean(q) + 0.1 * np.std(q))
        force = columns.matrix @ theta
        force *= 5 / np.max(np.sqrt(np.mean(force ** 2, axis=0)) / sd)
        tau = clean + force + rng.standard_normal(clean.shape) * sd
        counts[_outcome(diagnose(problem, tau), truth)] += 1
    return counts


def bad_motion(kind: str, t: np.ndarray) -> Motion:
    """planar_2r motions that cannot tell the pair apart: q1 with constant-sign velocity
    ("ramp"), or q2 barely moving ("still")."""
    q1 = 0.9 * np.sin(0.8 * t) + 0.4 * np.sin(2.1 * t + 0.3)
    d1 = 0.72 * np.cos(0.8 * t) + 0.84 * np.cos(2.1 * t + 0.3)
    a1 = -0.576 * np.sin(0.8 * t) - 1.764 * np.sin(2.1 * t + 0.3)
    q2 = 1.1 * np.sin(1.3 * t + 0.5) + 0.3 * np.sin(3.7 * t)
    d2 = 1.43 * np.cos(1.3 * t + 0.5) + 1.11 * np.cos(3.7 * t)
    a2 = -1.859 * np.sin(1.3 * t + 0.5) - 4.107 * np.sin(3.7 * t)
    if kind == "ramp":
        q1, d1, a1 = -1.5 + 0.3 * t + 0.1 * np.sin(2 * t), 0.3 + 0.2 * np.cos(2 * t), -0.4 * np.sin(2 * t)
    else:
        q2, d2, a2 = 0.4 + 0.01 * np.sin(1.3 * t), 0.013 * np.cos(1.3 * t), -0.0169 * np.sin(1.3 * t)
    return Motion(t, np.stack([q1, q2], 1), np.stack([d1, d2], 1), np.stack([a1, a2], 1))


def part_separate(args):
    print("\n## discrimination: diagnose names the hidden effect (and nothing else)\n")
    print("| pair | hidden | motion | named (right + right+extra) | right | right+extra | ambiguous | wrong | "
          "none | smallest angle (deg) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    mechanism = resolve("planar_2r")
    path = Path(mechanism.path)
    base = _base(mechanism)
    cases = [("viscous vs Coulomb, constant-sign velocity", "ramp", ("viscous_friction", "q1"),
              (("viscous_friction", "q1"), ("coulomb_friction", "q1"))),
             ("viscous vs Coulomb, constant-sign velocity", "ramp", ("coulomb_friction", "q1"),
              (("viscous_friction", "q1"), ("coulomb_friction", "q1"))),
             ("spring vs gravity, barely moving joint", "still", ("spring", "q2"), (("spring", "q2"),)),
             ("offset vs spring", "still", ("offset", "q2"), (("spring", "q2"), ("offset", "q2"))),
             ("offset vs spring", "still", ("spring", "q2"), (("spring", "q2"), ("offset", "q2")))]
    t = np.linspace(0, 10, args.samples)
    for label, kind, truth, pair in cases:
        limits = limits_of(mechanism)
        settings = Settings(samples=args.samples, criterion="separation", separate=pair)
        found = plan(mechanism, MechanismText.read(mechanism.name, path), base, limits, settings, starts=2,
                     rebase=_base)
        tq, tqd, tqdd = found.problem.form.motion(found.x, found.problem.times())
        designed = Motion(found.problem.times(), tq, tqd, tqdd)
        before_angle = design.check(found.problem, *(lambda m: (m.q, m.qd, m.qdd))(bad_motion(kind, t))).angle
        for name, motion, angle in (("today's", bad_motion(kind, t), before_angle),
                                    ("planned", designed, found.after.angle)):
            counts = campaign(mechanism, motion, truth, args.runs)
            total = sum(counts.values())
            named = counts["right"] + counts["right+extra"]
            print(f"| {label} | {truth[0]} | {name} | {100 * named / total:.1f} % | "
                  + " | ".join(f"{100 * counts[k] / total:.0f} %" for k in ("right", "right+extra", "ambiguous",
                                                                            "wrong", "none"))
                  + f" | {angle:.3g} |")


def part_speed(args):
    print("\n## speed\n")
    mechanism = load_mechanism(ur5_path())
    base = _base(mechanism)
    limits = limits_of(mechanism, positions="-3.14159:3.14159")
    text = MechanismText.read(mechanism.name, Path(mechanism.path))
    settings = Settings(harmonics=5, samples=100, maxiter=200)
    start, wall = time.process_time(), time.perf_counter()
    one = plan(mechanism, text, base, limits, settings, starts=1)
    cpu, wall = time.process_time() - start, time.perf_counter() - wall
    print(f"UR5, 5 harmonics, 1 start, 200 SLSQP iterations: {cpu:.1f} CPU s ({wall:.1f} s wall), "
          f"condition number {one.after.condition:.3g}")
    # yardstick: the same number of SVDs of the observation matrix, measured in this run
    q, qd, qdd = one.problem.form.motion(one.x, one.problem.times())
    matrix = one.problem.model.columns(q, qd, qdd).matrix.reshape(-1, base.rank)
    start = time.process_time()
    for _ in range(200):
        np.linalg.svd(matrix, full_matrices=False)
    print(f"  yardstick: 200 SVDs of the {matrix.shape[0]} x {matrix.shape[1]} matrix: "
          f"{time.process_time() - start:.2f} CPU s")
    walls = {}
    for label, runner in (("1 worker (in process)", InProcess()), ("2 worker processes", Processes(2))):
        start = time.perf_counter()
        found = plan(mechanism, text, base, limits, settings, starts=4, runner=runner)
        walls[label] = time.perf_counter() - start
        print(f"  4 starts, {label}: {walls[label]:.1f} s wall, best condition number {found.after.condition:.3g}")
    print(f"  ratio 1 worker / 2 workers: {walls['1 worker (in process)'] / walls['2 worker processes']:.2f}")


def _independent(written: Path, urdf: Path, srdf: Path | None) -> dict:
    """Pinocchio + coal on the original meshes (not excite's hulls), ten times the written
    file's sampling: the lowest point of any moving link (mesh vertices, else frame origins),
    the smallest distance of the pairs the SRDF leaves in, the largest |tau| / effort and
    |qd| / velocity limit."""
    import pinocchio as pin
    from baseparams.excite.collision import package_dirs
    mechanism = load_mechanism(written)
    spec = mechanism.trajectory
    t = np.linspace(0, float(spec.t_end), 10 * (spec.samples - 1) + 1)
    values = [values_at(spec.expressions[n], Float64(), t) for n in mechanism.independent]
    q, qd, qdd = (np.stack([np.broadcast_to(np.asarray(v[k], float), t.shape) for v in values], axis=1)
                  for k in range(3))
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    try:
        geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION,
                                         package_dirs=list(package_dirs(str(urdf))))
        geometry.addAllCollisionPairs()
        if srdf is not None:
            pin.removeCollisionPairs(model, geometry, str(srdf))
        gdata = pin.GeometryData(geometry)
    except Exception:
        geometry = None
    lowest, nearest, effort = np.inf, np.inf, 0.0
    for k in range(len(t)):
        pin.framesForwardKinematics(model, data, q[k])
        lowest = min(lowest, min(data.oMf[f].translation[2] for f in range(model.nframes)
                                 if model.frames[f].parentJoint > 0))
        if geometry is not None:
            pin.updateGeometryPlacements(model, data, geometry, gdata)
            pin.computeDistances(geometry, gdata)
            nearest = min(nearest, min(r.min_distance for r in gdata.distanceResults))
            for g, obj in enumerate(geometry.geometryObjects):
                if obj.parentJoint > 0 and hasattr(obj.geometry, "vertices"):
                    placed = np.asarray(obj.geometry.vertices()) @ gdata.oMg[g].rotation.T + gdata.oMg[g].translation
                    lowest = min(lowest, placed[:, 2].min())
        effort = max(effort, float(np.max(np.abs(pin.rnea(model, data, q[k], qd[k], qdd[k])) / model.effortLimit)))
    return {"lowest": float(lowest), "nearest": float(nearest) if geometry is not None else None,
            "effort": effort, "velocity": float(np.max(np.abs(qd) / model.velocityLimit)),
            "position_ok": bool(np.all(q >= model.lowerPositionLimit) and np.all(q <= model.upperPositionLimit))}


def part_robots(args):
    """Issue 43: the default plans of the UR5 and the TX40, checked independently."""
    import baseparams as bp
    from baseparams.excite import collision
    ur5 = ur5_path()
    srdf = ur5.parents[1] / "srdf" / "ur5.srdf"
    tx40 = Path(args.data) / "tx40_mdh_modified.urdf"
    if not tx40.exists():
        tx40 = ROOT / "tests" / "data" / "tx40" / "tx40_mdh_modified.urdf"
    rng = np.random.default_rng(0)
    A = rng.standard_normal((600, 36))
    began = time.process_time()
    for _ in range(200):
        np.linalg.svd(A, compute_uv=False)
    yardstick = time.process_time() - began
    spent = [0.0]
    original = collision.Scene.distances

    def timed(self, *a, **k):
        start = time.process_time()
        try:
            return original(self, *a, **k)
        finally:
            spent[0] += time.process_time() - start

    collision.Scene.distances = timed
    print("## issue 43: default plans, checked by Pinocchio + coal on the original meshes at 10x\n")
    print("| robot | before -> after (vp) | converged | lowest point above the base plane (m) | smallest "
          "distance between links (m) | max effort / limit | max velocity / limit | CPU s | collision share |")
    print("|---|---|---|---|---|---|---|---|---|")
    try:
        for label, urdf, extra in (("UR5 (example-robot-data, SRDF)", ur5, {"srdf": str(srdf)} if srdf.exists() else {}),
                                   ("TX40 (no meshes: frame origins)", tx40, {})):
            with tempfile.TemporaryDirectory() as folder:
                out = Path(folder) / "plan.toml"
                spent[0] = 0.0
                start = time.process_time()
                result = bp.excite(str(urdf), output=str(out), **extra)
                cpu = time.process_time() - start
                plan_ = result.plan
                check = _independent(out, urdf, srdf if extra else None)
            nearest = "not checked (no geometry)" if check["nearest"] is None else f"{check['nearest']:.4f}"
            print(f"| {label} | {plan_.before.condition:.3g} -> {plan_.after.condition:.3g} | "
                  f"{'yes' if plan_.converged else 'no'} | {check['lowest']:.4f} | {nearest} | {check['effort']:.3f} | "
                  f"{check['velocity']:.3f} | {cpu:.1f} | {spent[0] / cpu:.0%} |")
    finally:
        collision.Scene.distances = original
    print(f"\nyardstick (same run): 200 SVDs of a 600 x 36 matrix: {yardstick:.2f} CPU s\n")


def part_never_worse(args):
    """Issue 43: the closed loops with every solver: the returned motion is never worse than the start."""
    import baseparams as bp
    print("## never worse than the start (closed loops, every solver; 1 start, 60 iterations)\n")
    print("| mechanism | solver | before | optimised | returned | improved | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for mech in ("four_bar", "sla_suspension"):
        for solver in ("vp", "dp", "symbolic", "exact"):
            start = time.process_time()
            try:
                found = bp.excite(mech, solver=solver, starts=1, iterations=60).plan
            except Exception as exc:                          # not applicable (exact on closed loops)
                print(f"| {mech} | {solver} | - | - | - | {type(exc).__name__}: {str(exc)[:60]} | - |")
                continue
            returned = found.before if found.kept == "the file's trajectory" else found.after
            print(f"| {mech} | {solver} | {found.before.condition:.3g} | {found.after.condition:.3g} | "
                  f"{returned.condition:.3g} | {found.improved} | {time.process_time() - start:.1f} |")
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="condition,sla,separate,speed")
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "tx40"))
    parser.add_argument("--starts", type=int, default=4)
    parser.add_argument("--runs", type=int, default=40, help="datasets per discrimination case")
    parser.add_argument("--samples", type=int, default=200, help="samples of the discrimination motions")
    parser.add_argument("--margins", type=float, nargs="+", default=[0.03])
    args = parser.parse_args()
    parts = {"condition": part_condition, "sla": part_sla, "separate": part_separate, "speed": part_speed,
             "robots": part_robots, "never_worse": part_never_worse}
    for name in args.parts.split(","):
        parts[name](args)


if __name__ == "__main__":
    main()
