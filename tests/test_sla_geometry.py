"""The rebuilt SLA keeps every length the seed paper prints, along the whole trajectory.

Positions come from the tree kinematics and Newton's loop closure in world axes; the
lengths are measured between world points, so a wrong frame in the file or a loop that
fails to close shows up here.
"""

import numpy as np
import pytest

from baseparams.io.loader import resolve
from baseparams.dynamics.trajectory import Trajectory, samples_float64


@pytest.fixture(scope="module")
def sla():
    mech = resolve("sla_suspension")
    sample, times = samples_float64(mech, Trajectory.default(mech, samples=1000))
    g = {k: float(v) for k, v in mech.geometry.items()}
    return mech, sample, times.shape, g


def point(sample, body, local, shape):
    s = sample.states[body]
    return np.array([np.broadcast_to(s.pos[i] + sum(s.rot[i][j] * local[j] for j in range(3)), shape)
                     for i in range(3)])


def axis(sample, body, local, shape):
    s = sample.states[body]
    return np.array([np.broadcast_to(sum(s.rot[i][j] * local[j] for j in range(3)), shape) for i in range(3)])


def distance_to_line(p, origin, direction):
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    r = p - np.asarray(origin, float)[:, None]
    return np.linalg.norm(r - np.outer(d, d @ r), axis=0)


def test_arms_keep_their_lengths(sla):
    mech, s, shape, g = sla
    G = point(s, 1, (0, 0, 0), shape)
    D = point(s, 2, (0, 0, 0), shape)
    assert np.allclose(distance_to_line(G, (0, 0, 0), (1, 0, 0)), g["D12"] + g["D13"], atol=1e-12)
    upper_axis_point = (0, g["D12"] + g["D13"] - g["D22"], g["L7"])
    assert np.allclose(distance_to_line(D, upper_axis_point, (1, 0, 0)), g["D22"], atol=1e-12)
    H = point(s, 1, (-g["D13"], 0, 0), shape)
    assert np.allclose(np.linalg.norm(H - G, axis=0), g["D13"], atol=1e-12)


def test_hub_closes_on_both_ball_joints(sla):
    mech, s, shape, g = sla
    G = point(s, 1, (0, 0, 0), shape)
    D = point(s, 2, (0, 0, 0), shape)
    assert np.allclose(point(s, 3, (0, 0, -g["L7"] / 2), shape), G, atol=1e-11)
    assert np.allclose(point(s, 3, (0, 0, g["L7"] / 2), shape), D, atol=1e-11)
    assert np.allclose(np.linalg.norm(D - G, axis=0), g["L7"], atol=1e-11)


def test_tie_rod_length_and_wheel_axis(sla):
    mech, s, shape, g = sla
    J = np.array([-g["D31"], g["D12"] + g["D13"] - g["L10"], g["L7"] / 2])
    T = point(s, 3, (g["D31"], 0, 0), shape)
    assert np.allclose(np.linalg.norm(T - J[:, None], axis=0), g["L10"], atol=1e-11)
    assert np.allclose(point(s, 4, (g["L10"], 0, 0), shape), J[:, None], atol=1e-11)
    K = point(s, 3, (g["DKx"], g["DKy"], g["DKz"] + g["L7"] / 2), shape)
    assert np.allclose(point(s, 5, (0, 0, 0), shape), K, atol=1e-11)
    assert np.allclose(axis(s, 5, (1, 0, 0), shape), -axis(s, 3, (0, 1, 0), shape), atol=1e-11)


def test_damper_slides_between_its_mounts(sla):
    mech, s, shape, g = sla
    H = point(s, 1, (-g["D13"], 0, 0), shape)
    assert np.allclose(point(s, 7, (0, 0, 0), shape), H, atol=1e-11)
    C = np.array([-g["Cx"], g["D12"] - g["Cy"], g["Cz"]])
    assert np.allclose(point(s, 6, (0, 0, 0), shape), C[:, None], atol=1e-12)
    along = axis(s, 6, (0, 0, 1), shape)
    unit = (H - C[:, None]) / np.linalg.norm(H - C[:, None], axis=0)
    assert np.allclose(along, unit, atol=1e-11)                   # H stays on the damper axis
    assert np.allclose(axis(s, 7, (0, 0, 1), shape), along, atol=1e-11)


def test_motion_is_spatial_where_the_paper_needs_it(sla):
    """The special planar geometries that drop base parameters are avoided (docs/sla_geometry.md):
    the damper swings out of the arms' plane and the tie rod's second U axis tilts against gravity."""
    mech, s, shape, g = sla
    q = {name: np.broadcast_to(v, shape) for name, v in zip(mech.coordinates, s.q)}
    assert np.ptp(q["damper_2"]) > 0.1 and np.ptp(q["damper_1"]) > 0.1
    z4 = axis(s, 4, (0, 0, 1), shape)
    assert np.ptp(z4[2]) > 0.05            # g . z4 varies: a dipole along z4 is felt
