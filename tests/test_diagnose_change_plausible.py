"""diagnose --baseline names no friction change that leaves the changed runs' friction below
zero (core/diagnose/changeplausible.py, issue 42): the rule a single diagnosis applies to a
named effect (a friction coefficient is positive), applied to shared + change."""

import dataclasses
from pathlib import Path

import numpy as np

from baseparams.diagnose.change import diagnose_change, shared_effects
from baseparams.diagnose.changeplausible import impossible_changes, shared_values
from baseparams.diagnose.derived import body_columns
from baseparams.identify.fit import measured_design
from baseparams.io.loader import resolve
from baseparams.model.mechanism import EffectSpec
from baseparams.recordings.recording import read_data

TX40 = Path(__file__).parent / "data" / "tx40"


def test_shared_values_follow_the_shared_columns_and_the_known_effects():
    """theta after the inertial columns holds each shared effect's coefficients in order;
    a known effect's given value stands where the model does not fit one."""
    mechanism = resolve("planar_2r")
    mechanism = dataclasses.replace(mechanism, effects=(EffectSpec("viscous_friction", "q2", {"fv": 0.7}),))
    effects = shared_effects(mechanism)
    assert {e.kind for e in effects} == {"viscous_friction", "coulomb_friction", "offset"}    # one coefficient each
    theta = np.concatenate([np.full(4, 9.0), np.arange(1.0, len(effects) + 1)])
    values = shared_values(mechanism, effects, theta, 4)
    fitted = [(e.kind, e.coordinate) for e in effects]
    assert values[("viscous_friction", "q1")] == 1.0 + fitted.index(("viscous_friction", "q1"))
    assert values[("coulomb_friction", "q2")] == 1.0 + fitted.index(("coulomb_friction", "q2"))
    assert values[("viscous_friction", "q2")] == 0.7                         # known, not fitted
    assert ("offset", "q1") not in values


def test_a_change_is_refused_only_where_the_changed_friction_is_not_positive():
    shared = {("coulomb_friction", "q1"): 5.0, ("viscous_friction", "q1"): 1.0}
    changes = [{"kind": "coulomb_friction", "coordinate": "q1", "value": -5.5, "std": 1.0},
               {"kind": "viscous_friction", "coordinate": "q1", "value": -0.9, "std": 0.1},
               {"kind": "gain", "coordinate": "q1", "value": -0.5, "std": 0.1},
               {"kind": "body", "coordinate": "link", "value": {"m": -3.0}, "std": {"m": 0.1}}]
    refused = impossible_changes(changes, shared)
    assert [(k, c) for k, c, _ in refused] == [("coulomb_friction", "q1")]
    assert "5 -5.5 = -0.5" in refused[0][2]


def _tx40_halves_with_a_load():
    mechanism = resolve(str(TX40 / "tx40_mdh_modified.urdf"))
    before, mechanism = read_data([str(TX40 / "recording.toml") + "#first"], mechanism)
    after, _ = read_data([str(TX40 / "recording.toml") + "#last"], mechanism)
    inertial, _, _ = measured_design(mechanism, after, [], [])
    phi = np.zeros(len(mechanism.parameters))
    x, z = 0.03, 0.05
    phi[body_columns(mechanism, "link_6")] = 2.0 * np.array([1, x, 0, z, z * z, 0, -x * z, x * x + z * z, 0, x * x])
    return mechanism, before, dataclasses.replace(after, tau=after.tau + inertial.matrix @ phi)


def test_the_last_round_drops_what_it_refuses(monkeypatch):
    """With one round only, the refused change is not searched again but still not named."""
    import baseparams.diagnose.change as change
    monkeypatch.setattr(change, "PLAUSIBLE_ROUNDS", 1)
    result = diagnose_change(*_tx40_halves_with_a_load())
    assert ("coulomb_friction", "joint_3") not in {(c["kind"], c["coordinate"]) for c in result.changes}
    assert any("coulomb_friction:joint_3 would leave" in n and n.endswith("not named") for n in result.notes)


def test_real_halves_with_a_load_name_no_friction_that_drives_the_motion():
    """The real TX40's halves (other motions) with a 2 kg load's torque on link_6 added to the
    second: the search named 'coulomb_friction on joint_3: -7.26 +- 0.98' against a shared
    5.67 (the joint pushing with 1.6 N m), with +88 % gain beside it. Every friction change
    named now leaves the friction positive; the refused one is said in a note."""
    result = diagnose_change(*_tx40_halves_with_a_load())
    named = {(c["kind"], c["coordinate"]): c["value"] for c in result.changes}
    assert ("coulomb_friction", "joint_3") not in named, named
    assert any("coulomb_friction:joint_3 would leave the changed runs' friction" in n for n in result.notes)


KINOVA = Path(__file__).parent / "data" / "kinova_gen3"


def test_body_limits_are_a_hundred_times_the_mechanisms_mass_and_reach():
    from baseparams.identify.impossible import body_limits
    from baseparams.identify.impossible import mechanism_size
    mechanism = resolve(str(KINOVA / "gen3.urdf"))
    masses, lengths = mechanism_size(mechanism)
    limits = body_limits(mechanism)
    reach = max(sum(lengths), 1.0)
    assert np.isclose(limits["m"], 100 * sum(masses)) and np.isclose(limits["mx"], 100 * sum(masses) * reach)
    assert np.isclose(limits["Iyz"], 100 * sum(masses) * reach ** 2)
    assert body_limits(resolve("planar_2r")) == {}                      # no masses: nothing judged
    refused = impossible_changes([{"kind": "body", "coordinate": "b", "value": {"m": -2900.0, "mx": None},
                                   "std": {"m": 900.0, "mx": None}},
                                  {"kind": "mass", "coordinate": "c", "value": 2.0, "std": 0.1}], {}, limits)
    assert [(k, c) for k, c, _ in refused] == [("body", "b")]


def test_real_repeat_with_a_load_on_an_inner_link_names_no_body_beyond_any_scale():
    """The real Kinova repeat (133 paired samples) with a 1 kg load's torque on
    spherical_wrist_1_link added to the second run: 'body on half_arm_2_link: -2900 +- 900 kg'
    was named, its ten columns cancelling one another. Now no change is beyond the mechanism's
    scale, and the load's link is among what is named or ambiguous."""
    from baseparams.identify.impossible import body_limits
    mechanism = resolve(str(KINOVA / "gen3.urdf"))
    before, mechanism = read_data([str(KINOVA / "repeat_RunTrajectory1.toml")], mechanism)
    after, _ = read_data([str(KINOVA / "repeat_Trajectory1.toml")], mechanism)
    inertial, _, _ = measured_design(mechanism, after, [], [])
    phi = np.zeros(len(mechanism.parameters))
    x, z = 0.03, -0.06
    phi[body_columns(mechanism, "spherical_wrist_1_link")] = np.array(
        [1, x, 0, z, z * z, 0, -x * z, x * x + z * z, 0, x * x])
    result = diagnose_change(mechanism, before, dataclasses.replace(after, tau=after.tau + inertial.matrix @ phi))
    limits = body_limits(mechanism)
    for change in result.changes:
        values = change["value"] if isinstance(change["value"], dict) else {"m": change["value"]}
        assert all(v is None or abs(v) <= limits[k] for k, v in values.items() if k in limits), change
    places = {c["coordinate"] for c in result.changes} | {m["coordinate"] for g in result.ambiguous
                                                          for m in g["candidates"]}
    assert "spherical_wrist_1_link" in places, (result.changes, result.ambiguous)
