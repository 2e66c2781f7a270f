"""Pinocchio as the reference on whole URDF robots, mimic joints included (issue 22).

Used by tests/test_urdf_pinocchio.py and benchmarks/bench_urdf_robots.py. Pinocchio 4.1
loads ``<mimic>`` joints as ordinary joints (its default) and its joint-torque regressor
refuses mimic models, so the reference is its regressor of the *uncoupled* tree projected
onto the couplings: with the followers' positions ``q_tree = G q + offset`` (a follower =
multiplier x its leader + offset), ``v_tree = G v``, ``a_tree = G a`` and the independent
generalized forces ``tau = G^T tau_tree``, so ``Y = G^T Y_tree``. G is built here from the
file's ``<mimic>`` tags read with ElementTree, not from our reader's couplings, and the
mimic tags Pinocchio's URDF parser would not honour either (on a fixed joint, towards a
joint that is not in the robot) are left out, as our reader does.

Rank of the reference: the number of singular values of the stacked ``Y`` above
``max(shape) * eps * s_max`` (numpy's rule), with the gap at the cut reported; where that
gap is below 1e6 (the tolerance cuts through rounding noise), the position of the largest
gap between consecutive singular values (floored at ``eps * s_max``).
"""

import math
import re
import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

import numpy as np

MOVING = ("revolute", "continuous", "prismatic")


