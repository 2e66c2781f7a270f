"""Robots at full size (issue 47): dp and vp whole-process CPU seconds beside FIGAROH's own
base parameters, interleaved in one process tree; dp and vp beside a FIGAROH-like yardstick in
this process; the defaults' memory (no refusal); how accurate the printed dp expressions are.

    pip install example-robot-data pin figaroh
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_full_size.py [--repeats 3] [--no-vp]
        [--sections figaroh identify speed memory accuracy] [--previous DIR ...]

figaroh: per round, for TX40 (examples/data/tx40), TIAGo and Talos (example-robot-data), one
child process each for FIGAROH, dp and vp, in turn (``--repeats`` rounds; medians): the
child's whole-process CPU s (user + system, from ``RUSAGE_CHILDREN``: the interpreter, the
imports, loading the URDF, the solve) and its peak RSS. FIGAROH 1.0.2 runs its own documented
path for base parameters: ``load_robot``, ``generate_waypoints`` (as many random states as dp's
W has samples: the mechanism file's trajectory), ``build_regressor_basic``,
``get_index_eliminate``/``build_regressor_reduced`` and ``get_baseParams`` (its double QR). Its
URDF is the same file with ``<visual>`` and ``<collision>`` removed (FIGAROH's loader reads the
meshes; TX40's are not shipped, and reading Talos' took 2.5 s: leaving them out favours
FIGAROH). FIGAROH takes a ``<mimic>`` follower as a joint of its own (a higher rank on Talos and
TIAGo); baseparams solves the coupled robot. Skipped with a note when figaroh is not installed.

identify: ``identify`` of TIAGo's 48-joint model with the default solver (vp) on a recording
simulated by ``bp.simulate`` (the file's trajectory, 1 % noise), in child processes, each round
one with the generated code's disk cache off and one with it on (filled before the rounds), the
package's bytecode compiled as an installed package's is, and one with the cache on and no
bytecode (each child compiling the modules it imports, as the editable tree does here):
identify's own CPU s and the whole process's, beside a yardstick measured in the same process
after identify (Pinocchio's regressor over as many random states and one least-squares solve);
with ``--previous DIR`` (``git archive COMMIT | tar -x -C DIR``) that older tree's code too, in
the same turns, imported in place of the installed package.

speed: per robot, interleaved ``--repeats`` times in this process (medians, CPU s of
``time.process_time``): dp, vp (Talos only; it is long), and the yardstick: what FIGAROH
does for base parameters, Pinocchio's joint-torque regressor stacked over as many random
states as dp's W has samples and one QR with column pivoting (scipy), its rank by the
tolerance ``max(shape) eps |R_11|``; FIGAROH itself is not run (not installed here). The
ratio is solver / yardstick. The robot is loaded once, outside the timings.

memory: the defaults of issue 47's refusals, each solve in a child process: rank, whether
certified, the child's whole-process CPU s and peak RSS.

accuracy: the sine of the largest principal angle between the printed dp base expressions'
row space and W at three independent random batches (columns scaled to unit norm,
tests/test_full_size.py), beside dp's estimate, dp's unrounded beta, and the rule before
issue 47 (each coefficient to the trajectory-only estimate) applied to the trajectory's beta.
"""

import argparse
import math
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))                      # tests/ is not a package

from urdf_reference import Reference, example_robot_data, robot_id  # noqa: E402

SPEED = ("tiago_description/tiago", "talos_data/talos_full_v2")
SIDE_BY_SIDE = ("tx40", "tiago_description/tiago", "talos_data/talos_full_v2")
TX40 = ROOT / "examples" / "data" / "tx40" / "tx40_mdh_modified.urdf"
VP = ("talos_data/talos_full_v2",)
MEMORY = (("tiago_description/tiago_dual", "dp"), ("pr2_description/pr2", "vp"))
ACCURACY = ("romeo_description/romeo", "romeo_description/romeo_laas_small", "pr2_description/pr2")


def paths() -> dict[str, Path]:
    found = {robot_id(p): p for p in example_robot_data()}
    if not found:
        sys.exit("example-robot-data is not installed (pip install example-robot-data)")
    return {**found, "tx40": TX40}


def cpu(function):
    start = time.process_time()
    out = function()
    return out, time.process_time() - start


