"""Parity with Pinocchio on the URDF robots of tests/data/urdf (docs/urdf.md, "Pinocchio parity").

Pinocchio reads the same files with its own URDF parser (urdfdom) and computes the joint
torque regressor and RNEA with its own algorithms: an independent implementation of the
file's meaning and of the dynamics. Compared, on random states:

- the inertial parameters (Pinocchio's, from its reading of <inertial> and its merging of
  fixed links, against ours with ``merge_fixed``), to 1e-12;
- the regressor: ours against ``computeJointTorqueRegressor`` with its columns reordered
  (Pinocchio's body order is m, mc_x, mc_y, mc_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz about the
  joint frame) to 1e-12 relative;
- the torques K phi against ``rnea``;
- our dp solver's base-parameter count against the rank of Pinocchio's stacked regressor,
  with fixed links merged and kept.

and on every URDF of example-robot-data that Pinocchio loads (when it is installed), unedited,
mimic joints projected onto their couplings (tests/urdf_reference.py): torques and dp's count.

Conventions. Pinocchio's continuous joints have q = (cos, sin). Its free-flyer velocity is
not a coordinate derivative: v = (R^T p', omega in the base frame), and a = dv/dt. Our Free
joint's coordinates are x, y, z and Cardan angles a, b, c (R = Rx(a) Ry(b) Rz(c)), so
v = S(q) q' with S = diag(R^T, R^T E(a, b)) and a = S q'' + S' q'; since the generalized
forces are dual to the velocities, our regressor must equal S^T Y_pinocchio. Both S and S'q'
are written below in closed form, so the comparison is exact, not a finite difference.

Angles the reader snaps to multiples of pi/2 (within 1e-9 by design, e.g. iiwa's
1.57079632679) are given to Pinocchio at full double precision, so both use the same
geometry; a separate check shows the snap changes nothing above 1e-9.
"""

import re
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio", reason="Pinocchio (pip install pin) is an optional test dependency")

from baseparams import registry  # noqa: E402
from baseparams.dynamics.evaluator import Evaluator  # noqa: E402
from baseparams.errors import InputError  # noqa: E402
from baseparams.numeric.backends import Float64  # noqa: E402
from baseparams.plugins.urdf.reader import read_urdf  # noqa: E402

DATA = Path(__file__).parent / "data" / "urdf"
ROBOTS = ["ur5", "iiwa14", "gripper_arm", "quadruped"]
PIN_ORDER = [0, 1, 2, 3, 4, 5, 7, 6, 8, 9]       # our kind j is Pinocchio's column PIN_ORDER[j]
STATES = 6


def exact_angles(text: str) -> str:
    """URDF text with every number within 1e-9 of a multiple of pi/2 written to double precision."""
    def fix(match):
        value = float(match.group(0))
        k = round(value / (np.pi / 2))
        return repr(k * (np.pi / 2)) if k and abs(value - k * np.pi / 2) <= 1e-9 else match.group(0)
    return re.sub(r"(?<=rpy=\")[^\"]*", lambda m: re.sub(r"-?\d+\.\d+", fix, m.group(0)), text)


