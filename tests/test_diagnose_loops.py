"""What changed on a closed-chain arm (issue 49 parts 2 and 3): bodies that move together
through a closed loop (core/diagnose/loopbodies.py), a load on a parallelogram link named on
it or on its stated equivalents with its mass, and advice that follows the geometry.
Rates over 20 seeds per link: benchmarks/bench_diagnose_loops.py (docs/diagnosis.md)."""

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

from baseparams.api.render import _ambiguous_line, change_text
from baseparams.diagnose.change import diagnose_change
from baseparams.diagnose.derived import body_name
from baseparams.diagnose.identifiable import regroup
from baseparams.diagnose.loopbodies import cycle, equivalence
from baseparams.dynamics.forces import Motion, evaluate, inertial_columns
from baseparams.io.loader import resolve
from baseparams.model import generate
from baseparams.recordings.simulate import simulate_change, trajectory_motion

warnings.filterwarnings("ignore")


@pytest.fixture(scope="module")
def arm():
    return resolve("parallelogram_arm")


def point_load(m: float, c) -> np.ndarray:
    """A point mass's ten parameters at ``c`` in a body's axes (design.md's order and signs)."""
    x, y, z = c
    return m * np.array([1.0, x, y, z, y * y + z * z, -x * y, -x * z, x * x + z * z, -y * z, x * x + y * y])


def columns(mechanism, still: bool, seed: int = 1) -> np.ndarray:
    """K at the default trajectory's positions with random speeds and accelerations, the yaw
    still or not: rows drawn here, independently of the module's own states."""
    motion = trajectory_motion(mechanism, 40)
    rng = np.random.default_rng(seed)
    qd, qdd = rng.standard_normal(motion.qd.shape), rng.standard_normal(motion.qd.shape)
    if still:
        qd[:, 0] = qdd[:, 0] = 0.0
    k = inertial_columns(evaluate(mechanism, Motion(motion.t, motion.q, qd, qdd)), motion.count)
    return k.reshape(-1, k.shape[-1])


def test_the_arm_s_loops_and_which_links_they_move_together(arm):
    names = {b.label: body_name(arm, b.label) for b in arm.bodies}
    assert {names[b] for b in cycle(arm, "front_top")} == {"yaw_link", "pitch_back", "pitch_top", "pitch_front"}
    assert {names[b] for b in cycle(arm, "bottom_end")} == {"pitch_back", "pitch_top", "pitch_end", "pitch_bottom"}
    top = equivalence(arm, ["pitch_back", "pitch_top"])
    assert top is not None and top.separated_by == ("yaw",)
    assert "every load on pitch_top acts as one on pitch_back" in top.reason
    assert "only a motion of yaw" in top.separate_by and "wider range of positions" not in top.separate_by
    front = equivalence(arm, ["pitch_back", "pitch_front"])
    assert front is not None and "acts as one on pitch_back and back" in front.reason
    # the loop's base turns with the yaw only, a carriage slides: neither moves with the links
    assert equivalence(arm, ["yaw_link", "pitch_back"]) is None
    assert equivalence(arm, ["pitch_back", "carriage"]) is None
    assert equivalence(arm, ["pitch_top"]) is None


def test_a_load_on_the_top_beam_is_a_load_at_the_back_link_s_tip_while_the_yaw_is_still(arm):
    """Closed form: the top beam translates with the back link's tip (0, 0, a), so a point mass
    at the beam's origin is the same point mass at that tip for every motion with the yaw still;
    off the beam's origin along x it is not once the yaw turns (its distance from the yaw axis
    changes differently), which is why the yaw is the motion that separates them."""
    k = {b: slice(10 * i, 10 * i + 10) for i, b in enumerate(body_name(arm, x.label) for x in arm.bodies)}
    a = 0.3
    for still in (True, False):
        K = columns(arm, still)
        on_beam = K[:, k["pitch_top"]] @ point_load(0.2, (0.0, 0.0, 0.0))
        at_tip = K[:, k["pitch_back"]] @ point_load(0.2, (0.0, 0.0, a))
        assert np.max(np.abs(on_beam - at_tip)) <= 1e-9 * np.max(np.abs(on_beam))
    still, moving = columns(arm, True), columns(arm, False)
    off_axis = point_load(0.2, (0.1, 0.0, 0.0))
    for K, alike in ((still, True), (moving, False)):
        force = K[:, k["pitch_top"]] @ off_axis
        back = K[:, k["pitch_back"]]
        fitted = back @ np.linalg.lstsq(back, force, rcond=None)[0]
        assert (np.linalg.norm(force - fitted) <= 1e-9 * np.linalg.norm(force)) == alike


