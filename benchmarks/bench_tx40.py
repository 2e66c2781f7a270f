"""The real Staubli TX40 recording identified as recorded (docs/identification.md, "The
Staubli TX40, side by side with FIGAROH"): RMS residual and NRMS per joint with and
without the coupled motor 6, with the default filter and with FIGAROH's (100 Hz, decimation
by 10), the viscous friction against the config's reference values, and the CPU seconds of
reading, filtering and fitting beside those of one plain least-squares fit of the same
matrix (the yardstick, measured in the same run).

    python benchmarks/bench_tx40.py [--data ../shared/data/tx40]
"""

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from baseparams import registry
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify, predict
from baseparams.recordings.recording import read_data
from baseparams.io.loader import load_mechanism
from baseparams.model.mechanism import EffectSpec

ROOT = Path(__file__).resolve().parents[1]
FIGAROH = "3.874 4.642 2.635 1.091 4.410 1.866 | 3.357 | 0.125 0.143 0.219 0.193 0.540 0.377"
REFERENCE_FV = np.array([8.05, 5.53, 1.97, 1.11])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "tx40"))
    args = parser.parse_args()
    data_dir = Path(args.data).resolve()
    mechanism = load_mechanism(data_dir / "tx40_mdh_modified.urdf")
    base = BaseModel.from_result(registry.solvers()["dp"].item.solve(mechanism), mechanism)
    text = (ROOT / "examples" / "tx40" / "recording.toml").read_text()
    text = text.replace("../../../shared/data/tx40/", f"{data_dir}/")
    joints = [f"joint_{k}" for k in range(1, 7)]
    effects = [EffectSpec(kind, c) for kind in ("viscous_friction", "coulomb_friction", "rotor_inertia", "offset")
               for c in joints]
    motor6 = [EffectSpec(kind, "motor_6") for kind in ("rotor_inertia", "viscous_friction", "coulomb_friction")]
    print("| run | rows | RMS j1..j6 (N m) | overall | NRMS j1..j6 | CPU s | x one lstsq |")
    print("|---|---|---|---|---|---|---|")
    print(f"| FIGAROH 1.0.2 (its README) | 4496 | {FIGAROH} | | |")
    with tempfile.TemporaryDirectory() as folder:
        for label, extra, chosen in (("default filter, coupled motor 6", "", effects + motor6),
                                     ("FIGAROH's filter, coupled motor 6", "[filter]\ncutoff = 100\ndecimate = 10\n",
                                      effects + motor6),
                                     ("default filter, no motor 6", "", effects),
                                     ("FIGAROH's filter, no motor 6", "[filter]\ncutoff = 100\ndecimate = 10\n",
                                      effects)):
            description = Path(folder) / "recording.toml"
            description.write_text(text + extra)
            start = time.process_time()
            data, model = read_data([str(description)], mechanism)
            result = identify(model, data, effects=chosen, base=base)
            fitted = predict(result, model, data)
            cpu = time.process_time() - start
            x = np.random.default_rng(0).standard_normal((data.count * 6, len(result.names)))
            start = time.process_time()
            for _ in range(20):
                np.linalg.lstsq(x, x[:, 0], rcond=None)
            yardstick = max((time.process_time() - start) / 20, 1e-6)
            print(f"| {label} | {data.count} | {' '.join(f'{v:.3f}' for v in fitted.rms)} | "
                  f"{fitted.overall_rms:.3f} | {' '.join(f'{v:.3f}' for v in fitted.nrms)} | {cpu:.1f} | "
                  f"{cpu / yardstick:.0f} |")
            if chosen is not effects:
                fv = np.array([result.value(f"fv_joint_{k}") for k in range(1, 5)])
                print(f"|   viscous friction j1..j4 | | {' '.join(f'{v:.3g}' for v in fv)} | vs reference "
                      f"{' '.join(f'{100 * (v / r - 1):+.0f}%' for v, r in zip(fv, REFERENCE_FV))} | | | |")


if __name__ == "__main__":
    main()