def pin_model(tmp_path, name, text=None, root=None):
    text = exact_angles((DATA / f"{name}.urdf").read_text() if text is None else text)
    path = tmp_path / f"{name}_pin.urdf"
    path.write_text(text)
    return pin.buildModelFromUrdf(str(path)) if root is None else pin.buildModelFromUrdf(str(path), root)


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(b):
    c, s = np.cos(b), np.sin(b)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(c_):
    c, s = np.cos(c_), np.sin(c_)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def free_maps(q, qd):
    """For our Free coordinates (x, y, z, a, b, c) and rates: Pinocchio's configuration
    (p, quaternion xyzw), S (v = S q') and the bias S' q' (a = S q'' + S' q')."""
    a, b, c = q[3:]
    rx, ry, rz = rot_x(a), rot_y(b), rot_z(c)
    rot = rx @ ry @ rz
    e1, e2, e3 = np.eye(3)
    cols = np.column_stack([e1, rx @ e2, rx @ ry @ e3])          # omega_world = E (a', b', c')
    s = np.zeros((6, 6))
    s[:3, :3] = rot.T
    s[3:, 3:] = rot.T @ cols
    pd, rates = qd[:3], qd[3:]
    w1 = e1 * rates[0]
    w2 = w1 + rx @ e2 * rates[1]
    e_dot_rates = np.cross(w1, rx @ e2) * rates[1] + np.cross(w2, rx @ ry @ e3) * rates[2]
    w_local = rot.T @ (cols @ rates)
    bias = np.concatenate([-np.cross(w_local, rot.T @ pd), rot.T @ e_dot_rates])
    quat = pin.Quaternion(rot)
    config = np.concatenate([q[:3], [quat.x, quat.y, quat.z, quat.w]])
    return config, s, bias


def random_state(mech, rng):
    """Random (q, qd, qdd) of our coordinates, inside the limits (Cardan b within +-1)."""
    q = within_limits(mech, mech.coordinates, rng, 3.0)
    n = len(q)
    return np.array(q), rng.normal(size=n), rng.normal(size=n)


def to_pinocchio(model, mech, q, qd, qdd):
    """Pinocchio's (q, v, a) and the map S_full (v = S_full q') for our state."""
    qp, v, acc = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    s_full = np.zeros((model.nv, len(q)))
    index = {c: i for i, c in enumerate(mech.coordinates)}
    for joint in mech.joints:
        jid = model.getJointId(joint.name) if model.existJointName(joint.name) else 1
        jm = model.joints[jid]
        ours = [index[c] for c in joint.coordinates]
        if jm.shortname() == "JointModelFreeFlyer":
            config, s, bias = free_maps(q[ours], qd[ours])
            qp[jm.idx_q:jm.idx_q + 7] = config
            s_full[jm.idx_v:jm.idx_v + 6, ours] = s
            v[jm.idx_v:jm.idx_v + 6] = s @ qd[ours]
            acc[jm.idx_v:jm.idx_v + 6] = s @ qdd[ours] + bias
        else:
            (i,) = ours
            if jm.nq == 2:                                           # continuous: (cos, sin)
                qp[jm.idx_q:jm.idx_q + 2] = np.cos(q[i]), np.sin(q[i])
            else:
                qp[jm.idx_q] = q[i]
            s_full[jm.idx_v, i] = 1.0
            v[jm.idx_v], acc[jm.idx_v] = qd[i], qdd[i]
    return qp, v, acc, s_full


def column_map(model, mech):
    """Our parameter index -> Pinocchio's regressor column (bodies matched by link name)."""
    joint_of_link = {f.name: f.parentJoint for f in model.frames if f.type == pin.FrameType.BODY}
    cols = []
    for body in mech.bodies:
        jid = joint_of_link[body.name]
        cols += [10 * (jid - 1) + PIN_ORDER[j] for j in range(10)]
    return np.array(cols)


def our_regressor(mech, q, qd, qdd):
    sample = Evaluator(mech, Float64()).sample([np.array([v]) for v in q], [np.array([v]) for v in qd],
                                               [np.array([v]) for v in qdd])
    return sample.regressor_array()[0]


def our_phi(mech):
    return np.array([float(v) for b in mech.bodies for v in b.inertia])


def models(tmp_path, name):
    """(our merged mechanism, Pinocchio model) pairs for a robot; the quadruped also without
    its world link, as Pinocchio's root free flyer and our floating_base option."""
    pairs = [(read_urdf(DATA / f"{name}.urdf", merge_fixed=True).mechanism, pin_model(tmp_path, name))]
    if name == "quadruped":
        text = (DATA / "quadruped.urdf").read_text()
        bare = re.sub(r'\s*<link name="world"/>\s*<joint name="floating_base".*?</joint>', "", text, flags=re.S)
        path = tmp_path / "quadruped_bare.urdf"
        path.write_text(bare)
        ours = read_urdf(path, merge_fixed=True, floating_base=True).mechanism
        pairs.append((ours, pin_model(tmp_path, "quadruped_bare", bare, pin.JointModelFreeFlyer())))
    return pairs


