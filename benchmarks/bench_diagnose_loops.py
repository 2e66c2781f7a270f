"""What changed on a closed-chain arm (issue 49 part 2): ``diagnose --baseline`` on simulated
pairs of runs of ``parallelogram_arm`` (a double parallelogram, two loops, and a cable-driven
counterweight), a load added on one parallelogram link between them, or nothing.

Pairs are made by core/recordings/simulate.py (simulate_change): the default trajectory
recorded twice, model errors common to both runs (a smooth Coulomb law, viscous friction, a
2-sample delay), independent coloured noise (AR(1) 0.9 by default) at 1 % of each
coordinate's RMS torque, and a point load of ``--mass`` kg within 5 cm of a point of the
link: the frame's origin of the top and bottom beams and of the end link (each moves with
the loop), the middle of the back and front links (their origins are fixed pivots on the yaw
link, where a load moves nothing).

Printed per scenario, out of the seeds: "named" (the truth's link is the change named or one
of its stated equivalents, and nothing else is named), "+mass" (that link's mass within
``--tolerance`` of the truth, 10 %; on the back and front links, which turn about fixed
pivots, its first moments, what the data fix there), "first" (the change is named on the truth's link itself),
the CPU seconds of a diagnosis (median), and the failures. "nothing": the verdict is
"nothing changed".

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_diagnose_loops.py [--seeds 20] [--samples 2000]
        [--links pitch_top pitch_bottom pitch_end pitch_back pitch_front] [--noise ar1 white lowpass]
"""

import argparse
import time
import warnings

import numpy as np

from baseparams.diagnose.change import ChangeDiagnosis, diagnose_change
from baseparams.diagnose.derived import body_name
from baseparams.io.loader import resolve
from baseparams.recordings.simulate import simulate_change

# where on each link the load sits (body axes), the middle where the frame's origin is a fixed pivot
WHERE = {"pitch_back": (0.0, 0.0, 0.15), "pitch_front": (0.0, 0.0, 0.15)}


def judge(result: ChangeDiagnosis, link: str | None, mass: float, centre: list[float], tolerance: float
          ) -> tuple[bool, bool, bool, str]:
    """(named on the link or its stated equivalents alone, that link's mass within tolerance,
    named on the link itself, what went wrong). On the back and front links, which turn about
    fixed pivots, a load's mass and its distance are one product to the torques (a mass m at
    r and 4m at r/2 differ only in inertia, which a small load barely moves): there the first
    moments m x centre the data determine are judged (along the pivot's axis none is), within
    the tolerance of their size."""
    if link is None:
        ok = result.verdict == "nothing changed"
        return ok, ok, ok, "" if ok else f"{result.verdict}: " + ",".join(f"{e['kind']}:{e['coordinate']}"
                                                                           for e in result.changes)
    names = [f"{e['kind']}:{e['coordinate']}" for e in result.changes]
    if len(result.changes) != 1 or result.ambiguous:
        return False, False, False, f"{result.verdict}: {names} ambiguous {len(result.ambiguous)}"
    change = result.changes[0]
    entries = [change] + change.get("alternatives", [])
    on_link = [e for e in entries if e["kind"] in ("body", "mass") and e["coordinate"] == link]
    if not on_link:
        return False, False, False, f"on {[e['coordinate'] for e in entries]}"
    c = on_link[0]["coefficients"]
    if link in WHERE:         # a link turning about a fixed pivot: what the data fix is m x its centre
        fixed = [i for i, k in enumerate(("mx", "my", "mz")) if c[k]["value"] is not None]
        moment = [c[k]["value"] for k in ("mx", "my", "mz")]
        true = mass * np.asarray(centre)[fixed]
        found = np.array([moment[i] for i in fixed])
        within = bool(fixed) and bool(np.linalg.norm(found - true) <= tolerance * np.linalg.norm(true))
        return True, within, entries[0] is on_link[0], "" if within else f"{link} m c = {moment}"
    m = c["m"]["value"]
    within = m is not None and abs(m - mass) <= tolerance * mass
    return True, within, entries[0] is on_link[0], "" if within else f"{link} m = {m}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("--mass", type=float, default=0.205, help="the load in kg (the issue's 205 g)")
    parser.add_argument("--tolerance", type=float, default=0.10)
    parser.add_argument("--noise", nargs="+", default=["ar1"])
    parser.add_argument("--links", nargs="+", default=["pitch_top", "pitch_bottom", "pitch_end", "pitch_back",
                                                       "pitch_front"])
    parser.add_argument("--no-nothing", action="store_true", help="skip the scenario with nothing added")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    mechanism = resolve("parallelogram_arm")
    index = {body_name(mechanism, b.label): k for k, b in enumerate(mechanism.bodies)}
    scenarios = ([] if args.no_nothing else [None]) + list(args.links)
    print(f"parallelogram_arm, {args.samples} samples per run, {args.seeds} seeds per cell, load {args.mass:g} kg, "
          f"mass within {100 * args.tolerance:g} %")
    print(f"{'scenario':<14} {'noise':<6} {'named':>7} {'+mass':>7} {'first':>7} {'CPU s':>6}  failures")
    for link in scenarios:
        for noise in args.noise:
            named = right = first = 0
            cpu, failures = [], []
            for seed in range(args.seeds):
                extra = {} if link is None else {"payload_mass": args.mass, "payload_body": index[link],
                                                 "payload_at": WHERE.get(link, (0.0, 0.0, 0.0))}
                before, after, truth = simulate_change(mechanism, samples=args.samples, seed=seed, noise=noise,
                                                       **extra)
                start = time.process_time()
                result = diagnose_change(mechanism, before, after)
                cpu.append(time.process_time() - start)
                centre = truth["payload"]["centre"] if truth["payload"] else [0.0, 0.0, 0.0]
                ok, within, itself, why = judge(result, link, args.mass, centre, args.tolerance)
                named, right, first = named + ok, right + (ok and within), first + (ok and itself)
                if not (ok and within):
                    failures.append(f"{seed}: {why}")
            print(f"{link or 'nothing':<14} {noise:<6} {named:>3}/{args.seeds:<3} {right:>3}/{args.seeds:<3} "
                  f"{first:>3}/{args.seeds:<3} {np.median(cpu):>6.1f}  {'; '.join(failures[:4])}", flush=True)


if __name__ == "__main__":
    main()
