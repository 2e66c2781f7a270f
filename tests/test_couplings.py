"""Joint coordinates that follow another linearly (``[[couplings]]``: a gear train between
joints, URDF ``<mimic>``), on generated chains: every solver that applies agrees and the
energy balances (validate), the forces' power equals the energy's derivative along a
simulated motion, identification recovers the base parameters, and bad couplings are named."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli import main
from baseparams.errors import InputError
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify
from baseparams.dynamics.forces import evaluate
from baseparams.recordings.simulate import simulate
from baseparams.io.loader import parse_mechanism
from baseparams.io.toml_writer import mechanism_toml
from baseparams.model import generate

SEEDS = [0, 1, 2, 4, 5, 7]


@pytest.mark.parametrize("seed", SEEDS)
def test_solvers_agree_and_the_energy_balances(tmp_path, seed):
    path = tmp_path / f"coupled_{seed}.toml"
    path.write_text(generate.coupled_chain(seed))
    result = CliRunner().invoke(main, ["validate", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    (checked,) = json.loads(result.stdout)["mechanisms"]
    checks = {c["name"]: c["ok"] for c in checked["checks"]}
    assert checks["energy balance"] and checks["ranks"] and checks["space vp ~ dp"], checks
    assert checked["ok"]


@pytest.mark.parametrize("seed", SEEDS[:3])
def test_power_of_the_forces_is_the_energy_derivative(seed):
    """tau . zd (tau on the independent coordinates, R^T K) = d(T + V)/dt from the energy forms
    of the tree, where the follower moves too: a wrong coupling row in R would break it."""
    mech = parse_mechanism(generate.coupled_chain(seed))
    data, truth = simulate(mech, samples=4001, random_inertia=True, seed=seed)
    phi = np.array([truth["parameters"][p] for p in mech.parameters])
    t_form, v_form = evaluate(mech, data.motion).energies()
    n = data.count
    energy = sum(np.broadcast_to(np.asarray(c, float), (n,)) * p for c, p in zip(t_form + v_form, np.tile(phi, 2)))
    power = np.sum(data.tau * data.motion.qd, axis=1)
    derivative = np.gradient(energy, data.motion.t, edge_order=2)
    assert np.abs(derivative - power)[2:-2].max() < 1e-4 * np.abs(power).max()
    follower = mech.couplings[0]
    sample = evaluate(mech, data.motion)
    i, j = mech.coordinates.index(follower.coordinate), mech.coordinates.index(follower.leader)
    np.testing.assert_allclose(sample.q[i], float(follower.ratio) * sample.q[j] + float(follower.offset))
    np.testing.assert_allclose(sample.qd[i], float(follower.ratio) * sample.qd[j])


def test_identification_recovers_the_base_parameters():
    mech = parse_mechanism(generate.coupled_chain(4))
    data, truth = simulate(mech, samples=800, random_inertia=True, seed=3)
    assert data.coordinates == mech.independent and mech.couplings[0].coordinate not in data.coordinates
    base = BaseModel.from_result(registry.solvers()["vp"].item.solve(mech), mech)
    result = identify(mech, data, base=base)
    phi = np.array([truth["parameters"][p] for p in mech.parameters])
    np.testing.assert_allclose(result.base_estimates, base.values(phi), atol=1e-8 * np.abs(base.values(phi)).max())


def test_couplings_round_trip_and_the_exact_solver_says_why_not():
    mech = parse_mechanism(generate.coupled_chain(2))
    back = parse_mechanism(mechanism_toml(mech))
    assert back.couplings == mech.couplings and back.independent == mech.independent
    reason = registry.solvers()["exact"].item.applicable(mech)
    assert reason and "rational points of the circle" in reason


@pytest.mark.parametrize("table, key", [
    ('coordinate = "q9"\nleader = "q1"', "couplings[0].coordinate"),
    ('coordinate = "q2"\nleader = "q2"', "couplings[0].leader"),
    ('coordinate = "q2"\nleader = "q1"\nratio = "0"', "couplings[0].ratio"),
    ('coordinate = "q2"\nleader = "q1"\nratio = "x"', "couplings[0].ratio"),
])
def test_bad_couplings_are_named(table, key):
    text = generate.serial_chain(3, bodies=3, types="R")
    with pytest.raises(InputError) as info:
        parse_mechanism(text + f"\n[[couplings]]\n{table}\n")
    assert key in str(info.value)


def test_couplings_on_a_closed_loop_are_accepted():
    """Issue 49 (tests/test_loop_couplings.py checks them): a follower on a mechanism with a
    loop is one more closure equation; it stays dependent."""
    mech = parse_mechanism(generate.coupled_loop(0))
    assert mech.loops and mech.couplings and mech.couplings[0].coordinate not in mech.independent


def test_a_chain_of_couplings_is_refused():
    text = generate.serial_chain(1, bodies=3, types="R")
    with pytest.raises(InputError, match="follows another coordinate itself"):
        parse_mechanism(text + '\n[[couplings]]\ncoordinate = "q2"\nleader = "q1"\n'
                               '[[couplings]]\ncoordinate = "q3"\nleader = "q2"\n')


MIMIC_URDF = """<robot name="gripper">
  <link name="base"/>
  <link name="arm"><inertial><mass value="2"/><origin xyz="0.2 0 0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.03"/></inertial></link>
  <link name="left"><inertial><mass value="0.3"/><origin xyz="0.02 0.01 0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="right"><inertial><mass value="0.3"/><origin xyz="0.02 -0.01 0.01"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="finger_left" type="prismatic"><parent link="arm"/><child link="left"/>
    <origin xyz="0.4 0.02 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="finger_right" type="prismatic"><parent link="arm"/><child link="right"/>
    <origin xyz="0.4 -0.02 0" rpy="0 0 1.5707963267948966"/><axis xyz="1 0 0"/>
    <limit lower="-0.04" upper="0" effort="1" velocity="1"/>
    <mimic joint="finger_left" multiplier="-1" offset="0"/></joint>
</robot>
"""


def test_urdf_mimic_joints_are_couplings(tmp_path):
    """A gripper whose right finger mimics the left one (multiplier -1): read as a coupling,
    the default trajectory keeps the follower inside its limits, and every solver that
    applies agrees with the energy balance."""
    path = tmp_path / "gripper.urdf"
    path.write_text(MIMIC_URDF)
    from baseparams.io.loader import load_mechanism
    mech = load_mechanism(path)
    (coupling,) = mech.couplings
    assert (coupling.coordinate, coupling.leader, coupling.ratio, coupling.offset) == \
        ("finger_right", "finger_left", -1, 0)
    assert mech.independent == ("shoulder", "finger_left")
    result = CliRunner().invoke(main, ["validate", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output + result.stderr
    (checked,) = json.loads(result.stdout)["mechanisms"]
    assert checked["ok"] and {c["name"]: c["ok"] for c in checked["checks"]}["energy balance"]
    bad = tmp_path / "bad.urdf"
    bad.write_text(MIMIC_URDF.replace('mimic joint="finger_left"', 'mimic joint="nope"'))
    loose = load_mechanism(bad)            # as Pinocchio loads it: the follower moves on its own
    assert not loose.couplings and "finger_right" in loose.independent
    assert any("mimic.joint" in w and "'nope' is not a joint" in w for w in loose.warnings)
