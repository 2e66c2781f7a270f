"""diagnose's text report read in a minute (issue 42, part 4): the default text fits one
screen (at most 25 lines, whatever the data) with the verdict, the gap, each named effect on
one line with its unit, the ambiguous groups, where the gap remains, a count of what was not
named and the most important notes; ``--verbose`` is the whole report. On a real UR10e payload
run the report was 52 lines, 30 of them "not named (unsupported)"."""

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

import baseparams as bp
from baseparams.api.render import MAX_LINES, diagnosis_text, short_text
from baseparams.cli import main


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """planar_2r with two hidden frictions and a held-out block (0.2 CPU s to diagnose)."""
    path = tmp_path_factory.mktemp("report") / "d.csv"
    bp.simulate("planar_2r", output=path, effects=["viscous_friction:q1=0.5", "coulomb_friction:q2=0.3"],
                noise=0.01, seed=1, samples=600)
    return path


@pytest.fixture(scope="module")
def diagnosed(data):
    return bp.diagnose("planar_2r", data, holdout=0.2)


def _effect(kind, coordinate, values, stds, gain, shape=None, known=None):
    coefficients = {k: {"value": v, "std": s} for k, v, s in zip(values, values.values(), stds)}
    single = len(values) == 1
    entry = {"kind": kind, "coordinate": coordinate,
             "value": next(iter(values.values())) if single else dict(values),
             "std": stds[0] if single else dict(zip(values, stds)), "coefficients": coefficients,
             "test": {"stat": 50.0 + gain, "df": len(values), "pvalue": 1e-9, "pvalue_holm": 1e-8},
             "rivals": [], "checks": {"cv_gain": gain}}
    if shape:
        entry["shape"] = shape
    if known:
        entry["known"] = known
    return entry


BODY = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")


def _named():
    """Named effects of every kind the report words physically, on an angle (q1, q2), a length
    (s1) and bodies."""
    m = 2.62
    body = dict(zip(BODY, [m, m * 0.01, m * -0.02, m * 0.05, 0.01, 0.0, 0.0, 0.01, 0.0, 0.005]))
    absorbed = dict(zip(BODY, [None, None, 0.3, 0.1, 0.01, 0.0, 0.0, 0.01, 0.0, 0.005]))
    out = [_effect("viscous_friction", "q2", {"fv": 0.5213}, [0.0104], 3.0),
           _effect("coulomb_friction", "q1", {"fc": 1.234}, [0.021], 2.0, shape={"vs": 0.05}),
           _effect("viscous_friction", "s1", {"fv": 1503.38}, [1.4], 1.5),
           _effect("spring", "s1", {"k": 25000.0, "kq0": 12.0}, [300.0, 2.0], 1.2),
           _effect("rotor_inertia", "q2", {"Ia": 0.0123}, [0.0004], 0.9),
           _effect("delay", "all", {"d": 0.0041}, [0.0003], 0.8, shape={"low_pass_hz": 12.0}),
           _effect("gain", "q1", {"g": -0.102}, [0.003], 0.7),
           _effect("mass", "link1", {"m": 0.23}, [0.01], 0.6),
           _effect("body", "wrist_3_link", body, [0.04] + [0.001] * 9, 0.5),
           _effect("body", "link2", absorbed, [None, None] + [0.001] * 8, 0.4),
           _effect("load_friction", "q2", {"mu": 0.05}, [0.01], 0.3),
           _effect("viscous_friction", "q1", {"fv": 0.1}, [0.02], 0.2, known={"fv": 0.5})]
    for entry in out:
        if entry["kind"] == "body" and entry["coordinate"] == "link2":
            entry["coefficients"]["m"]["absorbed_into"] = {"my": 0.2}
            entry["coefficients"]["mx"]["absorbed_into"] = {"mz": -0.1}
    return out


KINDS = {"q1": "angle", "q2": "angle", "s1": "length"}