def example_robot_data() -> list[Path]:
    """The URDF files of the installed example-robot-data (``pip install example-robot-data``),
    sorted; empty when it is not installed."""
    try:
        root = Path(metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except metadata.PackageNotFoundError:
        return []
    return sorted(root.rglob("*.urdf")) if root.is_dir() else []


def robot_id(path: Path) -> str:
    """``talos_data/talos_full_v2``: the package folder and the file's stem."""
    parts = path.parts
    return f"{parts[parts.index('robots') + 1]}/{path.stem}" if "robots" in parts else path.stem


def mimic_tags(path: Path) -> dict:
    """{follower joint: (leader, multiplier, offset)} for the mimic tags that couple two
    moving joints of the file (others are ignored by urdfdom/Pinocchio and by our reader)."""
    root = ET.parse(path).getroot()
    kinds = {j.get("name"): j.get("type") for j in root.findall("joint")}
    out = {}
    for j in root.findall("joint"):
        mimic = j.find("mimic")
        if mimic is None or kinds[j.get("name")] not in MOVING or kinds.get(mimic.get("joint")) not in MOVING:
            continue
        out[j.get("name")] = (mimic.get("joint"), float(mimic.get("multiplier", 1)), float(mimic.get("offset", 0)))
    return out


class Reference:
    """Pinocchio's model of a URDF file (a free-flyer root when ``floating``) and the map
    from the independent coordinates to its configuration, velocity and acceleration."""

    def __init__(self, path: Path, floating: bool = False):
        import pinocchio as pin
        self.pin = pin
        self.model = (pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if floating
                      else pin.buildModelFromUrdf(str(path)))
        self.data = self.model.createData()
        self.mimic = mimic_tags(path)
        model = self.model
        self.names = [model.names[j] for j in range(1, model.njoints)]
        followers = {name for name in self.names if name in self.mimic}
        self.free_dofs = []                   # v indices of the independent coordinates
        for j in range(1, model.njoints):
            if model.names[j] not in followers:
                jm = model.joints[j]
                self.free_dofs += list(range(jm.idx_v, jm.idx_v + jm.nv))
        self.G = np.zeros((model.nv, len(self.free_dofs)))
        column = {v: k for k, v in enumerate(self.free_dofs)}
        for v in self.free_dofs:
            self.G[v, column[v]] = 1.0
        for name in followers:
            leader, ratio, _ = self.mimic[name]
            self.G[self._v(name), column[self._v(leader)]] = ratio

    def joint_id(self, coordinate: str) -> int:
        """Pinocchio's joint for our coordinate name (``joint_0.0`` is our ``joint_0_0``)."""
        if self.model.existJointName(coordinate):
            return self.model.getJointId(coordinate)
        found = [j for j in range(1, self.model.njoints)
                 if re.sub(r"[^A-Za-z0-9_]", "_", self.model.names[j]) in (coordinate, coordinate.removeprefix("j_"))]
        if len(found) != 1:
            raise KeyError(f"no Pinocchio joint for our coordinate {coordinate!r}")
        return found[0]

    def _v(self, name):
        return self.model.joints[self.model.getJointId(name)].idx_v

    def random_state(self, rng):
        """A random (q, v, a) of the tree, followers set by their leaders, inside the limits."""
        model, pin = self.model, self.pin
        angle = {}
        q = pin.neutral(model)
        for j in range(1, model.njoints):
            jm, name = model.joints[j], model.names[j]
            if name in self.mimic:
                continue
            if jm.nq == jm.nv == 1:
                lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
                lo, hi = (max(lo, -3.0), min(hi, 3.0)) if lo < hi else (-3.0, 3.0)
                angle[name] = q[jm.idx_q] = rng.uniform(lo, hi)
            elif jm.nq == 2:                                        # continuous: (cos, sin)
                angle[name] = rng.uniform(-3.0, 3.0)
                q[jm.idx_q:jm.idx_q + 2] = math.cos(angle[name]), math.sin(angle[name])
            else:                                                   # free flyer
                q[jm.idx_q:jm.idx_q + 3] = rng.uniform(-1, 1, 3)
                quat = rng.normal(size=4)
                q[jm.idx_q + 3:jm.idx_q + 7] = quat / np.linalg.norm(quat)
        for name, (leader, ratio, offset) in self.mimic.items():
            if not self.model.existJointName(name):
                continue
            jm = model.joints[model.getJointId(name)]
            value = ratio * angle[leader] + offset
            if jm.nq == 2:
                q[jm.idx_q:jm.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                q[jm.idx_q] = value
        n = len(self.free_dofs)
        return q, self.G @ rng.normal(size=n), self.G @ rng.normal(size=n)

    def stacked_regressor(self, states: int, seed: int = 0) -> np.ndarray:
        """G^T Y_tree stacked over ``states`` random states."""
        rng = np.random.default_rng(seed)
        rows = [self.G.T @ self.pin.computeJointTorqueRegressor(self.model, self.data, *self.random_state(rng))
                for _ in range(states)]
        return np.vstack(rows)

    def rank(self, states: int | None = None, seed: int = 0) -> tuple[int, float]:
        """(rank of the stacked projected regressor, gap s_r / s_(r+1) at the cut)."""
        n = len(self.free_dofs)
        if n == 0:
            return 0, math.inf
        states = states or max(40, math.ceil(3 * 10 * (self.model.njoints - 1) / n))
        w = self.stacked_regressor(states, seed)
        s = np.linalg.svd(w, compute_uv=False)
        if not s.size or s[0] == 0:
            return 0, math.inf
        r = int(np.sum(s > s[0] * max(w.shape) * np.finfo(float).eps))
        floored = np.maximum(s, s[0] * np.finfo(float).eps)
        gap = floored[r - 1] / floored[r] if 0 < r < len(s) else math.inf
        if gap < 1e6:
            # the tolerance cuts through noise (kinova: s_36 = 4.9, s_37 = 1.3e-11 and
            # s_38 = 8e-12 above the tolerance 6e-12, from columns of norm 1e-9): the largest gap
            ratios = floored[:-1] / floored[1:]
            r = int(np.argmax(ratios)) + 1
            gap = float(ratios[r - 1])
        return r, float(gap)


# ----- our side ----------------------------------------------------------------------------
def our_state_in_pinocchio(ref: Reference, mech, sample):
    """Pinocchio's (q, v, a) for our sample, and M (nv x independent): v = M zd.

    Our tree coordinates are matched to Pinocchio's joints by name (a Free joint is its root
    free flyer); our Free coordinates x, y, z, a, b, c (R = Rx(a) Ry(b) Rz(c)) map to its
    (p, quaternion) and v = S(q) q', a = S q'' + S' q' (tests/test_urdf_pinocchio.py)."""
    from test_urdf_pinocchio import free_maps            # the closed-form map, tested there
    pin, model = ref.pin, ref.model
    q_tree = np.array([float(np.ravel(v)[0]) for v in sample.q])
    qd_tree = np.array([float(np.ravel(v)[0]) for v in sample.qd])
    qdd_tree = np.array([float(np.ravel(v)[0]) for v in sample.qdd])
    r = np.array([[float(np.ravel(v)[0]) for v in row] for row in sample.projection])
    index = {c: i for i, c in enumerate(mech.coordinates)}
    qp, v, acc = pin.neutral(model), np.zeros(model.nv), np.zeros(model.nv)
    s_full = np.zeros((model.nv, len(q_tree)))
    for joint in mech.joints:
        ours = [index[c] for c in joint.coordinates]
        if not ours:
            continue
        if len(ours) == 6:
            jm = model.joints[1]
            config, s, bias = free_maps(q_tree[ours], qd_tree[ours])
            qp[jm.idx_q:jm.idx_q + 7] = config
            s_full[jm.idx_v:jm.idx_v + 6, ours] = s
            v[jm.idx_v:jm.idx_v + 6] = s @ qd_tree[ours]
            acc[jm.idx_v:jm.idx_v + 6] = s @ qdd_tree[ours] + bias
            continue
        (i,) = ours
        jm = model.joints[ref.joint_id(joint.name)]
        if jm.nq == 2:
            qp[jm.idx_q:jm.idx_q + 2] = np.cos(q_tree[i]), np.sin(q_tree[i])
        else:
            qp[jm.idx_q] = q_tree[i]
        s_full[jm.idx_v, i] = 1.0
        v[jm.idx_v], acc[jm.idx_v] = qd_tree[i], qdd_tree[i]
    return qp, v, acc, s_full @ r


def torque_check(ref: Reference, mech, states: int = 3, seed: int = 1) -> tuple[float, float]:
    """(largest |K phi - M^T rnea| relative to max(1, |tau|), largest distance of M's columns
    from the span of G) over random states of our independent coordinates."""
    from baseparams.dynamics.evaluator import Evaluator
    from baseparams.numeric.backends import Float64
    rng = np.random.default_rng(seed)
    phi = np.array([float(v) for b in mech.bodies for v in b.inertia])
    evaluator = Evaluator(mech, Float64())
    worst, off_span = 0.0, 0.0
    g_pinv = np.linalg.pinv(ref.G) if ref.G.size else ref.G.T
    for _ in range(states):
        z = within_limits(mech, mech.independent, rng, 1.0)
        n = len(z)
        zd, zdd = rng.normal(size=n), rng.normal(size=n)
        sample = evaluator.sample([np.array([x]) for x in z], [np.array([x]) for x in zd],
                                  [np.array([x]) for x in zdd])
        qp, v, acc, m = our_state_in_pinocchio(ref, mech, sample)
        tau_pin = m.T @ ref.pin.rnea(ref.model, ref.data, qp, v, acc)
        ours = sample.regressor_array()[0] @ phi
        scale = max(1.0, float(np.max(np.abs(tau_pin), initial=0.0)))
        worst = max(worst, float(np.max(np.abs(ours - tau_pin), initial=0.0)) / scale)
        if ref.G.size:
            off_span = max(off_span, float(np.max(np.abs(m - ref.G @ (g_pinv @ m)), initial=0.0)))
    return worst, off_span


def within_limits(mech, names, rng, bound: float) -> list[float]:
    """A uniform random value of each coordinate in ``names``, inside its limits and +-bound."""
    out = []
    for name in names:
        lo, hi = mech.joint_of_coordinate(name).limits.get(name, (-1.0, 1.0))
        out.append(rng.uniform(max(lo, -bound), min(hi, bound)))
    return out
