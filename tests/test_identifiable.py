"""A changed body's identifiable combinations (identify/identifiable.py): what the data
determine of its ten parameters beside the rest of the model, and the report that says so
instead of a zero with a standard deviation of zero."""

import sys
from pathlib import Path

import numpy as np

from baseparams.api.render import diagnosis_text
from baseparams.diagnose.derived import body_name
from baseparams.diagnose.workflow import diagnose
from baseparams.diagnose.identifiable import regroup

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import diagnose_campaign as C  # noqa: E402


def test_regroup_finds_the_dependent_coefficients_and_what_they_fold_into():
    rng = np.random.default_rng(3)
    others = rng.standard_normal((200, 3))
    columns = rng.standard_normal((200, 4))
    columns[:, 3] = 2 * columns[:, 0] - 0.5 * columns[:, 1] + others @ [1.0, -2.0, 0.3]   # beyond the others: 2 a - b/2
    columns[:, 2] = others @ [0.2, 0.1, -1.0]                                               # nothing beyond them
    phi = np.array([0.3, -1.2, 0.7, 0.05])
    covariance = np.diag([1.0, 2.0, 3.0, 4.0])
    found = regroup(others, columns, phi, covariance)
    assert found is not None and len(found.kept) == 2
    # which of a and d is kept is the pivoting's choice; the combinations are the same physics
    if found.kept == [0, 1]:
        into = dict(zip(found.absorbed, found.into.T))
        assert np.allclose(into[3], [2.0, -0.5]) and np.allclose(into[2], 0.0, atol=1e-9)
        assert np.allclose(found.values, [0.3 + 2 * 0.05, -1.2 - 0.5 * 0.05])
    else:                                    # d kept: a = d / 2 + b / 4 beyond the others
        assert 3 in found.kept and 2 in found.absorbed
    beyond = columns - others @ np.linalg.lstsq(others, columns, rcond=None)[0]
    # the kept combination reproduces every solution's force beyond the others
    kept = beyond[:, found.kept] @ found.values
    assert np.allclose(kept, beyond @ phi)
    transform = np.zeros((2, 4))
    transform[np.arange(2), found.kept] = 1.0
    transform[:, found.absorbed] = found.into
    assert np.allclose(found.covariance, transform @ covariance @ transform.T)


def test_regroup_leaves_independent_coefficients_alone():
    rng = np.random.default_rng(4)
    assert regroup(rng.standard_normal((100, 2)), rng.standard_normal((100, 3)), np.zeros(3), np.eye(3)) is None
    assert regroup(np.zeros((100, 0)), rng.standard_normal((100, 3)), np.zeros(3), np.eye(3)) is None


def test_a_payload_on_a_four_bars_rocker_reports_what_the_data_determine():
    """A generated four-bar (one coordinate): a payload on its last body, a rocker turning
    about its frame's origin, moves the torque through its first moments and its inertia
    about that axis, not through its mass. Reported before as ``m = 0 +- 0`` (one solution of
    many, with a certainty the data do not hold); now the mass is not identifiable and the
    combinations given are the truth's within their standard deviations (4 of 8 datasets
    named the body, the others reported it ambiguous with the coupler, which it moves alike;
    since the payload candidate, mass and first moments, 7 of 8 name that)."""
    s = C.generated_setting("four_bar2", 1200)
    rng = np.random.default_rng(2024)
    hits = 0
    for _ in range(8):
        phi = C.random_physical_inertia(s.mechanism, rng)
        k = max(i for i in range(len(s.mechanism.bodies)) if np.any(s.problem.inertial[:, :, 10 * i:10 * i + 10]))
        m = 1.5
        c = np.array([0.06, 0.0, -0.04])
        extra = np.array([m, *(m * c), m * (c @ c) - m * c[0] ** 2, -m * c[0] * c[1], -m * c[0] * c[2],
                          m * (c @ c) - m * c[1] ** 2, -m * c[1] * c[2], m * (c @ c) - m * c[2] ** 2])
        truth = phi.copy()
        truth[10 * k:10 * k + 10] += extra
        clean = s.problem.inertial @ truth
        tau = clean + rng.standard_normal(clean.shape) * 0.02 * np.sqrt(np.mean(clean ** 2, axis=0))
        d = diagnose(C.payload_problem(s, phi), tau)
        named = [e for e in d.effects if e["kind"] in ("body", "payload")]    # its body, or the load alone
        if not named:                          # or ambiguous with body2, which it moves alike
            continue
        assert [e["coordinate"] for e in named] == [body_name(s.mechanism, s.mechanism.bodies[k].label)]
        coefficients = named[0]["coefficients"]
        assert coefficients["m"]["value"] is None and coefficients["m"]["std"] is None
        assert "not identifiable on their own here: m" in diagnosis_text(d)
        for name, entry in coefficients.items():
            if entry["value"] is None:
                continue
            names = list(coefficients)
            expected = extra[names.index(name)] + sum(
                into.get(name, 0.0) * extra[names.index(other)]
                for other, into in ((o, e["absorbed_into"]) for o, e in coefficients.items() if e["value"] is None))
            assert abs(entry["value"] - expected) <= 4 * entry["std"] + 1e-9, (name, entry, expected)
            assert entry["std"] > 0
        hits += 1
    assert hits >= 3


