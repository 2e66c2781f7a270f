"""What changed between recordings (``diagnose CHANGED --baseline BASE``), measured on
simulated pairs of runs with a known truth (core/recordings/simulate.py, simulate_change):
the same trajectory recorded twice, model errors common to both sides (a smooth Coulomb law,
viscous friction, a 2-sample delay: none of them in the model), independent white, AR(1)
0.9 or low-passed noise at 1 % of each coordinate's RMS torque, and between the runs a
payload of 5-50 % of the last body's mass, a viscous-friction drift, or nothing.

Printed per scenario: the datasets with the right names (payload: named on the right body
alone; friction: viscous friction on the drifted coordinate alone; nothing: "nothing
changed") and, for a payload, with its mass within 5 % too, and within 2 of its own std (the
std is honest: the 5 % is then what the noise allows), the median text report's lines, and
the speed figure: CPU seconds of one diagnosis between recordings against one ``identify``
of the changed runs (the shared effects on every coordinate) in the same process.

    python benchmarks/bench_diagnose_change.py [--seeds 20] [--samples 5000] [--mechanism puma560]
    python benchmarks/bench_diagnose_change.py --mechanism tests/data/urdf/ur5.urdf --samples 1000 \
        --payload-mass 0.48 --load-friction 0.1 --quantum 0.01 --noise ar1 --seeds 6 --scenarios payload
"""

import argparse
import tempfile
import time
from pathlib import Path
import warnings

import numpy as np

from baseparams.api.render import change_text
from baseparams.diagnose.change import diagnose_change, shared_effects
from baseparams.recordings.simulate import simulate_change
from baseparams.io.loader import resolve


def rigidly_joined(mechanism, label: int) -> set[str]:
    """The names of ``label``'s body and of the bodies fixed to it (a payload on a tool frame
    is a payload on the link it is fixed to: their columns are the same)."""
    from baseparams.diagnose.derived import body_name
    group, grew = {label}, True
    while grew:
        grew = False
        for joint in mechanism.joints:
            if not joint.coordinates and (joint.parent in group) != (joint.child in group):
                group |= {joint.parent, joint.child}
                grew = True
    moving = {b.label for b in mechanism.bodies}
    return {body_name(mechanism, b) for b in group if b in moving}


