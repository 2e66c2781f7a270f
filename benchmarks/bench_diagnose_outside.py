"""Issue 21's figures for ``diagnose`` (run through ``bench_diagnose.py --outside``): rates of
confident wrong names with white and AR(1) noise, with the catalogue's effects, the new kinds
and mismatches outside the catalogue (scenarios in :mod:`diagnose_campaign`); a payload
diagnosed with the model held as given; the stated standard deviation against the spread
over repeated recordings with coloured noise; and diagnose on the real TX40 recording
against one ``identify`` of the same data in the same run (CPU seconds)."""

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import diagnose_campaign as C  # noqa: E402

from baseparams.diagnose.workflow import diagnose  # noqa: E402

MECHANISMS = ("puma560",)
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "tx40"


def rates(outcomes):
    n = len(outcomes)
    out = {k: f"{outcomes.count(k) / n:5.1%}" for k in ("right", "ambiguous", "unseeable", "none", "wrong")}
    seeable = n - outcomes.count("unseeable")
    out["right_of_seeable"] = f"{outcomes.count('right') / seeable:5.1%}" if seeable else "  -  "
    return out, n


def scenario_table(s, args, rng):
    rows = []
    for rho in (0.0, 0.9):
        for label, make in [("nothing hidden", C.nothing)] + list(C.INSIDE.items()) + list(C.NEW.items()) \
                + [(f"below 3: {k}", v) for k, v in C.BELOW.items()] \
                + [(f"outside: {k}", v) for k, v in C.OUTSIDE.items()]:
            outcomes = [C.run(s, make, rng, rho=rho)[2] for _ in range(args.count)]
            r, n = rates(outcomes)
            rows.append((label, rho, r, n))
            print(f"  {s.name:10s} {label:28s} AR {rho:3.1f}  n {n:3d}  right {r['right']}  ambiguous {r['ambiguous']}"
                  f"  unseeable {r['unseeable']}  none {r['none']}  WRONG {r['wrong']}  right of seeable "
                  f"{r['right_of_seeable']}", flush=True)
    return rows


GENERATED_SCENARIOS = ("nothing hidden", "viscous", "coulomb", "delay", "gear_loss", "outside: compliance",
                       "outside: ripple")


def generated_table(args):
    """The same scenarios on generated mechanisms (a chain, a tree, a four-bar loop), white
    and AR(1) 0.9 noise: the rates must not hold only on the PUMA."""
    table = {"nothing hidden": C.nothing, **C.INSIDE, **C.NEW, **{f"outside: {k}": v for k, v in C.OUTSIDE.items()}}
    for name in C.GENERATED:
        rng = np.random.default_rng(args.seed)
        s = C.generated_setting(name, 1200)
        print(f"\ngenerated {name} ({len(s.coordinates)} coordinates): scenarios", flush=True)
        for rho in (0.0, 0.9):
            for label in GENERATED_SCENARIOS:
                outcomes = [C.run(s, table[label], rng, rho=rho)[2] for _ in range(args.count)]
                r, n = rates(outcomes)
                print(f"  {name:10s} {label:28s} AR {rho:3.1f}  n {n:3d}  right {r['right']}  ambiguous "
                      f"{r['ambiguous']}  unseeable {r['unseeable']}  none {r['none']}  WRONG {r['wrong']}  "
                      f"right of seeable {r['right_of_seeable']}", flush=True)
        payload_rng = np.random.default_rng(args.seed + 1)         # its own stream: the rows above unchanged
        for rho in (0.0, 0.9):
            payload_table(s, args, payload_rng, rho)


def four_bar_power_table(args):
    """The one-coordinate four-bar under AR(1) 0.9 noise at rising effect/noise: whether its
    misses are power (fewer at a larger effect) or a wrong name that stays (load friction taken
    for position friction). ``--four-bar-power`` runs this alone."""
    s = C.generated_setting("four_bar2", 1200)
    for ratio in (5.0, 10.0, 20.0):
        for label, make in (("gear_loss", C.gear_loss), ("coulomb", C.INSIDE["coulomb"])):
            rng = np.random.default_rng(args.seed)
            outcomes = [C.run(s, make, rng, rho=0.9, ratio=ratio)[2] for _ in range(args.count)]
            r, n = rates(outcomes)
            print(f"  four_bar2  {label:10s} AR 0.9  effect/noise {ratio:4.0f}  n {n:3d}  right {r['right']}  "
                  f"ambiguous {r['ambiguous']}  none {r['none']}  WRONG {r['wrong']}", flush=True)