def yardstick(ref: Reference, states: int) -> int:
    """FIGAROH's way: the stacked Pinocchio regressor and a pivoted QR; the rank."""
    import scipy.linalg
    w = ref.stacked_regressor(states, seed=3)
    _, r, _ = scipy.linalg.qr(w, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    return int(np.sum(d > max(w.shape) * np.finfo(float).eps * d[0]))


def speed(found: dict[str, Path], repeats: int, with_vp: bool) -> None:
    from baseparams.io.loader import load_mechanism
    from baseparams.solvers.run import run_solver
    print("| robot | params | yardstick rank | dp rank | vp rank | yardstick s | dp s | dp / yardstick | vp s | "
          "vp / yardstick |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in SPEED:
        mech, ref = load_mechanism(found[name]), Reference(found[name])
        states = mech.trajectory.samples
        times: dict[str, list[float]] = {"y": [], "dp": [], "vp": []}
        ranks: dict[str, object] = {}
        for _ in range(repeats):
            ranks["y"], t = cpu(lambda: yardstick(ref, states))
            times["y"].append(t)
            result, t = cpu(lambda: run_solver("dp", mech))
            ranks["dp"] = result.rank
            times["dp"].append(t)
            if with_vp and name in VP:
                result, t = cpu(lambda: run_solver("vp", mech))
                ranks["vp"] = f"{result.rank}" + ("" if result.certified else " (not certified)")
                times["vp"].append(t)
        y, dp = statistics.median(times["y"]), statistics.median(times["dp"])
        vp = statistics.median(times["vp"]) if times["vp"] else None
        print(f"| {name} | {len(mech.parameters)} | {ranks['y']} | {ranks['dp']} | {ranks.get('vp', '-')} | "
              f"{y:.2f} | {dp:.2f} | {dp / y:.2f}x | {'-' if vp is None else f'{vp:.1f}'} | "
              f"{'-' if vp is None else f'{vp / y:.1f}x'} |", flush=True)


BASEPARAMS_CHILD = """
import json, resource, sys
from baseparams.io.loader import load_mechanism
from baseparams.solvers.run import run_solver
r = run_solver(sys.argv[2], load_mechanism(sys.argv[1]))
print(json.dumps({"rank": r.rank, "certified": r.certified,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

FIGAROH_CHILD = """
import json, resource, sys, warnings
warnings.filterwarnings("ignore")
import numpy as np
from figaroh.tools.load_robot import load_robot
from figaroh.tools.randomdata import generate_waypoints
from figaroh.tools.regressor import build_regressor_basic, get_index_eliminate, build_regressor_reduced
from figaroh.identification.parameter import get_standard_parameters
from figaroh.tools.qrdecomposition import get_baseParams
robot = load_robot(sys.argv[1], load_by_urdf=True)
config = {"has_friction": False, "has_actuator_inertia": False, "has_joint_offset": False,
          "is_joint_torques": True, "is_external_wrench": False, "force_torque": None,
          "act_idxv": list(range(robot.model.nv))}
np.random.seed(3)
q, v, a = generate_waypoints(int(sys.argv[2]), robot, -1, 1)
W = build_regressor_basic(robot, q, v, a, config)
params_std = get_standard_parameters(robot.model, config)
idx_e, params_r = get_index_eliminate(W, params_std, 1e-6)
_, params_base, idx_base = get_baseParams(build_regressor_reduced(W, idx_e), params_r, params_std)
print(json.dumps({"rank": len(idx_base), "certified": False,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def without_geometry(path: Path, folder: Path) -> Path:
    """The URDF with its <visual> and <collision> elements removed (FIGAROH's loader reads meshes)."""
    import xml.etree.ElementTree as ET
    tree = ET.parse(path)
    for link in tree.getroot().iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    out = folder / path.name
    tree.write(out)
    return out


def child(args: list[str], env: dict[str, str | None] | None = None) -> tuple[dict, float]:
    """(the child's JSON line, its whole-process CPU s); ``env``: variables set for it (None:
    unset)."""
    import json
    import os
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    merged = None if env is None else {k: v for k, v in {**os.environ, **env}.items() if v is not None}
    proc = subprocess.run([sys.executable, "-c", *args], capture_output=True, text=True, env=merged)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    seconds = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    if proc.returncode:
        return {"error": (proc.stderr.strip().splitlines() or ["?"])[-1][:120]}, seconds
    return json.loads(proc.stdout.strip().splitlines()[-1]), seconds


def side_by_side(found: dict[str, Path], repeats: int) -> None:
    """FIGAROH, dp and vp, each in a child process, interleaved round by round."""
    import importlib.util
    import tempfile
    from baseparams.io.loader import load_mechanism
    have_figaroh = importlib.util.find_spec("figaroh") is not None
    if not have_figaroh:
        print("figaroh is not installed (pip install figaroh): FIGAROH's columns are empty")
    tools = (["figaroh"] if have_figaroh else []) + ["dp", "vp"]
    with tempfile.TemporaryDirectory() as tmp:
        runs: dict[tuple[str, str], list[tuple[dict, float]]] = {}
        plain = {name: without_geometry(found[name], Path(tmp)) for name in SIDE_BY_SIDE}
        samples = {name: load_mechanism(found[name]).trajectory.samples for name in SIDE_BY_SIDE}
        for _ in range(repeats):
            for name in SIDE_BY_SIDE:
                for tool in tools:
                    args = ([FIGAROH_CHILD, str(plain[name]), str(samples[name])] if tool == "figaroh" else
                            [BASEPARAMS_CHILD, str(found[name]), tool])
                    runs.setdefault((name, tool), []).append(child(args))
    print("| robot | FIGAROH rank | dp rank | vp rank | FIGAROH s | dp s | dp / FIGAROH | vp s | vp / FIGAROH | "
          "peak MB (FIGAROH, dp, vp) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in SIDE_BY_SIDE:
        out = {tool: runs[name, tool] for tool in tools}
        cpu_s = {tool: statistics.median(t for _, t in out[tool]) for tool in tools}
        last = {tool: out[tool][-1][0] for tool in tools}

        def rank(tool: str) -> str:
            if tool not in last:
                return "-"
            r = last[tool]
            return r.get("error", f"{r['rank']}" + (" certified" if r["certified"] else ""))

        fig = cpu_s.get("figaroh")
        ratio = {tool: "-" if not fig else f"{cpu_s[tool] / fig:.2f}x" for tool in ("dp", "vp")}
        peaks = ", ".join(f"{last[t].get('peak_mb', 0):.0f}" for t in tools)
        print(f"| {name} | {rank('figaroh')} | {rank('dp')} | {rank('vp')} | "
              f"{'-' if fig is None else f'{fig:.2f}'} | {cpu_s['dp']:.2f} | {ratio['dp']} | {cpu_s['vp']:.2f} | "
              f"{ratio['vp']} | {peaks} |", flush=True)


CHILD = """
import json, resource, sys, time
from baseparams.io.loader import load_mechanism
from baseparams.solvers.run import run_solver
r = run_solver(sys.argv[2], load_mechanism(sys.argv[1]), {"recover": False} if sys.argv[2] == "vp" else {})
print(json.dumps({"rank": r.rank, "certified": r.certified, "summary": r.diagnostics.summary}))
"""


def memory(found: dict[str, Path]) -> None:
    import json
    print("| robot | solver | rank | certified | whole-process CPU s | peak RSS MB | how |")
    print("|---|---|---|---|---|---|---|")
    for name, solver in MEMORY:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        proc = subprocess.run([sys.executable, "-c", CHILD, str(found[name]), solver], capture_output=True, text=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode:
            print(f"| {name} | {solver} | refused: {proc.stderr.strip().splitlines()[-1][:100]} |||||")
            continue
        out = json.loads(proc.stdout.strip().splitlines()[-1])
        how = next((line for line in out["summary"] if "memory limit" in line), "")
        print(f"| {name} | {solver} | {out['rank']} | {out['certified']} | "
              f"{after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime:.1f} | "
              f"{after.ru_maxrss / 1024:.0f} | {how[:140]} |", flush=True)


# a child importing baseparams from another copy of the source tree (``--previous``: git archive
# of an older commit): its core/, plugins/ and mechanisms/ stand in for the installed package
FROM_TREE = """
import importlib.util, sys
class _Tree:
    parts = {"baseparams": "core", "baseparams.plugins": "plugins", "baseparams.mechanisms": "mechanisms"}
    @classmethod
    def find_spec(cls, name, path=None, target=None):
        if name not in cls.parts:
            return None
        where = TREE + "/" + cls.parts[name]
        return importlib.util.spec_from_file_location(name, where + "/__init__.py", submodule_search_locations=[where])
TREE = sys.argv.pop()
sys.meta_path.insert(0, _Tree)
"""

IDENTIFY_CHILD = """
import json, resource, sys, time
import numpy as np
import baseparams as bp
start = time.process_time()
fit = bp.identify(sys.argv[1], sys.argv[2])
seconds = time.process_time() - start
out = fit.to_json()
yardstick = None
try:                                 # Pinocchio's regressor over as many states, and one least squares
    sys.path.insert(0, sys.argv[3])
    from urdf_reference import Reference
    ref = Reference(sys.argv[1])
    start = time.process_time()
    W = ref.stacked_regressor(out["samples"], seed=3)
    np.linalg.lstsq(W, W @ np.random.default_rng(3).standard_normal(W.shape[1]), rcond=None)
    yardstick = time.process_time() - start
except ImportError:
    pass
print(json.dumps({"identify_s": seconds, "yardstick_s": yardstick, "rank": out["rank"],
                  "rms_overall": out.get("rms_overall"),
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def identify_tiago(found: dict[str, Path], repeats: int, previous: Sequence[Path] = ()) -> None:
    """identify of TIAGo's 48-joint model (issue 47: <= 5 CPU s) with the default solver, on a
    simulated recording (bp.simulate: the file's trajectory, 1 % noise), in child processes
    taking turns: with the generated code's disk cache off (``BASEPARAMS_CACHE_DIR=off``: a
    first run, or a changed mechanism) and on (a cache in a temporary folder, filled by one run
    before the rounds: every later run of the same mechanism), both with the package's bytecode
    compiled once, as an installed package has it (``pip install`` compiles it; here
    PYTHONPYCACHEPREFIX in the temporary folder, filled by the same run), and with the cache on
    and no bytecode written (PYTHONDONTWRITEBYTECODE, as this machine's environment sets it for
    the editable tree: each child then compiles the hundred modules identify imports, 0.03-0.14
    CPU s more, measured). Per child: identify's own CPU s,
    the whole process's (the interpreter, the imports, identify; the yardstick's CPU s
    subtracted), and the yardstick measured after identify in the same process: Pinocchio's
    joint-torque regressor stacked over as many random states as the recording has samples,
    and one least-squares solve of it (numpy lstsq, SVD): what an uncertified identification
    cannot do without. ``previous``: copies of other source trees, each run in the same turns
    with the cache and bytecode on (their rows say "previous" and the folder). A copy of the
    tree being measured among them keeps its row's generated-code cache valid while others edit
    the working tree (the cache's key holds each module file's size and time)."""
    import tempfile
    import baseparams as bp
    urdf = str(found["tiago_description/tiago"])
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "tiago.csv"
        bp.simulate(urdf, output=str(data), noise=0.01)
        args = [IDENTIFY_CHILD, urdf, str(data), str(ROOT / "tests")]
        compiled = {"PYTHONDONTWRITEBYTECODE": None, "PYTHONPYCACHEPREFIX": str(Path(tmp) / "pycache")}
        folder = str(Path(tmp) / "cache")
        settings: dict[str, dict[str, str | None]] = {
            "off": {"BASEPARAMS_CACHE_DIR": "off", **compiled}, "on": {"BASEPARAMS_CACHE_DIR": folder, **compiled},
            "on, no bytecode": {"BASEPARAMS_CACHE_DIR": folder, "PYTHONDONTWRITEBYTECODE": "1"}}
        jobs = {name: (args, env) for name, env in settings.items()}
        for tree in previous:
            jobs[f"previous {tree}, on"] = ([FROM_TREE + IDENTIFY_CHILD, *args[1:], str(tree)], settings["on"])
        for name in ["on"] + [f"previous {tree}, on" for tree in previous]:      # fill the caches and the bytecode
            child(*jobs[name])
        runs: dict[str, list[tuple[dict, float]]] = {name: [] for name in jobs}
        for _ in range(repeats):
            for name, (job, env) in jobs.items():
                runs[name].append(child(job, env))
    print("| robot | joints | code cache | identify CPU s (median) | whole process CPU s | yardstick CPU s | "
          "identify / yardstick | base parameters | RMS | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for cache, done in runs.items():
        ok = [(out, t) for out, t in done if "error" not in out]
        if not ok:
            print(f"| tiago | 48 | {cache} | failed: {done[-1][0]['error']} |||||||")
            continue
        out = ok[-1][0]
        identify_s = statistics.median(o["identify_s"] for o, _ in ok)
        yards = [o["yardstick_s"] for o, _ in ok if o["yardstick_s"] is not None]
        yard = statistics.median(yards) if yards else None
        whole = statistics.median(t - (o["yardstick_s"] or 0.0) for o, t in ok)      # the yardstick's time left out
        print(f"| tiago_description/tiago | 48 | {cache} | {identify_s:.2f} | {whole:.2f} | "
              f"{'-' if yard is None else f'{yard:.2f}'} | {'-' if yard is None else f'{identify_s / yard:.1f}x'} | "
              f"{out['rank']} | {out['rms_overall']:.3g} | {out['peak_mb']:.0f} |", flush=True)


def old_rule_rows(g, n: int) -> np.ndarray:
    """The printed rows by the rule before issue 47: each coefficient to
    floor(log10(|beta_s| / estimate)) digits, dropped at or below the estimate."""
    noise = max(g.error_estimate, np.finfo(float).eps)
    most = int(min(16, math.floor(-math.log10(noise))))
    B = np.zeros((g.rank, n))
    for a, i in enumerate(g.kept):
        B[a, i] = 1.0
        for b, j in enumerate(g.eliminated):
            value, scaled = g.beta[a, b], abs(g.beta_s[a, b])
            if value == 0 or scaled <= noise:
                continue
            digits = min(most, math.floor(math.log10(scaled / noise)))
            if digits >= 1:
                B[a, j] = float(f"{value:.{digits}g}")
    return B


def unrounded_rows(g, n: int) -> np.ndarray:
    B = np.zeros((g.rank, n))
    for a, i in enumerate(g.kept):
        B[a, i] = 1.0
        B[a, g.eliminated] = g.beta[a]
    return B


def accuracy(found: dict[str, Path]) -> None:
    from test_full_size import reference_w, row_space_angle, rows_of

    from baseparams.dynamics.excitation import random_batch
    from baseparams.dynamics.observation import observation_matrix
    from baseparams.dynamics.trajectory import Trajectory
    from baseparams.io.loader import load_mechanism
    from baseparams.numeric.backends import Float64
    from baseparams.plugins.solvers.dp.gautier import dp_gautier
    from baseparams.solvers.run import run_solver
    print("| robot | rank | printed | dp's estimate | printed / estimate | unrounded (W + batch) | "
          "before: printed | before: estimate (W alone) | before: unrounded (W alone) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ACCURACY:
        mech = load_mechanism(found[name])
        result = run_solver("dp", mech).to_json()
        W = reference_w(mech)
        n = len(mech.parameters)
        trajectory = Trajectory.default(mech, memory=False)
        W0 = observation_matrix(mech, Float64(), trajectory)[0]
        alone = dp_gautier(W0)
        both = dp_gautier(np.vstack([W0, observation_matrix(mech, Float64(), random_batch(mech, trajectory, 7919))[0]]))
        printed, estimate = row_space_angle(rows_of(result), W), result["diagnostics"]["beta_error_estimate"]
        print(f"| {name} | {result['rank']} | {printed:.2g} | {estimate:.2g} | {printed / estimate:.2g} | "
              f"{row_space_angle(unrounded_rows(both, n), W):.2g} | "
              f"{row_space_angle(old_rule_rows(alone, n), W):.2g} | {alone.error_estimate:.2g} | "
              f"{row_space_angle(unrounded_rows(alone, n), W):.2g} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-vp", action="store_true", help="no vp in the speed section")
    parser.add_argument("--sections", nargs="*", default=("figaroh", "identify", "speed", "memory", "accuracy"))
    parser.add_argument("--previous", type=Path, nargs="*", default=(), help="identify: also copies of other "
                        "source trees (core/, plugins/, mechanisms/: git archive COMMIT | tar -x -C DIR), each "
                        "in the same turns")
    args = parser.parse_args()
    found = paths()
    if "figaroh" in args.sections:
        side_by_side(found, args.repeats)
        print()
    if "identify" in args.sections:
        identify_tiago(found, args.repeats, args.previous)
        print()
    if "speed" in args.sections:
        speed(found, args.repeats, not args.no_vp)
    if "memory" in args.sections:
        print()
        memory(found)
    if "accuracy" in args.sections:
        print()
        accuracy(found)


if __name__ == "__main__":
    main()
