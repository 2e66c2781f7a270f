"""diagnose --baseline on currents (issue 42): two runs that differ by an unknown change
cannot fix the scale of currents whose gains are unknown, so such runs are refused with the
way out (exit 2); with the gains given, the change is found in physical units."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.io.loader import resolve
from baseparams.recordings.simulate import simulate_change

GAINS = np.array([0.5, 0.8, 0.3, 0.1, 0.07, 0.05])           # N m per A, one per coordinate


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The PUMA's baseline and a run with a payload on link6, logged as currents (tau / gain)."""
    folder = tmp_path_factory.mktemp("currents")
    before, after, truth = simulate_change(resolve("puma560"), samples=2000, seed=3, payload=0.3, noise="ar1")
    names = [f"q{i}" for i in range(1, 7)]
    for name, data in (("base", before), ("changed", after)):
        header = ",".join(["t"] + [f"pos_{n}" for n in names] + [f"cur_{n}" for n in names])
        np.savetxt(folder / f"{name}.csv", np.column_stack([data.t, data.motion.q, data.tau / GAINS]), delimiter=",",
                   header=header, comments="", fmt="%.12g")
    return folder, truth


def describe(folder: Path, name: str, known: list[int]) -> str:
    """``name``.csv's description, the gains of the coordinates ``known`` (0-based) given."""
    torque = "".join(f'q{i + 1} = {{ column = "cur_q{i + 1}", gain = '
                     + (repr(float(GAINS[i])) if i in known else '"unknown"') + " }\n" for i in range(6))
    path = folder / f"{name}_{len(known)}.toml"
    path.write_text(f'[recording]\ntime = "t"\n[[runs]]\nfile = "{name}.csv"\n[position]\n'
                    + "".join(f'q{i} = "pos_q{i}"\n' for i in range(1, 7)) + "[torque]\n" + torque)
    return str(path)


@pytest.mark.parametrize("known", [[], [0]])
def test_currents_of_unknown_gains_are_refused(runs, known):
    folder, _ = runs
    result = CliRunner().invoke(main, ["diagnose", "puma560", describe(folder, "changed", known), "--baseline",
                                       describe(folder, "base", known)])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert "--baseline" in result.stderr and "gain_q2" in result.stderr and "--params" in result.stderr
    assert ("gain_q1" in result.stderr) == (not known)


def test_currents_of_given_gains_find_the_payload(runs):
    folder, truth = runs
    every = list(range(6))
    result = CliRunner().invoke(main, ["diagnose", "puma560", describe(folder, "changed", every), "--baseline",
                                       describe(folder, "base", every), "--format", "json"])
    assert result.exit_code == 0, result.output
    import json
    report = json.loads(result.stdout)
    named = [(c["kind"], c["coordinate"]) for c in report["changes"]]
    assert named == [("body", "link6")], (named, report["notes"])
    mass = report["changes"][0]["value"]["m"]
    assert abs(mass - float(truth["payload"]["mass"])) <= 3 * report["changes"][0]["std"]["m"]
