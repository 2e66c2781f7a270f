"""What changed between recordings (``diagnose CHANGED --baseline BASE``), measured on
simulated pairs of runs with a known truth (core/recordings/simulate.py, simulate_change):
the same trajectory recorded twice, model errors common to both sides (a smooth Coulomb law,
viscous friction, a 2-sample delay: none of them in the model), independent white, AR(1)
0.9 or low-passed noise at 1 % of each coordinate's RMS torque, and between the runs a
payload of 5-50 % of the last body's mass, a viscous-friction drift, or nothing.

Printed per scenario: the datasets with the right names (payload: named on the right body
alone; friction: viscous friction on the drifted coordinate alone; nothing: "nothing
changed") and, for a payload, with its mass within 5 % too, and within 2 of its own std (the
std is honest: the 5 % is then what the noise allows); for a payload the yardstick of what
the data allow (:func:`oracle`: a perfect-model fit of the payload on the same two runs):
the datasets where it is within 5 %, and the median std over the mass of the diagnosis, of
the oracle's body and of the simulated point mass; the median text report's lines, and the
speed figure: CPU seconds of one diagnosis between recordings against one ``identify`` of
the changed runs (the shared effects on every coordinate) in the same process.
``--mechanism generated``: random serial chains (4 bodies, RRRR, random physical inertias),
dataset i on the chain of generator seed ``--generators[i % len]`` (several chains, not one).

    python benchmarks/bench_diagnose_change.py [--seeds 20] [--samples 5000] [--mechanism puma560]
    python benchmarks/bench_diagnose_change.py --mechanism tests/data/urdf/ur5.urdf --samples 1000 \
        --payload-mass 0.0094 0.094 0.48 --quantum 0.01 --noise ar1 lowpass --seeds 20
    python benchmarks/bench_diagnose_change.py --mechanism generated --samples 1000 --payloads 0.05 0.5 --seeds 20
    python benchmarks/bench_diagnose_change.py --mechanism generated --generators 11 12 13 14 --samples 1000 \
        --scenarios nothing --noise ar1 lowpass --seeds 40
"""

import argparse
import os
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