def judge(result, truth, scenario: str, last: set[str]) -> tuple[bool, bool, bool]:
    """(the right names and nothing else, and for a payload its mass within 5 % too, and
    within 2 of its own std: whether the std is honest, whatever the noise allows)."""
    names = [(e["kind"], e["coordinate"]) for e in result.changes]
    if scenario == "nothing":
        ok = result.verdict == "nothing changed"
        return ok, ok, ok
    if scenario == "friction":
        ok = names == [("viscous_friction", truth["friction_drift"]["coordinate"])] and not result.ambiguous
        return ok, ok, ok
    if len(names) != 1 or names[0][0] not in ("body", "mass") or names[0][1] not in last or result.ambiguous:
        return False, False, False
    m = result.changes[0]["coefficients"]["m"]
    true = truth["payload"]["mass"]
    if m["value"] is None:
        return True, False, False
    return True, abs(m["value"] - true) <= 0.05 * true, abs(m["value"] - true) <= 2 * m["std"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--samples", type=int, default=5000)
    parser.add_argument("--mechanism", default="puma560")
    parser.add_argument("--noise", nargs="+", default=["white", "ar1", "lowpass"])
    parser.add_argument("--payloads", nargs="+", type=float, default=[0.05, 0.1, 0.25, 0.5])
    parser.add_argument("--payload-mass", type=float, default=None,
                        help="one payload in kg instead of --payloads (a last body of no mass)")
    parser.add_argument("--load-friction", type=float, default=0.0, help="gear load friction mu, common to both runs")
    parser.add_argument("--quantum", type=float, default=0.0, help="torques rounded to this step (N m)")
    parser.add_argument("--scenarios", nargs="+", default=["nothing", "payload", "friction"])
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    mechanism = resolve(args.mechanism)
    last = rigidly_joined(mechanism, mechanism.bodies[-1].label)
    payloads = [(f"payload {p:g}", {"payload": p}) for p in args.payloads] if args.payload_mass is None else \
        [(f"payload {args.payload_mass:g} kg", {"payload_mass": args.payload_mass})]
    scenarios = [("nothing", {})] * ("nothing" in args.scenarios) + payloads * ("payload" in args.scenarios) + \
        [("friction", {"friction_drift": 0.1, "drift_coordinate": 1})] * ("friction" in args.scenarios)
    common = {"load_friction": args.load_friction, "quantum": args.quantum}
    print(f"{args.mechanism}, {args.samples} samples per run, {args.seeds} seeds per cell")
    print(f"{'scenario':<14} {'noise':<8} {'names':>7} {'+mass':>7} {'+2 std':>7} {'lines':>6} {'CPU s':>7}  wrong names")
    for name, change in scenarios:
        for noise in args.noise:
            named, right, honest, lines, wrong, cpu = 0, 0, 0, [], [], []
            for seed in range(args.seeds):
                before, after, truth = simulate_change(mechanism, samples=args.samples, seed=seed, noise=noise,
                                                       **change, **common)
                start = time.process_time()
                result = diagnose_change(mechanism, before, after)
                spent = time.process_time() - start
                cpu.append(spent)
                lines.append(len(change_text(result).splitlines()))
                names_right, all_right, within = judge(result, truth, name.split()[0], last)
                named += names_right
                right += all_right
                honest += within
                if not names_right:
                    wrong.append(f"{seed}: {result.verdict} "
                                 + ",".join(f"{e['kind']}:{e['coordinate']}" for e in result.changes))
            print(f"{name:<14} {noise:<8} {named:>3}/{args.seeds:<3} {right:>3}/{args.seeds:<3} "
                  f"{honest:>3}/{args.seeds:<3} {int(np.median(lines)):>6} "
                  f"{np.median(cpu):>7.2f}  {'; '.join(wrong[:4])}", flush=True)
    if args.payload_mass is None:
        speed(mechanism, args.samples)


def speed(mechanism, samples: int, repeats: int = 3) -> None:
    """diagnose --baseline, and diagnose --params (the baseline's identify held), against one
    identify of the changed runs (with the shared effects), all from CSV files through the
    Python API, CPU s in this process, ``repeats`` times each (medians)."""
    import json
    import baseparams as bp
    from baseparams.recordings.data import write_measured
    name = mechanism.path or mechanism.name
    with tempfile.TemporaryDirectory() as folder:
        before, after, _ = simulate_change(mechanism, samples=samples, seed=0, payload=0.25)
        base, changed = Path(folder) / "base.csv", Path(folder) / "changed.csv"
        held = Path(folder) / "base.json"
        write_measured(base, before)
        write_measured(changed, after)
        effects = [f"{e.kind}:{e.coordinate}" for e in shared_effects(mechanism)]
        held.write_text(json.dumps(bp.identify(name, str(base), effects=effects).to_json()))
        bp.identify(name, str(changed), effects=effects)      # warm the caches
        times: dict[str, list[float]] = {"diagnose --baseline": [], "diagnose --params": [], "identify": []}
        for _ in range(repeats):
            start = time.process_time()
            bp.identify(name, str(changed), effects=effects)
            times["identify"].append(time.process_time() - start)
            start = time.process_time()
            bp.diagnose(name, str(changed), baseline=str(base))
            times["diagnose --baseline"].append(time.process_time() - start)
            start = time.process_time()
            bp.diagnose(name, str(changed), params=str(held))
            times["diagnose --params"].append(time.process_time() - start)
    i = np.median(times["identify"])
    print(f"speed ({samples} samples x {len(after.coordinates)} coordinates per run), identify {i:.2f} CPU s:")
    for verb in ("diagnose --baseline", "diagnose --params"):
        d = np.median(times[verb])
        print(f"  {verb}: {d:.2f} CPU s, ratio {d / i:.2f} (target <= 5)")


if __name__ == "__main__":
    main()