def uneven_table(args):
    """Nothing hidden, the noise's level changing with the motion (larger at velocity
    reversals, or growing with the torque), white and AR(1) 0.9, on the PUMA and the
    generated mechanisms (its own random stream: the other tables' datasets are unchanged)."""
    for name in MECHANISMS + C.GENERATED:
        rng = np.random.default_rng(args.seed)
        s = C.setting(name, 1200) if name in MECHANISMS else C.generated_setting(name, 1200)
        for rho in (0.0, 0.9):
            for label, make in C.UNEVEN.items():
                outcomes = [C.run(s, make, rng, rho=rho)[2] for _ in range(args.count)]
                r, n = rates(outcomes)
                print(f"  {name:10s} nothing hidden, {label:26s} AR {rho:3.1f}  n {n:3d}  WRONG {r['wrong']}",
                      flush=True)


def payload_table(s, args, rng, rho=0.0):
    """A payload on the last body diagnosed against the payload-free model (--params): named
    alone on the right body, ambiguous with the right body among the group, or wrong; its mass
    within 10 %, or not identifiable on this mechanism (a body turning about its frame's
    origin on a closed loop: its first moments and inertia about the axis move the torque,
    its mass does not)."""
    hits = within = hidden = ambiguous = wrong = 0
    for _ in range(args.count):
        tau, body, mass, phi = C.payload(s, rng, rho=rho)
        d = diagnose(C.payload_problem(s, phi), tau)
        named = [e for e in d.effects if e["kind"] in ("mass", "body") and e["coordinate"] == body]
        others = [e for e in d.effects if e not in named]
        wrong += bool(others)
        if named and not others:
            hits += 1
            estimate = named[0]["coefficients"]["m"]["value"]         # None: not identifiable
            hidden += estimate is None
            within += estimate is not None and abs(estimate - mass) <= 0.1 * mass
        elif not d.effects and any(c["coordinate"] == body for a in d.ambiguous for c in a["candidates"]):
            ambiguous += 1
    n = args.count
    print(f"  {s.name:10s} payload on the last body, --params, AR {rho:3.1f}: named on the right body "
          f"{hits / n:5.1%}, mass within 10 % {within / n:5.1%}, mass not identifiable {hidden / n:5.1%}, "
          f"ambiguous with the right body {ambiguous / n:5.1%}, WRONG {wrong / n:5.1%} (n {n})", flush=True)


def spread_table(s, args, rng, rho=0.9, recordings=30):
    """One robot (one phi, one hidden viscous friction), many recordings with AR(1) noise:
    the stated std of the named coefficient against the spread of the estimates."""
    phi, clean, sd = C.base(s, rng)
    cand = next(c for c in s.problem.candidates if c.kind == "viscous_friction" and c.coordinate == s.coordinates[0])
    force = C.scaled(cand.columns @ [1.0], sd, 8.0)
    values, stds = [], []
    for _ in range(recordings):
        tau = clean + force + C.noise(rng, clean.shape, sd, rho)
        d = diagnose(s.problem, tau)
        e = next((e for e in d.effects if (e["kind"], e["coordinate"]) == (cand.kind, cand.coordinate)), None)
        if e is not None:
            values.append(e["value"])
            stds.append(e["std"])
    spread, stated = float(np.std(values, ddof=1)), float(np.sqrt(np.mean(np.square(stds))))
    print(f"  {s.name:10s} viscous_friction:{cand.coordinate}, AR(1) {rho}: named in {len(values)}/{recordings}; "
          f"spread over recordings {spread:.4g}, stated std (RMS) {stated:.4g}, ratio {stated / spread:.2f} "
          "(target within 1/1.5 .. 1.5)", flush=True)