def _crowded(d, effects, ambiguous=8, unsupported=40, notes=20, holdout=True, stopped=False):
    """The real diagnosis ``d`` with many named effects, ambiguous groups, candidates not named
    and notes (a long recording's reading notes first, the verdict's own reason last)."""
    groups = [{"candidates": [{"kind": "offset", "coordinate": f"q{k}", "pvalue": 1e-5, "pvalue_holm": 1e-4},
                              {"kind": "coulomb_friction", "coordinate": f"q{k}", "pvalue": 1e-5,
                               "pvalue_holm": 1e-4}],
               "strongest": f"offset:q{k}", "evidence": [{"candidate": f"coulomb_friction:q{k}", "correlation": 0.99,
                                                         "pvalue": 1e-5, "pvalue_strongest_over_it": 0.3,
                                                         "pvalue_it_over_strongest": 0.4}],
               "separate_by": "hold the direction of motion for longer in both directions", "reason": "..."}
              for k in range(ambiguous)]
    lost = [{"kind": "cogging", "coordinate": f"joint_{k}", "values": {},
             "reason": f"too small to name: a held-out block improves by {k} % (case {k})"} for k in range(unsupported)]
    said = [f"/data/rec.toml: run{k}: positions low-passed at 36.67 Hz (10 x the positions' bandwidth)"
            for k in range(notes - 3)]
    said += ["an unusual remark on the data,\nover two lines",
             "spring:q2 was named, then taken out: once the effects named after it are in, it adds nothing "
             "significant", "structure remains: the residual follows the motion on q1"]
    unexplained = {**d.unexplained, "significant_candidates_left": stopped, "max_steps": 3 if stopped else None,
                   "confusable_with_model": [{"candidate": f"spring:q{k}", "separate_by": "change the pose"}
                                             for k in range(5)]}
    gap = dict(d.gap) if holdout else {**d.gap, "holdout_before": None, "holdout_after": None}
    where = {"blocks": [{"t": [1.0, 2.0], "ratio": {"q1": 3.0}}],
             "concentrated": [{"coordinate": f"q{k}", "regime": "reversal", "ratio": 2.0 + k} for k in range(6)]}
    return replace(d, verdict="partly explained", closed=False, effects=effects, ambiguous=groups,
                   unsupported=lost, notes=said, unexplained=unexplained, gap=gap, where=where,
                   untestable=[f"rotor_inertia:q{k} (absorbed)" for k in range(7)])


def test_the_default_text_fits_a_screen_with_many_candidates_not_named_and_many_notes(diagnosed):
    d = _crowded(diagnosed.diagnosis, _named(), ambiguous=2)
    text = diagnosis_text(d, kinds=KINDS)
    lines = text.splitlines()
    assert len(lines) <= MAX_LINES, text
    assert lines[0] == "verdict: PARTLY EXPLAINED: the named effects close part of the gap; structure remains"
    assert lines[1].startswith("gap (NRMS, blocks predicted from the others, 5 blocks): ")
    # every named effect, one line each, in physical terms
    named = [line for line in lines if line.startswith("  ") and " on " in line]
    assert len(named) == len(d.effects)
    for e in d.effects:
        assert sum(line.startswith(f"  {e['kind']} on ") and e["coordinate"] in line for line in named) >= 1
    for words in ("viscous_friction on q2: 0.521 +- 0.010 N m s/rad",
                  "coulomb_friction on q1: 1.23 +- 0.02 N m, vs = 0.05 rad/s",
                  "viscous_friction on s1: 1503.4 +- 1.4 N s/m",
                  "spring on s1: k = 25000 +- 300 N/m, kq0 = 12 +- 2 N",
                  "rotor_inertia on q2: 0.0123 +- 0.0004 kg m^2",
                  "delay on all drives: 4.1 +- 0.3 ms",
                  "gain on q1: -10.2 +- 0.3 % of the torque",
                  "mass on link1: 0.230 +- 0.010 kg at its frame's origin",
                  "body on wrist_3_link: 2.62 +- 0.04 kg at (0.010, -0.020, 0.050) m in its axes",
                  "body on link2: not identifiable on their own here: m, mx",
                  "load_friction on q2: 0.050 +- 0.010 x |tau|",
                  "viscous_friction on q1: 0.10 +- 0.02 N m s/rad correcting the model's own fv = 0.5 "
                  "(total fv = 0.6)"):
        assert words in text, (words, text)
    assert "low_pass_hz" not in text and "(p = " not in text          # the method's details: --verbose
    assert sum(line.startswith("ambiguous: ") for line in lines) == 2
    # what was not named: counted on one line, listed by --verbose
    assert "not named (unsupported):" not in text
    assert ("40 candidates not named (unsupported), 5 nearly collinear with the inertial model, 7 not testable "
            "on this data; --verbose lists them and ") in text
    assert lines[-1].startswith("note: ") and sum(line.startswith("note: ") for line in lines) <= 3
    # the verdict's own reason first among the notes; how the data were read left to --verbose
    assert next(line for line in lines if line.startswith("note: ")) == \
        "note: structure remains: the residual follows the motion on q1"
    assert "low-passed" not in text
    assert lines[-1] == "note: an unusual remark on the data, over two lines"
    assert sum(line.startswith("where the gap remains: ") for line in lines) == 1