def test_a_payload_under_coloured_noise_is_named_as_a_body_not_its_point_mass_stand_in():
    """A payload on a generated tree's last body (its centre 2-10 cm off the frame's origin)
    under AR(1) 0.9 noise: the changed body was held back by the stability check (its ten
    coefficients' spread over the blocks was 0.56 of their norm, mostly along directions the
    motion barely excites) and the point mass at the frame's origin named in its place, with
    its mass 4-42 % off at 2-34 of its stated standard deviations; the
    spread is now measured in the force the body exerts. These five datasets of the
    campaign's stream (``payload_table``) all named the point mass; now the body or the payload
    (mass and first moments, issue 42), its mass within 10 %."""
    s = C.generated_setting("tree1", 1200)
    rng = np.random.default_rng(2025)
    for _ in range(20):
        C.payload(s, rng)                              # the white rows come first in the stream
    datasets = [C.payload(s, rng, rho=0.9) for _ in range(17)]
    for k in (5, 10, 13, 14, 16):
        tau, body, mass, phi = datasets[k]
        d = diagnose(C.payload_problem(s, phi), tau)
        assert [(e["kind"], e["coordinate"]) for e in d.effects] in ([("body", body)], [("payload", body)])
        assert abs(d.effects[0]["coefficients"]["m"]["value"] - mass) <= 0.1 * mass


def test_the_stability_spread_of_one_coefficient_is_its_relative_spread():
    """Measured in the force the effect exerts, the spread of a one-coefficient effect is the
    same ratio as in its coefficient (the rows' scale cancels)."""
    from baseparams.diagnose.outofsample import block_coefficients, stability
    rng = np.random.default_rng(5)
    n = 600
    columns = rng.standard_normal((n, 2, 1))
    partial = 1.5 * columns[:, :, 0] * np.repeat([1.0, 1.4, 0.7, 1.2, 0.9], n // 5)[:, None] \
        + 0.1 * rng.standard_normal((n, 2))
    weights = np.array([1.0, 3.0])
    result = stability(partial, columns, weights)
    estimates, covariances = block_coefficients(partial, columns, weights)
    precision = [1.0 / c[0, 0] for c in covariances]
    pooled = sum(p * e[0] for p, e in zip(precision, estimates)) / sum(precision)
    assert np.isclose(result.spread, np.sqrt(np.mean((estimates[:, 0] - pooled) ** 2)) / abs(pooled))


def test_named_bodies_that_the_motion_moves_alike_are_said_to_share_what_they_add():
    """Two named changed bodies whose masses move the joints alike: each mass is determined
    alone, not beside the other (a Z1's payload named as 0.395 kg on link06 and 0.557 kg on
    link04): the report says the split is not in the data, once for the pair."""
    from baseparams.diagnose import entries
    from baseparams.diagnose.derived import COEFFICIENTS
    from baseparams.diagnose.selection import Candidate
    rng = np.random.default_rng(6)
    n, f = 300, 2
    a, b = rng.standard_normal((n, f, 10)), rng.standard_normal((n, f, 10))
    b[:, :, 0] = a[:, :, 0]
    bodies = [Candidate("body", "link1", COEFFICIENTS["body"], a), Candidate("body", "link2", COEFFICIENTS["body"], b)]
    y = a @ rng.uniform(0.1, 1, 10) + b @ rng.uniform(0.1, 1, 10) + 0.01 * rng.standard_normal((n, f))
    regrouped = entries._regroupings(np.zeros((n, f, 0)), bodies, [0, 1], [0, 1], y, np.ones(f))
    assert regrouped[0].absorbed == [0] and regrouped[0].shared == ((0,), (1,))
    assert regrouped[1].absorbed == [0] and regrouped[1].shared == ((0,), (0,))
    notes = entries._shared_bodies(bodies, regrouped)
    assert len(notes) == 1 and notes[0].startswith("body:link1 and body:link2: the motion moves them alike")
    # alone, each body's ten are determined: nothing to regroup, nothing shared
    assert entries._regroupings(np.zeros((n, f, 0)), bodies, [0], [0], y, np.ones(f)) == {}