def tx40_timing():
    """diagnose and identify on the TX40 recording (every candidate, no cap), CPU seconds."""
    urdf, recording = SHARED / "tx40_mdh_modified.urdf", Path(__file__).parents[1] / "examples" / "tx40" / "recording.toml"
    if not urdf.exists():
        print("  TX40: ../shared/data/tx40 not found, skipped")
        return
    from baseparams.diagnose.workflow import diagnose_data
    from baseparams.identify.fit import identify
    from baseparams.recordings.recording import read_data
    from baseparams.io.loader import resolve
    mechanism = resolve(str(urdf))
    started = time.process_time()
    data, mech = read_data([str(recording)], mechanism)
    read = time.process_time() - started
    started = time.process_time()
    from baseparams import registry
    from baseparams.identify.base import BaseModel
    base = BaseModel.from_result(registry.solvers()["vp"].item.solve(mech), mech)    # as identify's default
    identify(mech, data, base=base)
    identify_cpu = time.process_time() - started
    started = time.process_time()
    d = diagnose_data(mech, data)
    diagnose_cpu = time.process_time() - started
    print(f"  TX40 ({data.tau.shape[0]} x {data.tau.shape[1]} fit rows; reading {read:.1f} CPU s): identify "
          f"{identify_cpu:.2f} CPU s, diagnose {diagnose_cpu:.2f} CPU s ({diagnose_cpu / identify_cpu:.1f} x identify; "
          f"with reading: {(read + diagnose_cpu):.1f} s vs {(read + identify_cpu):.1f} s, "
          f"{(read + diagnose_cpu) / (read + identify_cpu):.2f} x); {len(d.steps)} steps; verdict {d.verdict}; "
          f"named {len(d.effects)}, unsupported {len(d.unsupported)}; cross-validated gap "
          f"{d.gap['cv_before']:.3f} -> {d.gap['cv_after']:.3f}; implausible named: "
          f"{[e for e in d.effects if e['kind'] in ('viscous_friction', 'coulomb_friction', 'rotor_inertia') and min(v['value'] for v in e['coefficients'].values()) <= 0]}",
          flush=True)


RECORDING_SCENARIOS = {
    "nothing hidden": {},
    "nothing hidden, AR(1) 0.99 per log sample": {"rho": 0.99},
    "viscous mot3 + Coulomb q1": {"hidden": [("viscous_friction", "mot3", "fv"), ("coulomb_friction", "q1", "fc")]},
    "delay 3 ms": {"delay": 0.003},
}


def recording_table(args):
    """Through a recording as a robot writes it (:func:`diagnose_campaign.motor_side_recording`:
    motor-side encoders in degrees, currents with gains, a coupled motor, read with the
    recording's default filter and decimation), one generated 3-R chain per seed: the named
    effects against the truth, and how often the verdict says structure remains."""
    import json
    import tempfile

    from click.testing import CliRunner

    from baseparams.cli import main
    print("\nthrough a motor-side recording (generated 3-R chains with a coupled motor; 1 kHz -> ~15 Hz)",
          flush=True)
    for label, options in RECORDING_SCENARIOS.items():
        outcomes, unexplained = [], 0
        for seed in range(args.count):
            with tempfile.TemporaryDirectory() as folder:
                hidden = C.motor_side_recording(folder, seed, **options)
                result = CliRunner().invoke(main, ["diagnose", f"{folder}/mech.toml", f"{folder}/rec.toml",
                                                   "--format", "json", "--quiet"])
            report = json.loads(result.stdout)
            named = {(e["kind"], e["coordinate"]) for e in report["effects"]}
            truth = {(k, c) for k, c, _ in hidden} | ({("delay", "all")} if options.get("delay") else set())
            outcomes.append("wrong" if named - truth else "right" if named == truth and truth else
                            "none" if not truth else "partial")
            unexplained += report["verdict"] in ("unexplained", "partly explained")
        n = len(outcomes)
        print(f"  {label:42s} n {n:3d}  right {outcomes.count('right') / n:5.1%}  partial "
              f"{outcomes.count('partial') / n:5.1%}  none {outcomes.count('none') / n:5.1%}  WRONG "
              f"{outcomes.count('wrong') / n:5.1%}  verdict 'structure remains' {unexplained / n:5.1%}", flush=True)


def run_outside(args):
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    started = time.process_time()
    print(f"issue 21 campaign: {args.count} datasets per scenario, 1200 samples, noise SD {C.NOISE:.0%} of each "
          f"coordinate's RMS inertial torque, ratio 5 (effect RMS / noise SD), alpha 0.05, seed {args.seed}")
    print("\nTX40, real recording")
    tx40_timing()
    for name in args.mechanisms if "--mechanisms" in sys.argv else MECHANISMS:
        rng = np.random.default_rng(args.seed)
        s = C.setting(name, 1200)
        print(f"\n{name}: scenarios")
        scenario_table(s, args, rng)
        payload_table(s, args, rng)
        spread_table(s, args, rng)
    if "--mechanisms" not in sys.argv:
        generated_table(args)
        recording_table(args)
        print("\nnothing hidden, uneven noise: false effects")
        uneven_table(args)
    print(f"\ncampaign: {time.process_time() - started:.0f} CPU s")
