"""diagnose --params against what the held identification already lacked (issue 42).

Per seed, two simulated runs of the default trajectory share a real robot's model errors
(smooth Coulomb law, viscous friction, a delay; none in the mechanism) and AR(1) noise. The
first run is identified with the shared effects and held (``--params``); the second is
diagnosed (its CPU seconds in this process, median over the seeds). Scenarios: ``payload`` (PAYLOAD times the last body's mass added), ``nothing``, and
``outside`` (the payload plus a force on the second coordinate that no candidate has,
OUTSIDE times its RMS). Counted: the payload named alone on the last body (a body, a payload or a point mass), mass
within 10 %;
the verdict (exit 0 = 'explained' or 'nothing missing'); for ``outside`` the verdict must stay
'partly explained' or 'unexplained'.

    python benchmarks/bench_diagnose_held.py [--mechanism puma560] [--seeds 10] [--samples 1500] [--payload 0.5]
        [--payload-mass KG] [--quantum 0.01] [--load-friction MU]
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import baseparams as bp
from baseparams.diagnose.change import shared_effects
from baseparams.diagnose.derived import body_name
from baseparams.io.loader import resolve
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate_change

PAYLOAD = 0.5
OUTSIDE = 0.08


def run(name: str, seed: int, samples: int, scenario: str, payload: float = PAYLOAD,
        payload_mass: float | None = None, quantum: float = 0.0, load_friction: float = 0.0) -> dict:
    mechanism = resolve(name)
    nothing = scenario == "nothing"
    before, after, truth = simulate_change(mechanism, samples=samples, seed=seed, payload=0.0 if nothing else payload,
                                           payload_mass=(0.0 if nothing else payload_mass) if payload_mass else None,
                                           quantum=quantum, load_friction=load_friction)
    if scenario == "outside":
        q, j = after.motion.q, min(1, after.tau.shape[1] - 1)
        rms = np.sqrt(np.mean(after.tau[:, j] ** 2))
        after.tau[:, j] += OUTSIDE * rms * np.sqrt(2) * np.sin(3 * q[:, j] + 2 * q[:, (j + 1) % q.shape[1]])
    with tempfile.TemporaryDirectory() as folder:
        base, changed, held = (Path(folder) / n for n in ("base.csv", "changed.csv", "base.json"))
        write_measured(base, before)
        write_measured(changed, after)
        effects = [f"{e.kind}:{e.coordinate}" for e in shared_effects(mechanism)]
        held.write_text(json.dumps(bp.identify(name, str(base), effects=effects).to_json()))
        started = time.process_time()
        report = bp.diagnose(name, str(changed), params=str(held)).to_json()
        cpu = time.process_time() - started
    named = [f"{e['kind']}:{e['coordinate']}" for e in report["effects"]] + \
        [f"ambiguous:{a['strongest']}" for a in report["ambiguous"]]
    right = False
    if truth["payload"]:
        last = body_name(mechanism, mechanism.bodies[truth["payload"]["body"]].label)
        if named in ([f"body:{last}"], [f"payload:{last}"], [f"mass:{last}"]):   # a body, a load or a point mass on it
            mass = report["effects"][0]["coefficients"]["m"]["value"]
            right = mass is not None and abs(mass - truth["payload"]["mass"]) <= 0.10 * truth["payload"]["mass"]
    return {"verdict": report["verdict"], "named": named, "right": right, "cpu": cpu}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mechanism", default="puma560")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--samples", type=int, default=1500)
    parser.add_argument("--scenarios", nargs="+", default=["payload", "nothing", "outside"])
    parser.add_argument("--payload", type=float, default=PAYLOAD, help="the payload, times the last body's mass")
    parser.add_argument("--payload-mass", type=float, default=None, help="the payload in kg instead")
    parser.add_argument("--quantum", type=float, default=0.0, help="torques rounded to this step (N m)")
    parser.add_argument("--load-friction", type=float, default=0.0, help="gear friction mu |tau| common to both runs")
    args = parser.parse_args()
    size = f"{args.payload_mass:g} kg" if args.payload_mass else f"{args.payload:g} times the last body's mass"
    print(f"{args.mechanism}, {args.samples} samples per run, {args.seeds} seeds, AR(1) noise, shared model errors, "
          f"payload {size}" + (f", torques quantised to {args.quantum:g}" if args.quantum else "")
          + (f", load friction {args.load_friction:g}" if args.load_friction else ""))
    for scenario in args.scenarios:
        results = [run(args.mechanism, seed, args.samples, scenario, args.payload, args.payload_mass, args.quantum,
                       args.load_friction) for seed in range(args.seeds)]
        exit0 = sum(r["verdict"] in ("explained", "nothing missing") for r in results)
        line = f"  {scenario:8s} exit 0: {exit0}/{len(results)}"
        if scenario != "nothing":
            line += f"; payload named alone, mass within 10 %: {sum(r['right'] for r in results)}/{len(results)}"
        else:
            line += f"; nothing named: {sum(not r['named'] for r in results)}/{len(results)}"
        line += f"; diagnose {np.median([r['cpu'] for r in results]):.2f} CPU s (median, in process)"
        print(line, flush=True)
        for seed, r in enumerate(results):
            if (scenario == "outside") == (r["verdict"] in ("explained", "nothing missing")) or \
                    (scenario != "nothing" and not r["right"]) or (scenario == "nothing" and r["named"]):
                print(f"    seed {seed}: {r['verdict']}, named {r['named']}", flush=True)


if __name__ == "__main__":
    main()
