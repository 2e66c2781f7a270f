"""Couplings between joint coordinates on mechanisms with closed loops (issue 49): a
follower (``[[couplings]]``: a cable-driven counterweight, a belt, a gear) is one more
closure equation, solved with the loops'.

Checked against computations that do not use that path:
- a random parallelogram with coupled bodies against its tree form (the loop cut, its
  dependent angles written as couplings of the crank: the open-chain path, no closure):
  the same regressor at every state, the same dp and certified vp ranks;
- a random four-bar with coupled bodies against the same four-bar with the followers made
  free (independent) and composed by hand: K = Rc^T K_free;
- along simulated motion: the positions' time derivative is the velocity the projection
  gives (every tree coordinate, followers included), the coupling holds, and the power of
  the forces is the energy's derivative;
- arb (certified, generated scalar closure and the generic kinematics) encloses float64,
  and the batched float64 Newton agrees with the general one.
"""

import json
import re
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner
from flint import arb

from baseparams import registry
from baseparams.cli import main
from baseparams.dynamics import evaluator as evaluator_module
from baseparams.dynamics.evaluator import Evaluator
from baseparams.errors import InputError
from baseparams.io.loader import parse_mechanism
from baseparams.io.toml_writer import mechanism_toml
from baseparams.model import generate
from baseparams.numeric.backends import Arb, Float64

SEEDS = range(6)


def _states(seed: int, count: int, f: int = 1) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    return ([rng.uniform(-0.5, 0.5, count) for _ in range(f)], [rng.normal(size=count) for _ in range(f)],
            [rng.normal(size=count) for _ in range(f)])


def _k(mech, z, zd, zdd) -> np.ndarray:
    return Evaluator(mech, Float64()).sample(z, zd, zdd).regressor_array()


@pytest.mark.parametrize("seed", SEEDS)
def test_a_parallelogram_with_couplings_is_its_tree_form(seed):
    """Loops + couplings against the tree with couplings (no closure solved): K equal to
    rounding at every state (batched Newton over 300 states, the general path over 20),
    and the same rank from dp and from vp (certified) in both forms."""
    loop = parse_mechanism(generate.coupled_loop(seed, parallelogram=True))
    tree = parse_mechanism(generate.coupled_loop(seed, parallelogram=True, tree=True))
    assert loop.loops and loop.couplings and not tree.loops
    assert loop.parameters == tree.parameters
    for count in (20, 300):
        z, zd, zdd = _states(seed, count)
        k_loop, k_tree = _k(loop, z, zd, zdd), _k(tree, z, zd, zdd)
        assert np.abs(k_loop - k_tree).max() <= 1e-12 * np.abs(k_tree).max()
    solvers = registry.solvers()
    ranks = {(m.name, s): solvers[s].item.solve(m) for m in (loop, tree) for s in ("dp", "vp")}
    assert len({r.rank for r in ranks.values()}) == 1, {k: r.rank for k, r in ranks.items()}
    assert ranks[(loop.name, "vp")].certified