def test_verbose_is_the_whole_report(diagnosed):
    d = _crowded(diagnosed.diagnosis, _named())
    text = diagnosis_text(d, verbose=True)
    for u in d.unsupported:
        assert f"not named (unsupported): {u['kind']} on {u['coordinate']}: {u['reason']}" in text
    for note in d.notes:
        assert f"note: {note}" in text
    for e in d.effects:
        assert f"  {e['kind']} on {e['coordinate']}: " in text
    assert "residual / noise level (second differences): " in text and "whiteness (Ljung-Box, " in text
    assert "not testable on this data (7): " in text
    assert diagnosis_text(d, verbose=True, kinds=KINDS) == text      # units are the short report's
    assert len(text.splitlines()) > 80


def test_more_named_effects_than_fit_show_the_largest_and_say_how_many_more(diagnosed):
    rng = np.random.default_rng(3)
    gains = rng.permutation(40) / 10.0
    effects = [_effect("viscous_friction", f"q{k}", {"fv": 0.1 * k + 0.1}, [0.01], float(gains[k]))
               for k in range(40)]
    d = _crowded(diagnosed.diagnosis, effects)
    lines = short_text(d, kinds={f"q{k}": "angle" for k in range(40)}).splitlines()
    assert len(lines) <= MAX_LINES
    shown = [line for line in lines if line.startswith("  viscous_friction on ")]
    more = next(line for line in lines if line.startswith("  and ") and "more" in line)
    assert more == f"  and {40 - len(shown)} more, smaller (--verbose lists every named effect)"
    assert len(shown) >= 8
    # the largest (how much better each predicts a typical held-out block), in the report's order
    largest = sorted(range(40), key=lambda k: -gains[k])[:len(shown)]
    assert [line.split(":")[0].split()[-1] for line in shown] == [f"q{k}" for k in sorted(largest)]
    assert any(line.startswith("ambiguous: ") for line in lines)
    assert any(line.startswith("and ") and "more ambiguous groups" in line for line in lines)
    assert any(line.startswith("note: structure remains") for line in lines)


@pytest.mark.parametrize("seed", range(40))
def test_the_default_text_is_never_longer_than_a_screen(diagnosed, seed):
    """Whatever the counts: named effects, ambiguous groups, candidates not named, notes, a
    holdout, a search stopped at --max-steps, a written file."""
    rng = np.random.default_rng(seed)
    effects = [_effect("offset", f"q{k}", {"off": 0.3}, [0.01], float(rng.random()))
               for k in range(int(rng.integers(0, 60)))]
    d = _crowded(diagnosed.diagnosis, effects, ambiguous=int(rng.integers(0, 30)),
                 unsupported=int(rng.integers(0, 80)), notes=int(rng.integers(3, 40)),
                 holdout=bool(rng.integers(0, 2)), stopped=bool(rng.integers(0, 2)))
    written = "fixed.toml" if rng.integers(0, 2) else None
    text = diagnosis_text(d, written)
    assert len(text.splitlines()) <= MAX_LINES, text
    if d.unexplained["significant_candidates_left"]:
        assert "the search stopped at --max-steps 3 with candidates still significant" in text
    if written:
        assert text.endswith("written: fixed.toml")
    said = [line for line in text.splitlines() if line.startswith("  offset on ")]
    assert len(said) == len(effects) or f"  and {len(effects) - len(said)} more, smaller" in text


