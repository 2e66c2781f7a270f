"""Issue 42, part 2: the verdict under coloured residuals. Nothing hidden, noise white, AR(1)
at 0.9, or low-pass-filtered white noise (a second-order Butterworth at 10 % of the Nyquist
frequency, filtered forwards: a smooth noise correlated over ~10 samples); each coordinate's
noise SD 2 % of its RMS inertial torque (``diagnose_campaign.NOISE``). The verdict must be
"nothing missing" (exit 0): the rates of exit 0, of "nothing missing", and why the others
were not (structure: the residual follows the motion; held: an unsupported candidate still
adds; named: an effect or ambiguous group named). Then, under the same noises, a hidden
effect (viscous friction or a spring at effect/noise 5) must still be named, and a force
outside the catalogue that follows the motion (a dead-zone friction, sign(qd) |qd|^(1/3)
below 30 % of the RMS speed: on one joint, effect/noise 5) must leave "structure remains".

    python benchmarks/bench_diagnose_coloured.py                 # 100 datasets a row (~15 min on one core)
    python benchmarks/bench_diagnose_coloured.py --count 20      # a quick run
    python benchmarks/bench_diagnose_coloured.py --mechanisms puma560 --noises ar
    python benchmarks/bench_diagnose_coloured.py --tx40          # the real TX40 recording only
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import diagnose_campaign as C  # noqa: E402

from baseparams.diagnose.workflow import diagnose  # noqa: E402

MECHANISMS = ("planar_2r", "puma560", "stewart_platform", "chain4", "tree1", "four_bar2")
NOISES = ("white", "ar", "lowpass")
LOWPASS = 0.1                   # cut-off, a fraction of the Nyquist frequency
TX40 = Path(__file__).resolve().parents[1] / "tests" / "data" / "tx40"


def coloured(rng, shape, sd, kind: str) -> np.ndarray:
    """Noise (n, f) of marginal SD ``sd``: white, AR(1) 0.9, or low-pass-filtered white."""
    if kind == "white":
        return C.noise(rng, shape, sd)
    if kind == "ar":
        return C.noise(rng, shape, sd, 0.9)
    from scipy.signal import butter, lfilter
    b, a = butter(2, LOWPASS)
    burn = 200
    e = lfilter(b, a, rng.standard_normal((shape[0] + burn, shape[1])), axis=0)[burn:]
    return e / np.std(e, axis=0) * sd


def dead_zone(s, rng):
    """A friction outside the catalogue that follows the motion: sign(qd) |qd / 0.3 rms|^(1/3),
    saturating at 1 above 30 % of the RMS speed, on one moving joint (its force, unscaled)."""
    j = C.driven(s, rng)
    qd = s.motion.qd[:, j]
    v = qd / (0.3 * np.sqrt(np.mean(qd ** 2)))
    return C.on(len(s.coordinates), j, np.sign(v) * np.minimum(np.abs(v), 1.0) ** (1.0 / 3.0)), s.coordinates[j]


def dataset(s, rng, noise: str, scenario: str, ratio: float = 5.0):
    """(tau, truth) for a scenario: 'nothing', 'viscous', 'spring' (a catalogue effect on a
    random coordinate) or 'outside' (:func:`dead_zone`)."""
    phi, clean, sd = C.base(s, rng)
    truth = set()
    force = np.zeros_like(clean)
    if scenario == "outside":
        shape, _ = dead_zone(s, rng)
        force = C.scaled(shape, sd, ratio)
    elif scenario in ("viscous", "spring"):
        kind = {"viscous": "viscous_friction", "spring": "spring"}[scenario]
        choices = [c for c in s.problem.candidates if c.kind == kind and c.coordinate in s.coordinates]
        cand = choices[int(rng.integers(len(choices)))]
        theta = rng.uniform(0.5, 1.5, size=cand.columns.shape[-1])
        if kind == "spring":
            q = s.motion.q[:, s.coordinates.index(cand.coordinate)]
            theta[1] = theta[0] * (np.mean(q) + 0.1 * np.std(q))
        force = C.scaled(cand.columns @ theta, sd, ratio)
        truth = {(kind, cand.coordinate)}
    return clean + force + coloured(rng, clean.shape, sd, noise), truth


def before(d) -> bool:
    """The verdict's exit 0 as it was before the motion test (Ljung-Box white, no candidate
    left at --max-steps, no unsupported candidate but those within rounding or not significant
    beside the named effects), from the same diagnosis."""
    un = d.unexplained
    return bool(un["white"] and not un["significant_candidates_left"] and all(
        "within the rounding" in u["reason"] or "beside the named effects it is not significant" in u["reason"]
        for u in d.unsupported))


def why(d) -> str:
    if d.closed:
        return "exit 0"
    if d.unexplained.get("structure"):
        return "structure"
    if d.unsupported:
        return "held"
    return "other"


def setting(name):
    return C.generated_setting(name, 1200) if name in C.GENERATED else C.setting(name, 1200)


def run(args):
    print(f"{args.count} datasets a row, 1200 samples, noise SD {C.NOISE:.0%} of each coordinate's RMS inertial "
          f"torque; noise: white, AR(1) 0.9, low-pass (Butterworth 2 at {LOWPASS:.0%} of Nyquist); seed {args.seed}")
    started = time.process_time()
    for name in args.mechanisms:
        s = setting(name)
        for noise in args.noises:
            for scenario in args.scenarios:
                rng = np.random.default_rng([args.seed, MECHANISMS.index(name) if name in MECHANISMS else 99,
                                             NOISES.index(noise), ("nothing", "viscous", "spring",
                                                                   "outside").index(scenario)])
                reasons, verdicts, named, old = Counter(), Counter(), 0, 0
                t0 = time.process_time()
                for _ in range(args.count):
                    tau, truth = dataset(s, rng, noise, scenario)
                    d = diagnose(s.problem, tau)
                    reasons[why(d)] += 1
                    old += before(d)
                    verdicts[d.verdict] += 1
                    named += bool(truth) and truth <= {(e["kind"], e["coordinate"]) for e in d.effects}
                n = args.count
                cpu = (time.process_time() - t0) / n
                if scenario == "nothing":
                    print(f"  {name:16s} {noise:8s} nothing hidden   exit 0 {reasons['exit 0'] / n:6.1%}  nothing missing "
                          f"{verdicts['nothing missing'] / n:6.1%}  not: structure {reasons['structure']:3d}  held "
                          f"{reasons['held']:3d}  other {reasons['other']:3d}  (before: exit 0 {old / n:6.1%}; "
                          f"{cpu:.2f} CPU s each)", flush=True)
                elif scenario == "outside":
                    print(f"  {name:16s} {noise:8s} outside (dead zone) structure remains {reasons['structure'] / n:6.1%}  "
                          f"exit 1 {1 - reasons['exit 0'] / n:6.1%} (before {1 - old / n:6.1%})  verdicts "
                          f"{dict(verdicts)}", flush=True)
                else:
                    print(f"  {name:16s} {noise:8s} {scenario:8s} named {named / n:6.1%}  exit 0 {reasons['exit 0'] / n:6.1%}"
                          f" (before {old / n:6.1%})  verdicts {dict(verdicts)}", flush=True)
    print(f"campaign: {time.process_time() - started:.0f} CPU s")


def tx40():
    """The real payload-free TX40 recording (tests/data/tx40): the verdict, the residual's
    colour, and whether the motion predicts the residual (per joint)."""
    import json

    from click.testing import CliRunner

    from baseparams.cli import main
    t0 = time.process_time()
    result = CliRunner().invoke(main, ["diagnose", str(TX40 / "tx40_mdh_modified.urdf"), str(TX40 / "recording.toml"),
                                       "--format", "json"])
    d = json.loads(result.stdout)
    un = d["unexplained"]
    print(f"TX40 ({d['samples']['fit']} samples): verdict {d['verdict']}, exit {result.exit_code}; gap "
          f"{d['gap']['before']:.3f} -> {d['gap']['after']:.3f}; named {len(d['effects'])}; "
          f"{time.process_time() - t0:.1f} CPU s")
    for c in d["coordinates"]:
        p, k, lb = un["predictable"][c], un["colour"][c], un["ljung_box"][c]
        print(f"  {c}: Ljung-Box p {lb['pvalue']:.2g}; lag-1 {k['lag1']:.2f}, AR({k['ar_order']}), half power below "
              f"{k['half_power_hz']:.3g} Hz; residual / noise level {un['ratio'][c]:.2f}; motion predicts it: p "
              f"{p['pvalue']:.2g} (Holm {p['pvalue_holm']:.2g}, F({p['df']}, {p['effective_samples']}))")
    for note in d["notes"]:
        if note.startswith(("structure remains", "the residual is coloured")):
            print(f"  note: {note}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=100)
    parser.add_argument("--seed", type=int, default=42)
    parser.add_argument("--mechanisms", nargs="*", default=list(MECHANISMS))
    parser.add_argument("--noises", nargs="*", default=list(NOISES), choices=NOISES)
    parser.add_argument("--scenarios", nargs="*", default=["nothing", "viscous", "spring", "outside"],
                        choices=["nothing", "viscous", "spring", "outside"])
    parser.add_argument("--tx40", action="store_true", help="the real TX40 recording only")
    args = parser.parse_args()
    if args.tx40:
        tx40()
        return
    run(args)


if __name__ == "__main__":
    main()