def oracle(mechanism, before, after, truth: dict, load_friction: float) -> tuple[float, float, float]:
    """The yardstick for "mass within 5 %": a perfect-model fit of the payload on the same two
    runs, (its mass's error, its std with the payload's centre known, its std as a body of
    unknown centre). The perfect model is the simulation's own: the difference of the two
    runs' torques (one motion: everything else cancels) against the payload body's ten
    columns at the true delay (with the load friction's share, linearised, when the gears
    have it), generalised least squares with each coordinate whitened by the autoregression
    (order <= 20 by BIC) of its residual at the truth's force and weighted by its noise.
    "Point": the simulated point mass's four unknowns (its mass and centre, linearised at the
    truth: the Cramér-Rao floor for its mass); "body": all ten (a load of any shape, as the
    diagnosis fits it); the error is the body fit's. Why not the centre known: the PUMA's
    last joint, whose simulated noise is 1 % of its tiny torque, then fixes the mass to 1e-4 %
    through the known lever arm, a yardstick no method can reach. Under low-passed noise (no
    white floor) the whitened fit draws on frequencies where the simulated noise vanishes and
    needs the columns exact there: the body's columns shifted 0.3 ms late of the true delay
    (3 % of a sample), or 0.5 ms early, bias its mass by +6 to +18 % more than at the exact
    shift (the PUMA, 4.5 g, seeds 0-4), where least squares on the raw rows is unmoved (and
    scattered by 50 %)."""
    from baseparams.diagnose.changesearch import _filtered, ar_whitening
    from baseparams.dynamics.forces import design, standard_parameters
    from baseparams.recordings.simulate import COMMON_DELAY, COMMON_TRANSITION
    payload = truth["payload"]
    k, m, (x, y, z) = payload["body"], payload["mass"], payload["centre"]
    K = design(mechanism, after.motion, [], after.sample)[0].matrix
    body = K[:, :, 10 * k:10 * k + 10]
    if load_friction:
        qd = after.motion.qd
        speed = np.sqrt(np.mean(qd ** 2, axis=0))
        clean = K @ standard_parameters(mechanism)
        slope = load_friction * np.sign(clean) * np.tanh(qd / (COMMON_TRANSITION * np.where(speed > 0, speed, 1.0)))
        body = body * (1.0 + slope)[:, :, None]
    lag = COMMON_DELAY if truth["delay"] else 0
    if lag:
        body = np.concatenate([np.repeat(body[:1], lag, axis=0), body[:len(body) - lag]])
    unit = np.array([1.0, x, y, z, y * y + z * z, -x * y, -x * z, x * x + z * z, -y * z, x * x + y * y])
    difference = after.tau - before.tau
    weights = 1.0 / np.sqrt(np.mean((difference - body @ (m * unit)) ** 2, axis=0))
    filters = ar_whitening((difference - body @ (m * unit)) * weights[None, :])

    def gls(columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X = _filtered(filters, columns * weights[None, :, None]).reshape(-1, columns.shape[-1])
        b = _filtered(filters, difference * weights[None, :]).reshape(-1)
        inverse = np.linalg.pinv(X.T @ X)
        value = inverse @ (X.T @ b)
        sigma2 = float(np.sum((b - X @ value) ** 2)) / max(len(b) - np.linalg.matrix_rank(X), 1)
        return value, np.sqrt(np.diag(inverse) * sigma2)

    moved = np.array([[0.0, 1.0, 0.0, 0.0, 0.0, -y, -z, 2 * x, 0.0, 2 * x],     # d unit / d centre
                      [0.0, 0.0, 1.0, 0.0, 2 * y, -x, 0.0, 0.0, -z, 2 * y],
                      [0.0, 0.0, 0.0, 1.0, 2 * z, 0.0, -x, 2 * z, -y, 0.0]])
    _, point = gls(np.concatenate([(body @ unit)[:, :, None], body @ (m * moved.T)], axis=-1))
    value, std = gls(body)
    return float(value[0] - m), float(point[0]), float(std[0])


def drift_oracle(before, after, truth: dict, quantum: float) -> float:
    """The yardstick for a friction drift: its t statistic in a perfect-model fit, generalised
    least squares of the two runs' torque difference on the drift's column (the speed at the
    true delay) with the true noise covariance (the simulated noise kind's autocovariance
    times 2 sd^2, plus the quantisation's white 2 q^2 / 12), the true drift over its std."""
    from scipy.linalg import solve_toeplitz
    from scipy.signal import butter, lfilter
    from baseparams.recordings.simulate import COMMON_DELAY
    drift = truth["friction_drift"]
    j = list(after.coordinates).index(drift["coordinate"])
    n = len(after.tau)
    qd = after.motion.qd[:, j]
    lag = COMMON_DELAY if truth["delay"] else 0
    x = np.concatenate([np.repeat(qd[:1], lag), qd[:n - lag]])
    impulse = np.zeros(n + 4000)
    impulse[0] = 1.0
    if truth["noise"] == "lowpass":
        h = lfilter(*butter(4, 0.05), impulse)
    elif truth["noise"] == "ar1":
        h = lfilter([1.0], [1.0, -0.9], impulse)
    else:
        h = impulse
    autocovariance = np.array([h[:len(h) - k] @ h[k:] for k in range(n)])
    column = 2 * truth["noise_sd"][j] ** 2 * autocovariance / autocovariance[0]
    column[0] += 2 * quantum ** 2 / 12
    weighted = solve_toeplitz(column, x)
    return float(drift["fv"] * np.sqrt(weighted @ x))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--samples", type=int, default=5000)
    parser.add_argument("--mechanism", default="puma560",
                        help="a name or file, or 'generated' (a random 4-body RRRR chain, random physical inertias)")
    parser.add_argument("--noise", nargs="+", default=["white", "ar1", "lowpass"])
    parser.add_argument("--payloads", nargs="+", type=float, default=[0.05, 0.1, 0.25, 0.5])
    parser.add_argument("--payload-mass", nargs="+", type=float, default=None,
                        help="payloads in kg instead of --payloads (a last body of no mass)")
    parser.add_argument("--load-friction", type=float, default=0.0, help="gear load friction mu, common to both runs")
    parser.add_argument("--quantum", type=float, default=0.0, help="torques rounded to this step (N m)")
    parser.add_argument("--scenarios", nargs="+", default=["nothing", "payload", "friction"])
    parser.add_argument("--no-speed", action="store_true", help="skip the speed figure")
    parser.add_argument("--generators", nargs="+", type=int, default=[11],
                        help="with --mechanism generated: the chains' generator seeds (dataset i: the i mod count-th)")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    generated = args.mechanism == "generated"
    if generated:
        from baseparams.io.loader import parse_mechanism
        from baseparams.model import generate
        chains = [parse_mechanism(generate.serial_chain(g, bodies=4, types="RRRR", samples=600), "chain.toml")
                  for g in args.generators]
    else:
        chains = [resolve(args.mechanism)]
    mechanism = chains[0]
    payloads = [(f"payload {p:g}", {"payload": p}) for p in args.payloads] if args.payload_mass is None else \
        [(f"payload {m:g} kg", {"payload_mass": m}) for m in args.payload_mass]
    scenarios = [("nothing", {})] * ("nothing" in args.scenarios) + payloads * ("payload" in args.scenarios) + \
        [("friction", {"friction_drift": 0.1, "drift_coordinate": 1})] * ("friction" in args.scenarios)
    common = {"load_friction": args.load_friction, "quantum": args.quantum, "random_inertia": generated}
    print(f"{args.mechanism}, {args.samples} samples per run, {args.seeds} seeds per cell; payloads: the oracle "
          "(a perfect-model GLS fit of the payload body on the same data, bench's oracle()) within 5 %, and the "
          "median std/mass of the diagnosis, of the oracle's body and of the simulated point mass (Cramér-Rao)")
    print(f"{'scenario':<16} {'noise':<8} {'names':>7} {'+mass':>7} {'+2 std':>7} {'oracle':>7} {'std/m':>6} "
          f"{'body':>6} {'point':>6} {'lines':>5} {'CPU s':>6}  wrong names")
    for name, change in scenarios if args.seeds > 0 else ():        # --seeds 0: the speed figure alone
        for noise in args.noise:
            named, right, honest, reached, lines, wrong, cpu, drift_t = 0, 0, 0, 0, [], [], [], []
            spreads: dict[str, list[float]] = {"std/m": [], "body": [], "point": []}
            for seed in range(args.seeds):
                mechanism = chains[seed % len(chains)]
                last = rigidly_joined(mechanism, mechanism.bodies[-1].label)
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
                if truth["payload"]:
                    true = truth["payload"]["mass"]
                    error, point, body = oracle(mechanism, before, after, truth, args.load_friction)
                    reached += abs(error) <= 0.05 * true
                    spreads["body"].append(body / true)
                    spreads["point"].append(point / true)
                    if names_right and result.changes[0]["coefficients"]["m"]["std"] is not None:
                        spreads["std/m"].append(result.changes[0]["coefficients"]["m"]["std"] / true)
                if truth["friction_drift"] and seed < 5:
                    drift_t.append(drift_oracle(before, after, truth, args.quantum))
                if not names_right:
                    where = f"{args.generators[seed % len(chains)]}/" if generated else ""
                    wrong.append(f"{where}{seed}: {result.verdict} "
                                 + ",".join(f"{e['kind']}:{e['coordinate']}" for e in result.changes))
            figures = {k: f"{100 * np.median(v):5.1f}%" if v else "     -" for k, v in spreads.items()}
            oracle_rate = f"{reached:>3}/{args.seeds:<3}" if truth["payload"] else "    -  "
            print(f"{name:<16} {noise:<8} {named:>3}/{args.seeds:<3} {right:>3}/{args.seeds:<3} "
                  f"{honest:>3}/{args.seeds:<3} {oracle_rate} {figures['std/m']} {figures['body']} "
                  f"{figures['point']} {int(np.median(lines)):>5} "
                  f"{np.median(cpu):>6.2f}  {'; '.join(wrong[:4])}", flush=True)
            if drift_t:
                print(f"{'':<16} {noise:<8} the drift's t in a perfect-model fit with the true noise (drift_oracle, "
                      f"seeds 0-4): median {np.median(drift_t):.1f}, least {np.min(drift_t):.1f}", flush=True)
    if args.payload_mass is None and not args.no_speed and not generated:
        speed(chains[0], args.samples)


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
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"speed ({samples} samples x {len(after.coordinates)} coordinates per run), identify {i:.2f} CPU s "
          f"({min(times['identify']):.2f}-{max(times['identify']):.2f}), load {load:.1f}:")
    for verb in ("diagnose --baseline", "diagnose --params"):
        d = np.median(times[verb])
        print(f"  {verb}: {d:.2f} CPU s ({min(times[verb]):.2f}-{max(times[verb]):.2f}), ratio {d / i:.2f} "
              "(target <= 5)")


if __name__ == "__main__":
    main()