def test_the_short_report_of_a_real_diagnosis(diagnosed):
    text = diagnosed.to_text()
    lines = text.splitlines()
    assert diagnosed.kinds == {"q1": "angle", "q2": "angle"}
    assert lines[0] == "verdict: EXPLAINED: the named effects close the gap to the noise level"
    assert lines[2].startswith("last block kept out: ")
    assert lines[3] == "named effects:"
    fv = diagnosed.diagnosis.effects[[e["kind"] for e in diagnosed.diagnosis.effects].index("viscous_friction")]
    (line,) = [line for line in lines if line.startswith("  viscous_friction on q1: ")]
    value, pm, std, unit = line.split(": ")[1].split(" ", 3)
    assert (pm, unit) == ("+-", "N m s/rad")
    assert abs(float(value) - fv["value"]) <= 0.05 * fv["std"] and float(std) == pytest.approx(fv["std"], rel=0.25)
    assert any(line.startswith("  coulomb_friction on q2: ") and line.endswith(" N m") for line in lines)
    assert str(diagnosed) == text and diagnosed.to_text(verbose=True) == diagnosis_text(diagnosed.diagnosis,
                                                                                        verbose=True)


def test_the_verb_prints_the_short_report_and_the_whole_one_with_verbose(data):
    runner = CliRunner()
    short = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--quiet"])
    assert short.exit_code == 0, short.output + short.stderr
    full = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--quiet", "--verbose"])
    assert full.exit_code == 0, full.output + full.stderr
    assert len(short.stdout.splitlines()) <= MAX_LINES
    assert "residual / noise level" not in short.stdout and "(p = " not in short.stdout
    assert " N m s/rad" in short.stdout
    for line in ("residual / noise level (second differences): ", "whiteness (Ljung-Box, ", "samples: ",
                 "nearly collinear with the inertial model (", "(p = "):
        assert line in full.stdout, line
    assert short.stdout.splitlines()[:2] == full.stdout.splitlines()[:2]
    # JSON holds everything with or without --verbose
    plain = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--quiet", "--format", "json"])
    verbose = runner.invoke(main, ["diagnose", "planar_2r", str(data), "--quiet", "--format", "json", "--verbose"])
    assert json.loads(plain.stdout) == json.loads(verbose.stdout)


def test_a_p_value_that_underflowed_is_printed_below_the_smallest_double():
    """A change far above the noise has a Holm p of exactly 0.0 in float64 (the PUMA's 5000
    paired samples, a payload on link6): printed 'p < 1e-300', not 'p = 0'."""
    from baseparams.api.render import _p
    assert _p(0.0) == "p < 1e-300" and _p(2.4e-5) == "p = 2.4e-05" and _p(1e-320) == "p = 1e-320"


def test_a_load_taken_off_is_reported_with_its_place():
    """The runs given the other way round (the payload's run as the baseline): the change is a
    negative body on link6, printed as a load taken off, at the load's place (its first moments
    over its mass: the same point either way), within 3 std of the simulated payload."""
    from baseparams.diagnose.change import diagnose_change
    from baseparams.api.render import change_text
    from baseparams.io.loader import resolve
    from baseparams.recordings.simulate import simulate_change
    mechanism = resolve("puma560")
    before, after, truth = simulate_change(mechanism, samples=2000, seed=1, payload=0.5, noise="white")
    result = diagnose_change(mechanism, after, before)
    assert [(c["kind"], c["coordinate"]) for c in result.changes] == [("body", "link6")], result.notes
    change = result.changes[0]
    m, sd = change["value"]["m"], change["std"]["m"]
    assert abs(m + truth["payload"]["mass"]) <= 3 * sd
    assert np.allclose(change["centre_of_mass"], truth["payload"]["centre"], atol=0.01), change["centre_of_mass"]
    line = next(line for line in change_text(result).splitlines() if "body on link6" in line)
    assert "(a load taken off) at (" in line, line