@pytest.mark.parametrize("name", ROBOTS)
def test_inertial_parameters_equal_pinocchio(tmp_path, name):
    for mech, model in models(tmp_path, name):
        theirs = np.concatenate([model.inertias[j].toDynamicParameters() for j in range(1, model.njoints)])
        assert np.max(np.abs(our_phi(mech) - theirs[column_map(model, mech)])) < 1e-12


@pytest.mark.parametrize("name", ROBOTS)
def test_regressor_and_torques_equal_pinocchio(tmp_path, name):
    rng = np.random.default_rng(11)
    for mech, model in models(tmp_path, name):
        data = model.createData()
        cols = column_map(model, mech)
        for _ in range(STATES):
            q, qd, qdd = random_state(mech, rng)
            qp, v, acc, s_full = to_pinocchio(model, mech, q, qd, qdd)
            y_pin = pin.computeJointTorqueRegressor(model, data, qp, v, acc)
            expected = s_full.T @ y_pin[:, cols]
            ours = our_regressor(mech, q, qd, qdd)
            assert ours.shape == expected.shape
            assert np.max(np.abs(ours - expected)) <= 1e-12 * np.max(np.abs(expected))
            tau_pin = s_full.T @ pin.rnea(model, data, qp, v, acc)
            assert np.max(np.abs(ours @ our_phi(mech) - tau_pin)) <= 1e-12 * max(1.0, np.max(np.abs(tau_pin)))


@pytest.mark.parametrize("name", ROBOTS)
def test_base_parameter_count_equals_pinocchio_rank(tmp_path, name):
    rng = np.random.default_rng(5)
    dp = registry.solvers()["dp"].item
    mech, model = models(tmp_path, name)[0]
    data = model.createData()
    rows = []
    for _ in range(40):
        q, qd, qdd = random_state(mech, rng)
        qp, v, acc, _ = to_pinocchio(model, mech, q, qd, qdd)
        rows.append(pin.computeJointTorqueRegressor(model, data, qp, v, acc))
    w = np.vstack(rows)
    sv = np.linalg.svd(w, compute_uv=False)
    rank = int(np.sum(sv > sv[0] * max(w.shape) * np.finfo(float).eps))
    assert dp.solve(mech, samples=100).rank == rank
    kept = read_urdf(DATA / f"{name}.urdf").mechanism              # fixed links kept as bodies
    assert dp.solve(kept, samples=100).rank == rank


def test_snapped_angles_change_nothing_above_1e9(tmp_path):
    """iiwa's 1.57079632679 is taken as pi/2: Pinocchio on the untouched file differs by < 1e-9."""
    rng = np.random.default_rng(3)
    mech = read_urdf(DATA / "iiwa14.urdf", merge_fixed=True).mechanism
    model = pin.buildModelFromUrdf(str(DATA / "iiwa14.urdf"))
    data = model.createData()
    q, qd, qdd = random_state(mech, rng)
    qp, v, acc, s_full = to_pinocchio(model, mech, q, qd, qdd)
    y_pin = s_full.T @ pin.computeJointTorqueRegressor(model, data, qp, v, acc)[:, column_map(model, mech)]
    gap = np.max(np.abs(our_regressor(mech, q, qd, qdd) - y_pin)) / np.max(np.abs(y_pin))
    assert 1e-14 < gap < 1e-9


# ----- every robot of example-robot-data that Pinocchio loads (issue 22) -----------------------
# Unedited files: mimic tags (projected: tau = G^T tau_tree, tests/urdf_reference.py), dummy and
# non-physical inertias (warnings) included. The reference rank is Pinocchio's regressor's;
# ours is dp's base-parameter count; torques are K phi against rnea. Robots whose check takes
# more than a few seconds are marked slow; benchmarks/bench_urdf_robots.py times them all.
from urdf_reference import Reference, example_robot_data, robot_id, torque_check, within_limits  # noqa: E402

