"""``diagnose CHANGED... --baseline BASE...``: every path after --baseline up to the next option
is a baseline run, as the usage line writes it. Click alone gave the option one value and read
the next path as a changed run: the baseline's own run among the changed ones (PUMA, two runs a
side) halved the payload found (0.015 kg for 0.027) and the gap did not close."""

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.cli.options import paths_after
from baseparams.io.loader import resolve
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate_change


def baseline_runs(args: list[str]) -> list[str]:
    return paths_after(args, ("--baseline",))


def test_paths_after_baseline_are_baseline_runs():
    assert baseline_runs(["m", "c1", "c2", "--baseline", "b1", "b2", "--plot", "p.png"]) == \
        ["m", "c1", "c2", "--baseline", "b1", "--baseline", "b2", "--plot", "p.png"]
    assert baseline_runs(["m", "c1", "--baseline=b1", "b2"]) == ["m", "c1", "--baseline=b1", "--baseline", "b2"]
    assert baseline_runs(["m", "c1", "--baseline", "b1", "--", "-c2"]) == ["m", "c1", "--baseline", "b1", "--", "-c2"]
    assert baseline_runs(["m", "--plot", "p.png", "c1", "--baseline", "b1", "-"]) == \
        ["m", "--plot", "p.png", "c1", "--baseline", "b1", "-"]
    assert baseline_runs(["m", "c1", "--format", "json"]) == ["m", "c1", "--format", "json"]


@pytest.fixture(scope="module")
def two_runs_a_side(tmp_path_factory):
    """The PUMA before and after a payload, each recorded twice (independent white noise, SD 1 %
    of each coordinate's RMS torque)."""
    folder = tmp_path_factory.mktemp("runs")
    before, after, truth = simulate_change(resolve("puma560"), samples=1500, seed=11, payload=0.3, noise_level=0.0)
    rng = np.random.default_rng(5)
    sd = 0.01 * np.sqrt(np.mean(before.tau ** 2, axis=0))
    for k in (1, 2):
        for name, data in (("base", before), ("changed", after)):
            noisy = dataclasses.replace(data, tau=data.tau + rng.standard_normal(data.tau.shape) * sd)
            write_measured(folder / f"{name}{k}.csv", noisy)
    return folder, truth


def test_two_runs_a_side_after_one_baseline_option(two_runs_a_side):
    folder, truth = two_runs_a_side
    c1, c2, b1, b2 = (str(folder / n) for n in ("changed1.csv", "changed2.csv", "base1.csv", "base2.csv"))
    result = CliRunner().invoke(main, ["diagnose", "puma560", c1, c2, "--baseline", b1, b2, "--format", "json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["pairing"]["baseline_samples"] == report["pairing"]["changed_samples"] == 3000
    assert [(c["kind"], c["coordinate"]) for c in report["changes"]] == [("body", "link6")], report["notes"]
    change = report["changes"][0]
    assert abs(change["value"]["m"] - float(truth["payload"]["mass"])) <= 3 * change["std"]["m"]


def test_changed_runs_after_the_baseline_are_refused_with_the_order(two_runs_a_side):
    folder, _ = two_runs_a_side
    result = CliRunner().invoke(main, ["diagnose", "puma560", "--baseline", str(folder / "base1.csv"),
                                       str(folder / "changed1.csv")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert result.stderr.count("\n") == 1 and "before --baseline" in result.stderr, result.stderr


def test_paths_after_validate_are_validated_not_fitted(tmp_path):
    """identify's --validate OTHER... likewise: 'identify MECH D --validate V1 V2' validates on
    both (V2 was fitted); DATA after them is refused with the order."""
    from baseparams.recordings.simulate import simulate
    mechanism = resolve("planar_2r")
    for k, seed in enumerate((1, 2, 3)):
        write_measured(tmp_path / f"r{k}.csv", simulate(mechanism, samples=300, seed=seed, noise_sd=0.01)[0])
    r0, r1, r2 = (str(tmp_path / f"r{k}.csv") for k in range(3))
    result = CliRunner().invoke(main, ["identify", "planar_2r", r0, "--validate", r1, r2, "--format", "json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert [v["data"] for v in report["validation"]] == [r1, r2], report["validation"]
    wrong = CliRunner().invoke(main, ["identify", "planar_2r", "--validate", r1, r0])
    assert wrong.exit_code == 2 and "before --validate" in wrong.stderr and wrong.stderr.count("\n") == 1


def test_two_runs_a_side_are_paired_run_with_run(tmp_path):
    """Each changed run is paired within a baseline run of its own (change.pair_runs): paired
    against both, the two changed runs took the same baseline partners, their difference rows
    shared that noise across runs, and the rest test read it as structure (nothing changed,
    white noise: p 1e-4 to 0.03 over six seeds, 'unexplained' in one; now 0.39 to 0.56)."""
    from baseparams.diagnose.change import diagnose_change
    from baseparams.recordings.recording import read_data
    mechanism = resolve("puma560")
    pvalues = []
    for seed in range(4):
        before, after, _ = simulate_change(mechanism, samples=1000, seed=seed, noise_level=0.0)
        rng = np.random.default_rng(100 + seed)
        sd = 0.01 * np.sqrt(np.mean(before.tau ** 2, axis=0))
        for k in (1, 2):
            for name, data in (("b", before), ("c", after)):
                write_measured(tmp_path / f"{name}{k}.csv",
                               dataclasses.replace(data, tau=data.tau + rng.standard_normal(data.tau.shape) * sd))
        base, _ = read_data([str(tmp_path / "b1.csv"), str(tmp_path / "b2.csv")], mechanism)
        changed, _ = read_data([str(tmp_path / "c1.csv"), str(tmp_path / "c2.csv")], mechanism)
        result = diagnose_change(mechanism, base, changed)
        assert result.verdict == "nothing changed", (seed, result.verdict, result.notes)
        pvalues.append(result.rest["pvalue"])
    assert np.median(pvalues) > 0.1, pvalues