def _free_form(text: str) -> str:
    """The same mechanism with every coupling left out and its follower made independent."""
    head, _, _ = text.partition("\n[[couplings]]")
    followers = [line.split('"')[1] for line in text.split("\n") if line.startswith('coordinate = "qe')]
    listed = ", ".join(f'"{c}"' for c in ["qa"] + followers)
    still = "".join(f'{c} = "0", ' for c in followers)
    return head.replace('independent = ["qa"]', f"independent = [{listed}]").replace("q = { ", "q = { " + still)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_coupled_four_bar_is_the_free_one_composed_by_hand(seed):
    """A general four-bar (dependent angles nonlinear in the crank) with followers: K equals
    Rc^T K_free, where the free mechanism has the followers independent and is evaluated
    where the followers' coupling puts them (velocities and accelerations by the chain rule
    from the free loop's own solution): no coupling equation anywhere in this reference."""
    text = generate.coupled_loop(seed)
    mech, free = parse_mechanism(text), parse_mechanism(_free_form(text))
    z, zd, zdd = _states(seed + 10, 60)
    coupled = Evaluator(mech, Float64()).sample(z, zd, zdd)
    # the loop's own coordinates do not depend on the extra bodies: solve them once
    count = len(z[0])
    extra = len(free.independent) - 1
    zero = [np.zeros(count)] * extra
    first = Evaluator(free, Float64()).sample(z + zero, zd + zero, zdd + zero)
    names = list(free.coordinates)
    fz, fzd, fzdd, column = list(z), list(zd), list(zdd), [np.ones(count)]
    for c in mech.couplings:
        lead, r, o = names.index(c.leader), float(c.ratio), float(c.offset)
        fz.append(r * first.q[lead] + o)
        fzd.append(r * first.qd[lead])
        fzdd.append(r * first.qdd[lead])
        column.append(r * np.broadcast_to(first.projection[lead][0], (count,)))   # d follower / d qa
    k_free = Evaluator(free, Float64()).sample(fz, fzd, fzdd).regressor_array()    # (N, 1 + extra, p)
    expected = np.einsum("fs,sfp->sp", np.array(column), k_free)[:, None, :]
    k = coupled.regressor_array()
    assert np.abs(k - expected).max() <= 1e-11 * np.abs(expected).max()
    for c in mech.couplings:                               # the positions themselves
        i, j = names.index(c.coordinate), names.index(c.leader)
        np.testing.assert_allclose(coupled.q[i], float(c.ratio) * coupled.q[j] + float(c.offset), atol=1e-13)


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_the_motion_is_consistent_and_the_energy_balances(seed):
    """Along a simulated motion: dq/dt (finite differences of the Newton positions, which
    never read R) is qd = R zd for every tree coordinate, and tau . zd = d(T + V)/dt."""
    from baseparams.dynamics.forces import evaluate
    from baseparams.recordings.simulate import simulate
    mech = parse_mechanism(generate.coupled_loop(seed))
    data, truth = simulate(mech, samples=4001, random_inertia=True, seed=seed)
    sample = evaluate(mech, data.motion)
    t = data.motion.t
    for i, name in enumerate(mech.coordinates):
        q = np.broadcast_to(np.asarray(sample.q[i], float), t.shape)
        qd = np.broadcast_to(np.asarray(sample.qd[i], float), t.shape)
        derivative = np.gradient(q, t, edge_order=2)
        assert np.abs(derivative - qd)[2:-2].max() < 1e-4 * max(1.0, np.abs(qd).max()), name
    phi = np.array([truth["parameters"][p] for p in mech.parameters])
    t_form, v_form = sample.energies()
    energy = sum(np.broadcast_to(np.asarray(c, float), t.shape) * p for c, p in zip(t_form + v_form, np.tile(phi, 2)))
    power = np.sum(data.tau * data.motion.qd, axis=1)
    assert np.abs(np.gradient(energy, t, edge_order=2) - power)[2:-2].max() < 1e-4 * np.abs(power).max()