def test_a_planar_parallelogram_s_links_no_motion_can_separate():
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "parallelogram.toml"
        path.write_text(generate.four_bar(1, parallelogram=True))
        mechanism = resolve(str(path))
        found = equivalence(mechanism, ["body1", "body3"])
    assert found is not None and found.separated_by == ()
    assert found.separate_by.startswith("no motion can")


def test_regroup_keeps_a_body_s_mass_before_its_inertia():
    """Of dependent coefficients the mass is kept (the first a reader asks of a load), the
    later one absorbed into it: pivoting kept an end link's inertia and called its mass not
    identifiable (issue 49)."""
    rng = np.random.default_rng(5)
    columns = rng.standard_normal((300, 4))
    columns[:, 0] *= 1e-3                              # the mass: a small column
    columns[:, 3] = 40.0 * columns[:, 0]               # an inertia that moves the torques as the mass does
    found = regroup(np.zeros((300, 0)), columns, np.array([0.2, 1.0, -1.0, 0.001]), np.eye(4))
    assert found is not None and found.kept == [0, 1, 2] and found.absorbed == [3]
    assert np.isclose(found.values[0], 0.2 + 40.0 * 0.001)


@pytest.mark.parametrize("link, seed", [("pitch_top", 0), ("pitch_top", 2), ("pitch_bottom", 2),
                                        ("pitch_bottom", 1)])
def test_a_load_on_a_parallelogram_link_is_named_with_its_equivalents_and_its_mass(arm, link, seed):
    """205 g on a beam (the issue's load): before, ambiguous between the top beam and the back
    link, nothing named. Now one change, named on the beam (where the data fix its mass) with
    the links that move with it as stated alternatives, the mass within 10 % (AR(1) 0.9 noise).
    On seed 1 an offset on the pitch was named beside the load: it borrowed its force from the
    load's columns (the size check now weighs what a change adds to the others)."""
    index = {body_name(arm, b.label): i for i, b in enumerate(arm.bodies)}
    before, after, truth = simulate_change(arm, samples=2000, seed=seed, noise="ar1", payload_mass=0.205,
                                           payload_body=index[link])
    result = diagnose_change(arm, before, after)
    assert result.verdict == "changed" and not result.ambiguous
    (change,) = result.changes
    assert change["coordinate"] == link and change["kind"] in ("body", "mass")
    assert abs(change["coefficients"]["m"]["value"] - 0.205) <= 0.1 * 0.205
    assert change["alternatives"] and change["equivalent"]["separated_by"] == ["yaw"]
    assert all(a["coordinate"] in change["equivalent"]["bodies"] for a in change["alternatives"])
    text = change_text(result)
    assert "or, equivalently, body on" in text and "only a motion of yaw" in text
    assert "wider range of positions" not in text


@pytest.mark.parametrize("seed", [0, 1])
def test_nothing_added_nothing_named(arm, seed):
    before, after, _ = simulate_change(arm, samples=2000, seed=seed, noise="ar1")
    assert diagnose_change(arm, before, after).verdict == "nothing changed"


def test_an_ambiguous_group_of_loop_bodies_is_reported_equivalent_with_the_geometry_s_advice(arm):
    """The single-set diagnosis' report of an ambiguous group of body candidates on links that
    move together: the reason and the motion the geometry allows, not "a wider range of
    positions, so that the transmission ratios differ" (what a group of one kind was told)."""
    group = {"candidates": [{"kind": "body", "coordinate": "pitch_back"}, {"kind": "body", "coordinate": "pitch_top"}],
             "evidence": [{"correlation": 0.9999}], "strongest": "body:pitch_back"}
    found = equivalence(arm, ["pitch_back", "pitch_top"])
    line = _ambiguous_line({**group, "equivalent": found.reason, "separate_by": found.separate_by})
    assert line.startswith("equivalent: body:pitch_back | body:pitch_top: pitch_back and pitch_top move together")
    assert "to separate them: only a motion of yaw" in line and "transmission ratios" not in line