ERD = example_robot_data()
FAST = {"double_pendulum_description/double_pendulum", "double_pendulum_description/double_pendulum_continuous",
        "double_pendulum_description/double_pendulum_simple", "panda_description/panda",
        "so_arm_description/so100", "so_arm_description/so101", "ur_description/ur5_robot",
        "asr_twodof_description/TwoDofs", "finger_edu_description/finger_edu", "kinova_description/kinova",
        "z1_description/z1", "borinot_description/borinot_flying_arm_2"}
FLOATING = ("hector_description/quadrotor_base", "solo_description/solo12", "anymal_b_simple_description/anymal",
            "hyq_description/hyq_no_sensors", "go1_description/go1", "b1_description/b1",
            "anymal_b_simple_description/anymal-kinova", "talos_data/talos_full_v2", "romeo_description/romeo")


def _erd_cases(floating):
    cases = []
    for path in ERD:
        name = robot_id(path)
        if floating and name not in FLOATING:
            continue
        fast = name in FAST or (floating and name == "hector_description/quadrotor_base")
        cases.append(pytest.param(path, floating, id=name, marks=() if fast else pytest.mark.slow))
    return cases or [pytest.param(None, floating, marks=pytest.mark.skip(
        reason="example-robot-data is not installed (pip install example-robot-data)"))]


@pytest.mark.parametrize("path,floating", _erd_cases(False) + _erd_cases(True))
def test_example_robot_data_matches_pinocchio(path, floating):
    try:
        ref = Reference(path, floating)
    except Exception as exc:                                 # noqa: BLE001 (Pinocchio's own refusal)
        pytest.skip(f"Pinocchio does not load it: {str(exc)[:80]}")
    if ref.model.nv == 0:                 # nothing moves (hector, iris_simple): refused with the reason
        from baseparams.io.loader import load_mechanism
        with pytest.raises(InputError, match="no moving link|no degree of freedom"):
            load_mechanism(path)
        return
    mech = read_urdf(path, floating_base=floating).mechanism
    error, off_span = torque_check(ref, mech)
    assert error <= 1e-9 and off_span <= 1e-12
    rank, gap = ref.rank()
    assert gap > 1e6, f"Pinocchio's own rank is not clear (gap {gap:.3g})"
    samples = {"samples": 100} if len(mech.bodies) > 100 else {}     # TIAGo dual: 2.6 GiB at 200
    assert registry.solvers()["dp"].item.solve(mech, **samples).rank == rank


def test_so100_dp_rank_is_38_as_pinocchio_and_exact():
    """so100's angles are 1.57079 (6e-6 off pi/2): two small columns (mx1, mx2, norm 8e-4 of
    W's 200) equal up to rounding once made dp report 39 with no clear ridge. dp now gives
    38, Pinocchio's rank, and its base parameters span the exact solver's row space."""
    mech = read_urdf(DATA / "so100.urdf").mechanism
    solvers = registry.solvers()
    dp, exact = solvers["dp"].item.solve(mech), solvers["exact"].item.solve(mech)
    assert dp.rank == exact.rank == 38
    ref = Reference(DATA / "so100.urdf")
    assert ref.rank()[0] == 38
    index = {p: i for i, p in enumerate(mech.parameters)}

    def rows(result):
        out = np.zeros((result.rank, len(index)))
        for k, base in enumerate(result.base):
            for name, value in base["expression"].items():
                out[k, index[name]] = float(value) if not isinstance(value, str) or "/" not in value else \
                    float(__import__("fractions").Fraction(value))
        return out

    a, b = np.linalg.qr(rows(dp).T)[0], np.linalg.qr(rows(exact).T)[0]
    cosines = np.linalg.svd(a.T @ b, compute_uv=False)
    assert cosines.min() > 1 - 1e-8                           # principal angles below 1e-4 rad