@pytest.mark.parametrize("seed", SEEDS[:4])
def test_every_path_of_the_closure_agrees(seed, monkeypatch):
    """The batched float64 Newton against the general one; one state in arb (certified:
    Krawczyk over loops and couplings) by the generated scalar closure and by the generic
    kinematics, each enclosing the float64 regressor; the follower's row of R is exactly
    the ratio times the leader's (its ball contains that)."""
    mech = parse_mechanism(generate.coupled_loop(seed))
    z, zd, zdd = _states(seed, 80)
    batched = _k(mech, z, zd, zdd)
    monkeypatch.setattr(evaluator_module, "BATCHED_NEWTON", False)
    np.testing.assert_allclose(_k(mech, z, zd, zdd), batched, rtol=0, atol=1e-11 * np.abs(batched).max())
    state = [Fraction(float(v[0])) for v in z], [Fraction(float(v[0])) for v in zd], [Fraction(float(v[0])) for v in zdd]
    names = list(mech.coordinates)
    for scalar in (True, False):
        monkeypatch.setattr(evaluator_module, "SCALAR_CLOSURE", scalar)
        backend = Arb(40)
        with backend.activate():
            ev = Evaluator(mech, backend, certify=True)
            sample = ev.sample(*([backend.rational(v) for v in part] for part in state))
            k = sample.regressor()
            for row, expected in zip(k, batched[0]):
                for ball, value in zip(row, expected):
                    assert abs(arb(ball).mid() - value) <= 1e-9 * max(1.0, np.abs(batched).max())
                    assert arb(ball).rad() < 1e-25
            for c in mech.couplings:
                i, j = names.index(c.coordinate), names.index(c.leader)
                gap = sample.projection[i][0] - backend.rational(c.ratio) * sample.projection[j][0]
                assert arb(gap).contains(0)
                assert (sample.q[i] - backend.rational(c.ratio) * sample.q[j] - backend.rational(c.offset)).contains(0)


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_validate_passes_and_solvers_decline_with_reasons(tmp_path, seed):
    path = tmp_path / f"coupled_loop_{seed}.toml"
    path.write_text(generate.coupled_loop(seed))
    result = CliRunner().invoke(main, ["validate", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    (checked,) = json.loads(result.stdout)["mechanisms"]
    checks = {c["name"]: c["ok"] for c in checked["checks"]}
    assert checks["energy balance"] and checks["ranks"] and checks["space vp ~ dp"], checks
    mech = parse_mechanism(path.read_text())
    assert "closed loop" in (registry.solvers()["exact"].item.applicable(mech) or "")
    assert "transfer rules" in (registry.solvers()["symbolic"].item.applicable(mech) or "")


def test_a_coupled_loop_round_trips_through_the_writer():
    mech = parse_mechanism(generate.coupled_loop(1))
    back = parse_mechanism(mechanism_toml(mech))
    assert back.couplings == mech.couplings and back.independent == mech.independent and len(back.loops) == 1
    assert all(isinstance(c.ratio, Fraction) for c in back.couplings)


def test_identification_on_a_coupled_loop_recovers_the_base_parameters():
    from baseparams.identify.base import BaseModel
    from baseparams.identify.fit import identify
    from baseparams.recordings.simulate import simulate
    mech = parse_mechanism(generate.coupled_loop(1))
    data, truth = simulate(mech, samples=800, random_inertia=True, seed=3)
    assert data.coordinates == ("qa",)
    base = BaseModel.from_result(registry.solvers()["vp"].item.solve(mech), mech)
    result = identify(mech, data, base=base)
    expected = base.values(np.array([truth["parameters"][p] for p in mech.parameters]))
    # noise-free data: the estimates are the truth up to rounding times the fit's condition
    # number (a one-degree-of-freedom motion excites some base parameters only weakly)
    assert result.nrms.max() < 1e-9
    error = np.abs(result.base_estimates - expected).max() / np.abs(expected).max()
    assert error < 1e-15 * result.condition_number, (error, result.condition_number)


# ----- what is refused, and how it is said ---------------------------------------------------
PARALLELOGRAM = generate.four_bar(1, parallelogram=True)


@pytest.mark.parametrize("table, key, reason", [
    ('coordinate = "qb"\nleader = "qa"\nratio = "-1"', "couplings[0]", "follows from the closed loops"),
    ('coordinate = "qa"\nleader = "qb"\nratio = "2"', "coordinates.independent", "'qa' follows 'qb'"),
    ('coordinate = "qb"\nleader = "qa"\nratio = "2"', "coordinates.independent", "coupling(s) included"),
    ('coordinate = "qc"\nleader = "qa"', "couplings[0].coordinate", "not a tree coordinate"),
])
def test_bad_couplings_on_a_loop_are_named(tmp_path, table, key, reason):
    text = PARALLELOGRAM + f"\n[[couplings]]\n{table}\n"
    with pytest.raises(InputError) as info:
        parse_mechanism(text)
    assert key in str(info.value) and reason in str(info.value)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["show", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output + result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("error: ") and str(path) in line and key in line


def test_the_parallelogram_s_own_angles_as_couplings_agree_exactly():
    """generate.four_bar(parallelogram=True) really is a parallelogram: qb = -qa and
    qd = qa at every state (what the tree form writes as couplings)."""
    mech = parse_mechanism(PARALLELOGRAM)
    z, zd, zdd = _states(3, 50)
    s = Evaluator(mech, Float64()).sample(z, zd, zdd)
    names = list(mech.coordinates)
    qa, qb, qd = (np.asarray(s.q[names.index(c)]) for c in ("qa", "qb", "qd"))
    np.testing.assert_allclose(qb, -qa, atol=1e-14)
    np.testing.assert_allclose(qd, qa, atol=1e-14)


# ----- the built-in parallelogram arm with its counterweight -----------------------------------
def _arm_tree_form(text: str) -> str:
    """parallelogram_arm as the authors of such an arm write it: the tree, the loop joints
    left out and the passive angles as couplings of the pitch (the counterweight's stays)."""
    import re
    text = re.sub(r'(# loop \d[^\n]*\n)?\[\[joints\]\]\nname = "(front_top|bottom_end)"\n(?:(?!\n\n).)*\n', "", text,
                  flags=re.S)
    assert "loop = true" not in text
    extra = "".join(f'\n[[couplings]]\ncoordinate = "{c}"\nleader = "pitch"\nratio = "{r}"\n' for c, r in
                    (("pitch_front", 1), ("pitch_top", -1), ("pitch_end", 1), ("pitch_bottom", -1)))
    return text.replace('name = "parallelogram_arm"', 'name = "parallelogram_arm_tree"') + extra


def test_the_parallelogram_arm_is_its_tree_form():
    """Issue 49, done when: the arm written as loops plus a coupling loads, its rank equals
    the tree-with-couplings form's, certified by vp, and the regressors are equal."""
    from baseparams.io.loader import resolve
    from baseparams.registry import mechanisms
    arm = resolve("parallelogram_arm")
    tree = parse_mechanism(_arm_tree_form(mechanisms()["parallelogram_arm"].item.path.read_text()))
    assert len(arm.loops) == 2 and not tree.loops and arm.independent == tree.independent
    assert [c.coordinate for c in arm.couplings] == ["counterweight"]
    rng = np.random.default_rng(49)
    count = 120
    z = [rng.uniform(-0.8, 0.8, count), rng.uniform(-0.8, 0.8, count), rng.uniform(0, 0.24, count)]
    zd, zdd = [rng.normal(size=count) for _ in range(3)], [rng.normal(size=count) for _ in range(3)]
    k_arm, k_tree = _k(arm, z, zd, zdd), _k(tree, z, zd, zdd)
    assert np.abs(k_arm - k_tree).max() <= 1e-12 * np.abs(k_tree).max()
    solvers = registry.solvers()
    results = [solvers[s].item.solve(m) for m in (arm, tree) for s in ("dp", "vp")]
    assert [r.rank for r in results] == [15] * 4
    assert results[1].certified and results[3].certified


def test_validate_passes_on_the_parallelogram_arm():
    result = CliRunner().invoke(main, ["validate", "parallelogram_arm", "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    (checked,) = json.loads(result.stdout)["mechanisms"]
    assert checked["ok"] and all(c["ok"] for c in checked["checks"])
    assert {c["name"] for c in checked["checks"]} >= {"energy balance", "ranks", "space vp ~ dp"}
    shown = json.loads(CliRunner().invoke(main, ["show", "parallelogram_arm", "--format", "json"]).stdout)
    assert shown["dof"] == 3 and shown["closure_equations"] - shown["redundant_closure_equations"] == 5


# ----- coordinates no motion can move apart (issue 49, part 3) ---------------------------------
def test_tied_coordinates_are_found_from_loops_and_couplings():
    """parallelogram_arm: the passive angles are +-1 times the pitch (a loop, found at random
    states) and the counterweight -1 times the insertion (the coupling); a four-bar's
    rocker is not tied (its ratio changes with the crank), nor is anything in a tree
    without couplings; a generated coupled loop's followers are tied with their ratio."""
    from baseparams.dynamics.tied import ties, tied_group
    from baseparams.io.loader import resolve
    arm = resolve("parallelogram_arm")
    found = {t.coordinate: (t.leader, round(t.ratio, 12), t.how) for t in ties(arm)}
    assert found == {"pitch_front": ("pitch", 1.0, "loop"), "pitch_top": ("pitch", -1.0, "loop"),
                     "pitch_end": ("pitch", 1.0, "loop"), "pitch_bottom": ("pitch", -1.0, "loop"),
                     "counterweight": ("insertion", -1.0, "coupling")}
    assert tied_group(arm, ["pitch_front", "pitch_end"]) is not None
    assert tied_group(arm, ["pitch", "insertion"]) is None and tied_group(arm, ["pitch", "pitch"]) is None
    assert ties(resolve("four_bar")) == () and ties(resolve("puma560")) == ()
    for seed in range(3):
        mech = parse_mechanism(generate.coupled_loop(seed))
        tied = {t.coordinate: t for t in ties(mech)}
        for c in mech.couplings:
            t = tied[c.coordinate]
            assert t.leader == c.leader and abs(t.ratio - float(c.ratio)) < 1e-9 and t.how == "coupling"


@pytest.mark.parametrize("seed, ratio, offset", [(1, "-3/4", "0.05"), (3, "1.3", "0")])
def test_two_loops_with_their_cranks_coupled(seed, ratio, offset):
    """Two four-bars in series (the second standing on the first's rocker) whose cranks a
    belt couples, qa1 = ratio qa0 + offset: a follower that is a loop's own driving
    coordinate. K equals the free ladder's (both cranks independent) composed by hand,
    K_qa0 + ratio K_qa1, at the state the coupling puts the free ladder in."""
    free_text = generate.ladder(2, seed=seed)
    coupled_text = (free_text.replace('independent = ["qa0", "qa1"]', 'independent = ["qa0"]')
                    .replace(", qa1 = ", ", unused = ").split("\n[trajectory]")[0]
                    + '\n[trajectory]\nt_start = "0"\nt_end = "10"\nsamples = 200\n'
                    + 'q = { qa0 = "0.3*sin(1.3*t) + 0.2*sin(2.9*t + 1) + 0.1*sin(0.7*t)" }\n'
                    + f'\n[[couplings]]\ncoordinate = "qa1"\nleader = "qa0"\nratio = "{ratio}"\noffset = "{offset}"\n')
    free, coupled = parse_mechanism(free_text), parse_mechanism(coupled_text)
    assert coupled.independent == ("qa0",) and len(coupled.loops) == 2
    r, o = float(Fraction(ratio)), float(Fraction(offset))
    (z,), (zd,), (zdd,) = _states(seed, 40)
    z = 0.4 * z
    k = _k(coupled, [z], [zd], [zdd])
    k_free = _k(free, [z, r * z + o], [zd, r * zd], [zdd, r * zdd])
    expected = k_free[:, :1, :] + r * k_free[:, 1:, :]
    assert np.abs(k - expected).max() <= 1e-11 * np.abs(expected).max()
    # one degree of freedom drives every body: many base parameters, weakly excited (vp's
    # s_r near 1e-17 on seed 1), so dp is asked to agree only on a rich trajectory
    results = [registry.solvers()[s].item.solve(coupled) for s in ("dp", "vp")]
    assert results[0].rank == results[1].rank and results[1].certified


@pytest.mark.parametrize("seed", [20, 25])
def test_single_states_stay_on_the_parallelogram_branch(seed):
    """One state at a time (the excitation check's random draws) by continuation from the
    reference: a parallelogram with a short coupler, whose plain Newton stages folded onto
    the crossed branch (qb = -6.98 = -0.7 - 2 pi, or qb = 3.65 with qd = 0.51 at qa = 0.8),
    stays a parallelogram: qb = -qa and qd = qa up to 1 rad of crank; and its rank equals
    its tree form's (dp and vp), which the folded draws had raised (9 -> 13, vp 14)."""
    mech = parse_mechanism(generate.coupled_loop(seed, parallelogram=True))
    tree = parse_mechanism(generate.coupled_loop(seed, parallelogram=True, tree=True))
    ev = Evaluator(mech, Float64())
    names = list(mech.coordinates)
    for qa in (0.5, 0.7, 0.8, 0.9, 1.0, -0.8, -1.0):
        q = ev.assemble([qa])
        assert abs(q[names.index("qb")] + qa) < 1e-12 and abs(q[names.index("qd")] - qa) < 1e-12
    solvers = registry.solvers()
    ranks = {(m.name, s): solvers[s].item.solve(m).rank for m in (mech, tree) for s in ("dp", "vp")}
    assert len(set(ranks.values())) == 1, ranks


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6, 30))
def test_more_generated_coupled_loops(seed):
    """The default run's checks on 24 more seeds of each family: a parallelogram's regressor
    is its tree form's, and dp and vp (certified) agree on every coupled loop."""
    loop = parse_mechanism(generate.coupled_loop(seed, parallelogram=True))
    tree = parse_mechanism(generate.coupled_loop(seed, parallelogram=True, tree=True))
    z, zd, zdd = _states(seed, 100)
    k_loop, k_tree = _k(loop, z, zd, zdd), _k(tree, z, zd, zdd)
    assert np.abs(k_loop - k_tree).max() <= 1e-12 * np.abs(k_tree).max()
    solvers = registry.solvers()
    for mech in (loop, tree, parse_mechanism(generate.coupled_loop(seed))):
        dp, vp = (solvers[s].item.solve(mech) for s in ("dp", "vp"))
        assert dp.rank == vp.rank and vp.certified, mech.name


def test_diagnose_reports_tied_candidates_as_equivalent(tmp_path):
    """A viscous friction on a parallelogram's passive angle (simulated on pitch_top, which
    moves as -1 x pitch): every candidate of that kind on the tied angles gives the same
    column for every motion. diagnose says so, with the ties, never advises a motion, and
    gives the group's coefficient as one effect (the ratio is -1: the value itself)."""
    data = tmp_path / "friction.csv"
    result = CliRunner().invoke(main, ["simulate", "parallelogram_arm", "-o", str(data), "--samples", "3000",
                                       "--noise", "0.02", "--seed", "5", "--effect",
                                       "viscous_friction:pitch_top=0.3", "--quiet"])
    assert result.exit_code == 0, result.output + result.stderr
    result = CliRunner().invoke(main, ["diagnose", "parallelogram_arm", str(data), "--format", "json"])
    report = json.loads(result.stdout)
    groups = [g for g in report["ambiguous"] if "equivalent" in g]
    named = [e for e in report["effects"] if e["kind"] == "viscous_friction"]
    assert groups or named, report
    for g in groups:
        coordinates = {c["coordinate"] for c in g["candidates"]}
        assert coordinates <= {"pitch", "pitch_front", "pitch_top", "pitch_end", "pitch_bottom"}
        assert "closed loop" in g["equivalent"] and g["separate_by"].startswith("no motion can")
        assert "wider range" not in g["separate_by"]
        (value,) = g["value"]
        assert abs(value - 0.3) < 0.015
    for e in named:
        assert abs(e["value"] - 0.3) < 0.015
    text = CliRunner().invoke(main, ["diagnose", "parallelogram_arm", str(data)]).stdout
    assert "wider range" not in text and ("equivalent:" in text or "viscous_friction" in text)
    if groups and not report["effects"]:        # the verdict's "explained" is not contradicted
        assert "named effects: none alone; the gap is closed by one effect of each ambiguous group" in text


def test_a_body_named_like_a_tied_coordinate_is_not_called_equivalent():
    """parallelogram_arm names its bodies as its coordinates (body pitch_top turns on the
    coordinate pitch_top): body, mass and gain candidates are not on joint coordinates,
    and two bodies are never 'tied' by the coordinates' names."""
    from baseparams.diagnose.selection import Candidate
    from baseparams.diagnose.entries import tied_reason
    from baseparams.io.loader import resolve
    arm = resolve("parallelogram_arm")
    column = np.zeros((4, 3, 1))
    bodies = [Candidate("body", name, ("m",), column) for name in ("pitch_top", "pitch_front")]
    assert tied_reason(arm, bodies) is None
    frictions = [Candidate("viscous_friction", name, ("fv",), column) for name in ("pitch_top", "pitch_front")]
    assert "closed loop" in (tied_reason(arm, frictions) or "")
    mixed = [Candidate("viscous_friction", "pitch_top", ("fv",), column), Candidate("offset", "pitch", ("off",), column)]
    assert tied_reason(arm, mixed) is None
    counterweight = [Candidate("offset", name, ("off",), column) for name in ("insertion", "counterweight")]
    assert "coupling" in (tied_reason(arm, counterweight) or "")


def test_effects_on_the_counterweight_and_a_passive_angle_are_identified(tmp_path):
    """Forces on dependent coordinates of the looped arm (a viscous friction on the coupled
    counterweight's slide, Coulomb friction on the passive pitch_top) reach the independent
    coordinates through R^T: simulated without noise, identify gives them back."""
    from baseparams.registry import mechanisms
    data = tmp_path / "effects.csv"
    result = CliRunner().invoke(main, ["simulate", "parallelogram_arm", "-o", str(data), "--samples", "1500",
                                       "--seed", "2", "--effect", "viscous_friction:counterweight=1.5",
                                       "--effect", "coulomb_friction:pitch_top=0.2", "--quiet"])
    assert result.exit_code == 0, result.output + result.stderr
    text = mechanisms()["parallelogram_arm"].item.path.read_text().replace(
        "[coordinates]", '[[effects]]\nkind = "viscous_friction"\ncoordinate = "counterweight"\n\n'
                         '[[effects]]\nkind = "coulomb_friction"\ncoordinate = "pitch_top"\n\n[coordinates]')
    arm = tmp_path / "arm.toml"
    arm.write_text(text)
    result = CliRunner().invoke(main, ["identify", str(arm), str(data), "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    found = {(e["kind"], e["coordinate"]): e["coefficients"][0]["value"] for e in json.loads(result.stdout)["effects"]}
    assert found[("viscous_friction", "counterweight")] == pytest.approx(1.5, rel=1e-9)
    assert found[("coulomb_friction", "pitch_top")] == pytest.approx(0.2, rel=1e-9)


# ----- an exact rank for a looped mechanism, through its tree form ------------------------------
def _parallelogram_tree(text: str) -> str:
    """A generated parallelogram (four_bar(parallelogram=True)) cut at its loop joint, the
    dependent angles written as couplings of the crank: qb = -qa, qd = qa."""
    import re
    text = re.sub(r'\[\[joints\]\]\nname = "JC"\n(?:(?!\n\n).)*\n', "", text, flags=re.S)
    assert "loop = true" not in text
    return text + "".join(f'\n[[couplings]]\ncoordinate = "{c}"\nleader = "qa"\nratio = "{r}"\n'
                          for c, r in (("qb", -1), ("qd", 1)))


@pytest.mark.parametrize("seed", range(4))
def test_an_exact_rank_for_a_parallelogram_through_its_tree_form(seed):
    """The exact solver declines loops, but a parallelogram's tree form (couplings of ratio
    +-1 and offset 0 between angles: tan(-theta/2) = -tan(theta/2) keeps an exact angle
    exact) is open: its exact rank (rref over the rationals) equals the loop form's dp and
    certified vp ranks, and the exact solver still says why for any other angle ratio."""
    text = generate.four_bar(seed, parallelogram=True)
    loop, tree = parse_mechanism(text), parse_mechanism(_parallelogram_tree(text))
    solvers = registry.solvers()
    assert solvers["exact"].item.applicable(tree) is None
    exact = solvers["exact"].item.solve(tree)
    ranks = [exact.rank] + [solvers[s].item.solve(loop).rank for s in ("dp", "vp")]
    assert len(set(ranks)) == 1 and exact.certified, ranks
    halved = parse_mechanism(_parallelogram_tree(text).replace('ratio = "-1"', 'ratio = "-1/2"'))
    assert "rational points of the circle" in (solvers["exact"].item.applicable(halved) or "")


def test_the_parallelogram_arm_s_rank_is_exact_through_its_tree_form():
    from baseparams.registry import mechanisms
    tree = parse_mechanism(_arm_tree_form(mechanisms()["parallelogram_arm"].item.path.read_text()))
    result = registry.solvers()["exact"].item.solve(tree)
    assert result.rank == 15 and result.certified


def test_the_exact_solver_declines_a_unit_ratio_between_an_angle_and_a_length():
    """Ratio 1, offset 0, but an angle following a length (or a length an angle): no rational
    point of the circle then; the exact solver says why, as before."""
    text = generate.serial_chain(0, bodies=3, types="RP")          # q1 R, q2 P, q3 R
    text = re.sub(r'(, )?q3 = "[^"]*"', "", text)
    mech = parse_mechanism(text + '\n[[couplings]]\ncoordinate = "q3"\nleader = "q2"\n')
    assert "rational points of the circle" in (registry.solvers()["exact"].item.applicable(mech) or "")
