"""The identification model (baseparams.dynamics.forces) and the mechanism file's [[effects]].

Checked against independent computations: the inertial columns against the observation
matrix W that the solvers use; an effect on a dependent coordinate against virtual work
(its generalized force on the independent coordinates is dq_i/dz times the force, with
dq_i/dz by finite differences of the loop-closed positions).
"""

import numpy as np
import pytest

from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.observation import observation_matrix
from baseparams.errors import InputError
from baseparams.dynamics.forces import (Motion, design, effect_values, evaluate, independent_names,
                                       standard_parameters)
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.model import generate
from baseparams.model.mechanism import EffectSpec
from baseparams.numeric.backends import Float64


def _motion_along_trajectory(mech, samples=40):
    trajectory = Trajectory.default(mech, samples=samples)
    t = np.array([float(x) for x in trajectory.times])
    z, zd, zdd = trajectory.independent_values(mech, Float64(), t)
    stack = [np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in values], axis=1)
             for values in (z, zd, zdd)]
    return trajectory, Motion(t, *stack)


@pytest.mark.parametrize("text", [generate.serial_chain(3), generate.tree(5), generate.four_bar(2)],
                         ids=["chain", "tree", "four_bar"])
def test_inertial_columns_are_the_observation_matrix(text):
    mech = parse_mechanism(text)
    trajectory, motion = _motion_along_trajectory(mech)
    inertial, _ = design(mech, motion)
    W, _ = observation_matrix(mech, Float64(), trajectory)
    assert inertial.names == tuple(mech.parameters)
    np.testing.assert_allclose(inertial.stacked(), W, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ["sla_suspension", "four_bar"])
def test_effect_on_a_dependent_coordinate_follows_virtual_work(name):
    mech = resolve(name)
    _, motion = _motion_along_trajectory(mech, samples=12)
    dependent = [c for c in mech.coordinates if c not in mech.independent]
    sample = evaluate(mech, motion)
    h = 1e-6
    for coordinate in dependent[:3]:
        i = mech.coordinates.index(coordinate)
        _, effects = design(mech, motion, [EffectSpec("spring", coordinate)], sample=sample)
        for j in range(len(mech.independent)):
            moved = []
            for step in (h, -h):
                q = motion.q.copy()
                q[:, j] += step
                moved.append(np.asarray(evaluate(mech, Motion(motion.t, q, motion.qd, motion.qdd)).q[i]))
            dqi_dz = (moved[0] - moved[1]) / (2 * h)        # central: the SLA's curvature is large
            # spring columns: q_i and -1, each times dq_i/dz_j on independent coordinate j
            np.testing.assert_allclose(effects.matrix[:, j, 0], dqi_dz * np.asarray(sample.q[i]),
                                       atol=1e-4)
            np.testing.assert_allclose(effects.matrix[:, j, 1], -dqi_dz, atol=1e-4)


def test_effect_on_an_independent_coordinate_of_an_open_chain():
    mech = resolve("planar_2r")
    _, motion = _motion_along_trajectory(mech, samples=10)
    names = independent_names(mech)
    _, effects = design(mech, motion, [EffectSpec("viscous_friction", names[1]),
                                       EffectSpec("offset", names[0])])
    assert effects.names == (f"fv_{names[1]}", f"off_{names[0]}")
    np.testing.assert_array_equal(effects.matrix[:, 1, 0], motion.qd[:, 1])
    np.testing.assert_array_equal(effects.matrix[:, 0, 0], 0.0)
    np.testing.assert_array_equal(effects.matrix[:, 0, 1], 1.0)
    np.testing.assert_array_equal(effects.matrix[:, 1, 1], 0.0)


EFFECTS_TOML = """
[[effects]]
kind = "viscous_friction"
coordinate = "{c}"
values = {{ fv = "0.8" }}

[[effects]]
kind = "spring"
coordinate = "{c}"
"""


def _pendulum_text():
    return resolve("pendulum").path and open(resolve("pendulum").path, encoding="utf-8").read()


def test_effects_table_is_read_exactly():
    base = _pendulum_text()
    c = parse_mechanism(base).coordinates[0]
    mech = parse_mechanism(base + EFFECTS_TOML.format(c=c))
    assert [(e.kind, e.coordinate) for e in mech.effects] == [("viscous_friction", c), ("spring", c)]
    assert str(mech.effects[0].values["fv"]) == "4/5"
    with pytest.raises(InputError, match="no value for k"):
        effect_values(mech, mech.effects)
    assert effect_values(mech, mech.effects[:1]).tolist() == [0.8]
    assert standard_parameters(mech).shape == (10,)


@pytest.mark.parametrize("table, key, reason", [
    ('kind = "viscous"\ncoordinate = "{c}"', "effects[0].kind", "unknown effect 'viscous'"),
    ('kind = "offset"\ncoordinate = "nope"', "effects[0].coordinate", "not a tree coordinate"),
    ('kind = "offset"\ncoordinate = "{c}"\nvalues = {{ fv = "1" }}', "effects[0].values.fv",
     "not a coefficient or shape parameter of offset"),
    ('kind = "offset"\ncoordinate = "{c}"\nvalue = "1"', "effects[0]", "unknown key"),
    ('kind = "offset"\ncoordinate = "{c}"\nvalues = {{ off = 0.5 }}', None, None),
])
def test_effects_table_errors_name_the_key(table, key, reason):
    base = _pendulum_text()
    c = parse_mechanism(base).coordinates[0]
    text = base + "\n[[effects]]\n" + table.format(c=c) + "\n"
    if key is None:
        assert str(parse_mechanism(text).effects[0].values["off"]) == "1/2"
        return
    with pytest.raises(InputError) as info:
        parse_mechanism(text)
    assert key in str(info.value) and reason in str(info.value)

