"""Collisions of a planned motion: the URDF's collision geometry (Pinocchio + coal, the
optional extra ``baseparams[collision]``), keep-out planes and boxes, the smallest distance
at each sample with its gradient in the independent coordinates, and a bound on how fast a
distance can shrink, so a distance checked at samples holds between them too.

Meshes are replaced by their convex hulls (a hull contains its mesh, so a distance on hulls
is never larger than on the meshes: conservative, and GJK on hulls is fast). A link without
collision geometry (no ``<collision>``, or a mesh that cannot be found) is represented by
the origins of its frames (its skeleton), checked against the keep-out geometry only.
By default the base plane (z = 0 of the URDF's root frame) is a floor no moving link may cross.
"""

from __future__ import annotations

import functools
import importlib
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism

DEFAULT_CLEARANCE = 0.02        # m: smallest distance between links, and to the keep-out geometry
FLOOR = ((0.0, 0.0, 1.0), 0.0)  # the base plane: n . p >= d with n = +z, d = 0


@dataclass(frozen=True)
class SceneSpec:
    """What the collision scene is built from (plain data, so a start's job carries it)."""
    urdf: str | None = None
    srdf: str | None = None
    package_dirs: tuple[str, ...] = ()
    clearance: float = DEFAULT_CLEARANCE
    planes: tuple[tuple[tuple[float, float, float], float], ...] = (FLOOR,)
    boxes: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = ()


def parse_keep_out(items: Sequence[str], floor: bool = True) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
    """(planes, boxes) from ``plane:NX,NY,NZ,D`` (free where n . p >= D, n normalised) and
    ``box:CX,CY,CZ,HX,HY,HZ`` (centre and half sides, axes of the base frame); the floor first."""
    planes: list[Any] = [FLOOR] if floor else []
    boxes: list[Any] = []
    for item in items:
        kind, _, rest = item.partition(":")
        try:
            values = [float(v) for v in rest.split(",")]
            if not all(math.isfinite(v) for v in values):
                raise ValueError
        except ValueError:
            values = []
        if kind == "plane" and len(values) == 4 and np.linalg.norm(values[:3]) > 0:
            n = np.array(values[:3]) / np.linalg.norm(values[:3])
            planes.append((tuple(map(float, n)), values[3] / float(np.linalg.norm(values[:3]))))
        elif kind == "box" and len(values) == 6 and all(v > 0 for v in values[3:]):
            boxes.append((tuple(values[:3]), tuple(values[3:])))
        else:
            raise InputError(f"{item!r}: give plane:NX,NY,NZ,D (free where n.p >= D) or "
                             "box:CX,CY,CZ,HX,HY,HZ (centre, positive half sides; metres)", key="--keep-out")
    return tuple(planes), tuple(boxes)


def available() -> str | None:
    """None when Pinocchio and coal can be imported, else the reason."""
    try:
        importlib.import_module("coal")
        importlib.import_module("pinocchio")
    except ImportError as exc:
        return f"collision checking needs Pinocchio and coal: pip install 'baseparams[collision]' ({exc})"
    return None


def find_srdf(urdf: str) -> str | None:
    """The robot's SRDF where ROS packages keep it: beside the URDF with its stem, or in
    ``../srdf/`` named after the URDF's stem or its robot's name; None when there is none."""
    here = os.path.dirname(os.path.abspath(urdf))
    stem = os.path.splitext(os.path.basename(urdf))[0]
    try:
        robot = ET.parse(urdf).getroot().get("name") or stem
    except (OSError, ET.ParseError):
        robot = stem
    for candidate in (os.path.join(here, f"{stem}.srdf"), os.path.join(here, "..", "srdf", f"{stem}.srdf"),
                      os.path.join(here, "..", "srdf", f"{robot}.srdf")):
        if os.path.isfile(candidate):
            return os.path.normpath(candidate)
    return None


def package_dirs(urdf: str, extra: Sequence[str] = ()) -> tuple[str, ...]:
    """Where ``package://`` meshes are looked for: the given directories, then the URDF's
    directory and its ancestors (a ROS package's layout puts the package's folder there)."""
    out = [os.path.abspath(d) for d in extra]
    here = os.path.dirname(os.path.abspath(urdf))
    for _ in range(6):
        out.append(here)
        here = os.path.dirname(here)
    return tuple(dict.fromkeys(out))


def _mesh_found(filename: str, dirs: Sequence[str], urdf: str) -> bool:
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        return any(os.path.isfile(os.path.join(d, rest)) for d in dirs)
    path = filename[len("file://"):] if filename.startswith("file://") else filename
    return os.path.isfile(path if os.path.isabs(path) else os.path.join(os.path.dirname(urdf), path))


def _without_missing_meshes(urdf: str, dirs: Sequence[str]) -> tuple[str, list[str]]:
    """The URDF's text without the ``<collision>`` elements whose mesh is not found, and the
    links that lost one."""
    try:
        tree = ET.parse(urdf)
    except (OSError, ET.ParseError) as exc:
        raise InputError(f"cannot read the collision geometry: {exc}", file=urdf) from None
    lost = []
    for link in tree.getroot().iter("link"):
        for collision in list(link.findall("collision")):
            mesh = collision.find("geometry/mesh")
            if mesh is not None and not _mesh_found(mesh.get("filename", ""), dirs, urdf):
                link.remove(collision)
                lost.append(link.get("name", "?"))
    return ET.tostring(tree.getroot(), encoding="unicode"), sorted(set(lost))


@dataclass
class Scene:
    """The robot's collision model at the independent coordinates ``names`` (Pinocchio's
    model and geometry, hulls), the pairs checked, the keep-out planes, and what it says
    about itself (``notes``)."""
    spec: SceneSpec
    names: tuple[str, ...]
    model: Any
    data: Any
    geometry: Any
    gdata: Any
    mapping: np.ndarray                 # (nv, f): d(pinocchio velocity)/d(independent velocity)
    offsets: np.ndarray                 # (nq,) configuration at zero independent coordinates (angles)
    angle_of: list[tuple[int, int, int]]  # (nq index, kind 1: plain / 2: cos-sin, independent col)
    vertices: list[np.ndarray]          # per geometry: its points (hull vertices) in its own frame
    moving: list[int]                   # geometries attached to a moving joint
    plane_items: list[tuple[int, int]]  # (plane, geometry)
    pair_names: list[tuple[str, str]]
    speed: np.ndarray                   # (geometries, f): speed bound per unit |qd| of each coordinate
    skeleton: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    self_checked: bool = False
    required: np.ndarray = field(default_factory=lambda: np.zeros(0))   # per item: the distance it must keep

    # ----- evaluation ---------------------------------------------------------------------
    def configuration(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configuration of one sample of the independent coordinates."""
        angles = self.mapping @ q          # joint values (nv) from the independent ones
        out = self.offsets.copy()
        for iq, kind, iv in self.angle_of:
            a = angles[iv] + out[iq] if kind == 1 else angles[iv]
            if kind == 1:
                out[iq] = a
            else:
                out[iq], out[iq + 1] = math.cos(a), math.sin(a)
        return out

    def distances(self, q: np.ndarray, gradient: bool = False) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """(all (N, items): every pair's and plane item's signed distance, grad (N, f) of each
        sample's smallest slack (distance less ``required``), the labels of the items)."""
        import pinocchio as pin
        q = np.atleast_2d(q)
        count, f = q.shape
        labels = [f"{a} / {b}" for a, b in self.pair_names] + \
                 [f"{self.geometry.geometryObjects[g].name} / plane {p}" for p, g in self.plane_items]
        out = np.empty((count, len(labels)))
        grad = np.zeros((count, f))
        pairs = len(self.pair_names)
        for n in range(count):
            config = self.configuration(q[n])
            if gradient:
                pin.computeJointJacobians(self.model, self.data, config)
            else:
                pin.forwardKinematics(self.model, self.data, config)
            pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.gdata)
            witness: list[Any] = []
            if pairs:
                pin.computeDistances(self.geometry, self.gdata)
                for k, result in enumerate(self.gdata.distanceResults):
                    out[n, k] = result.min_distance
            for k, (p, g) in enumerate(self.plane_items):
                normal, offset = self.spec.planes[p]
                placement = self.gdata.oMg[g]
                heights = self.vertices[g] @ (placement.rotation.T @ np.asarray(normal))
                j = int(np.argmin(heights))
                out[n, pairs + k] = heights[j] + float(np.dot(normal, placement.translation)) - offset
                witness.append(j)
            if gradient and len(labels):
                k = int(np.argmin(out[n] - self.required))
                grad[n] = self._gradient(k, witness) @ self.mapping
        return out, grad, labels

    def _point_velocity(self, joint: int, point: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """direction . (velocity of the world point ``point`` fixed to ``joint``) per unit of
        each Pinocchio velocity: (nv,)."""
        import pinocchio as pin
        if joint == 0:
            return np.zeros(self.model.nv)
        J = pin.getJointJacobian(self.model, self.data, joint, pin.LOCAL_WORLD_ALIGNED)
        r = point - self.data.oMi[joint].translation
        return direction @ J[:3] + np.cross(r, direction) @ J[3:]

    def _gradient(self, k: int, witness: list[int]) -> np.ndarray:
        pairs = len(self.pair_names)
        objects = self.geometry.geometryObjects
        if k < pairs:
            pair = self.geometry.collisionPairs[k]
            result = self.gdata.distanceResults[k]
            n = np.asarray(result.normal)
            p1, p2 = np.asarray(result.getNearestPoint1()), np.asarray(result.getNearestPoint2())
            return (self._point_velocity(objects[pair.second].parentJoint, p2, n) -
                    self._point_velocity(objects[pair.first].parentJoint, p1, n))
        p, g = self.plane_items[k - pairs]
        placement = self.gdata.oMg[g]
        point = placement.rotation @ self.vertices[g][witness[k - pairs]] + placement.translation
        return self._point_velocity(objects[g].parentJoint, point, np.asarray(self.spec.planes[p][0]))

    def item_speed(self, qd_bound: np.ndarray) -> np.ndarray:
        """(N, items): how fast each item's distance can change at most, given a bound
        on |qd| of each independent coordinate (N, f)."""
        geometry = qd_bound @ self.speed.T            # (N, geometries)
        pairs = [(p.first, p.second) for p in self.geometry.collisionPairs]
        parts = [geometry[:, a] + geometry[:, b] for a, b in pairs] + [geometry[:, g] for _, g in self.plane_items]
        return np.stack(parts, axis=1) if parts else np.zeros((len(qd_bound), 0))

    @property
    def checks(self) -> int:
        return len(self.pair_names) + len(self.plane_items)


def build(spec: SceneSpec, mechanism: Mechanism, names: Sequence[str], centre: np.ndarray) -> Scene:
    """The scene of ``spec`` for ``mechanism``'s independent coordinates ``names`` (``centre``:
    the centre of the position ranges, where the checks that cannot change are found)."""
    return _build(spec, mechanism, tuple(names), tuple(map(float, centre)))


@functools.lru_cache(maxsize=8)
def _build(spec: SceneSpec, mechanism: Mechanism, names: tuple[str, ...], centre: tuple[float, ...]) -> Scene:
    coal = importlib.import_module("coal")
    import pinocchio as pin
    notes: list[str] = []
    assert spec.urdf is not None
    try:
        model = pin.buildModelFromUrdf(spec.urdf)
    except Exception as exc:                       # Pinocchio's own reason: the user's file
        raise InputError(f"Pinocchio cannot read the URDF for the collision check: {exc}", file=spec.urdf) from None
    dirs = package_dirs(spec.urdf, spec.package_dirs)
    text, lost = _without_missing_meshes(spec.urdf, dirs)
    if lost:
        notes.append(f"collision meshes not found for {', '.join(lost)} (looked in the URDF's folder and its "
                     "parents; --package-dir adds more): those links are checked by their frames' origins only")
    geometry = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.COLLISION, package_dirs=list(dirs))
    for obj in geometry.geometryObjects:
        if hasattr(obj.geometry, "buildConvexHull"):            # a mesh: its convex hull (qhull)
            obj.geometry.buildConvexHull(True, "Qt")
            obj.geometry = obj.geometry.convex
    with_geometry = {obj.parentJoint for obj in geometry.geometryObjects}
    skeleton = []
    for k, frame in enumerate(model.frames):
        joint = frame.parentJoint
        if joint == 0 or joint in with_geometry:
            continue
        name = f"{frame.name} (origin)"
        if any(o.name == name for o in geometry.geometryObjects):
            continue
        geometry.addGeometryObject(pin.GeometryObject(name, joint, k, frame.placement, coal.Sphere(0.0)))
        skeleton.append(frame.name)
    meshes = [o for o in geometry.geometryObjects if not o.name.endswith("(origin)")]
    if not meshes:
        notes.append("no collision geometry in the URDF: self-collision is not checked; the keep-out "
                     "geometry is checked against the links' frame origins")
    real = len(geometry.geometryObjects)
    for b, (centre_b, half) in enumerate(spec.boxes):
        placement = pin.SE3(np.eye(3), np.array(centre_b))
        geometry.addGeometryObject(pin.GeometryObject(f"keep-out box {b + 1}", 0, 0, placement,
                                                      coal.Box(*(2 * np.array(half)))))
    # pairs: moving geometry against the boxes, and link against link
    objects = geometry.geometryObjects
    moving_mesh = [i for i in range(real) if objects[i].parentJoint != 0 and not objects[i].name.endswith("(origin)")]
    moving = [i for i in range(real) if objects[i].parentJoint != 0]
    for b in range(real, len(objects)):
        for i in moving:
            geometry.addCollisionPair(pin.CollisionPair(i, b))
    self_pairs = []
    mesh_ids = [i for i in range(real) if not objects[i].name.endswith("(origin)")]
    for a in mesh_ids:
        for c in mesh_ids:
            if a < c and objects[a].parentJoint != objects[c].parentJoint and (a in moving_mesh or c in moving_mesh):
                self_pairs.append((a, c))
    disabled = _disabled(spec, model, objects, self_pairs, notes)
    for a, c in self_pairs:
        if (a, c) not in disabled:
            geometry.addCollisionPair(pin.CollisionPair(a, c))
    mapping, offsets, angle_of = _mapping(model, mechanism, names)
    vertices = [_points(o.geometry) for o in objects]
    planes = [(p, g) for p in range(len(spec.planes)) for g in moving]
    scene = Scene(spec, names, model, model.createData(), geometry, _geometry_data(geometry), mapping, offsets,
                  angle_of, vertices, moving, planes, [], np.zeros((len(objects), len(names))), skeleton, notes,
                  bool(meshes))
    scene.speed = _speed_bounds(scene)
    scene.pair_names = [(objects[p.first].name, objects[p.second].name) for p in geometry.collisionPairs]
    # items whose distance no motion changes (a link turning about the floor's normal) are
    # left out, and said when they break the clearance; without an SRDF, link pairs already
    # within the clearance at the centre of the ranges are too (their meshes overlap there)
    rng = np.random.default_rng(0)
    probe = np.vstack([np.array(centre), np.array(centre) + rng.uniform(-1.5, 1.5, (6, len(names)))])
    values, _, labels = scene.distances(probe)
    pairs = len(scene.pair_names)
    static = [k for k in range(scene.checks) if np.ptp(values[:, k]) < 1e-9]
    bad = [labels[k] for k in static if values[0, k] < spec.clearance]
    if bad:
        notes.append(f"within the clearance at every configuration (no joint moves them apart), so not checked: "
                     f"{', '.join(bad)}")
    drop = set(static)
    # a link that no configuration takes farther than twice the clearance from an obstacle (the
    # UR5's shoulder housing turns 3 cm above its mounting plane) must only not touch it
    scene.required = np.full(scene.checks, spec.clearance)
    near = [k for k in range(scene.checks) if k not in drop and np.max(values[:, k]) < 2 * spec.clearance + 0.01]
    for k in near:
        scene.required[k] = 0.0
    if near:
        notes.append(f"no configuration takes these farther than {2 * spec.clearance + 0.01:g} m apart, so they "
                     f"must only not touch (clearance 0 for them): {', '.join(labels[k] for k in near)}")
    if not spec.srdf:
        close = [k for k in range(pairs) if values[0, k] < spec.clearance and k not in drop]
        if close:
            notes.append("link pairs within the clearance already at the centre of the position ranges, left out "
                         f"(an SRDF's disabled pairs say which pairs to skip): {', '.join(labels[k] for k in close)}")
        drop |= set(close)
    if drop:
        keep_pairs = [p for k, p in enumerate(list(geometry.collisionPairs)) if k not in drop]
        geometry.removeAllCollisionPairs()
        for p in keep_pairs:
            geometry.addCollisionPair(p)
        scene.plane_items = [item for k, item in enumerate(planes) if pairs + k not in drop]
        scene.required = np.array([r for k, r in enumerate(scene.required) if k not in drop])
        scene.gdata = _geometry_data(geometry)
        scene.pair_names = [(objects[p.first].name, objects[p.second].name) for p in geometry.collisionPairs]
    return scene


def _geometry_data(geometry: Any) -> Any:
    """Pinocchio's geometry data with GJK tight (1e-10) and no warm start from the last call:
    the same configuration gives the same distance whatever was computed before."""
    import pinocchio as pin
    coal = importlib.import_module("coal")
    gdata = pin.GeometryData(geometry)
    for request in gdata.distanceRequests:
        request.gjk_tolerance = 1e-10
        request.gjk_initial_guess = coal.GJKInitialGuess.DefaultGuess
    return gdata


def _disabled(spec: SceneSpec, model: Any, objects: Any, pairs: list[tuple[int, int]],
              notes: list[str]) -> set[tuple[int, int]]:
    """Pairs not checked: the SRDF's disabled pairs, or without an SRDF the pairs of links
    joined by one joint (their meshes touch at the joint)."""
    link_of = {i: objects[i].name.rsplit("_", 1)[0] for i in range(len(objects))}
    if spec.srdf:
        try:
            root = ET.parse(spec.srdf).getroot()
        except (OSError, ET.ParseError) as exc:
            raise InputError(f"cannot read the SRDF: {exc}", file=spec.srdf, key="--srdf") from None
        off = {frozenset((e.get("link1"), e.get("link2"))) for e in root.iter("disable_collisions")}
        return {(a, c) for a, c in pairs if frozenset((link_of[a], link_of[c])) in off}
    if len({objects[i].parentJoint for i in range(len(objects)) if not objects[i].name.endswith("(origin)")}) > 1:
        notes.append("no SRDF (--srdf): the pairs of links joined by one joint are not checked against each other")
    out = set()
    for a, c in pairs:
        ja, jc = objects[a].parentJoint, objects[c].parentJoint
        if model.parents[ja] == jc or model.parents[jc] == ja:
            out.add((a, c))
    return out


def _mapping(model: Any, mechanism: Mechanism, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int]]]:
    """The Pinocchio joints in the independent coordinates: a joint named as a coordinate
    follows it, a URDF mimic (a coupling) follows its leader, any other joint is held at 0."""
    couplings = {c.coordinate: c for c in mechanism.couplings}
    mapping = np.zeros((model.nv, len(names)))
    offsets = np.zeros(model.nq)
    angle_of = []
    for j in range(1, model.njoints):
        joint, name = model.joints[j], model.names[j]
        if joint.nv != 1:
            raise InputError(f"joint {name}: the collision check handles one-degree-of-freedom joints only",
                             file=mechanism.path)
        if name in names:
            mapping[joint.idx_v, names.index(name)] = 1.0
        elif name in couplings and couplings[name].leader in names:
            mapping[joint.idx_v, names.index(couplings[name].leader)] = float(couplings[name].ratio)
            offsets[joint.idx_q] = float(couplings[name].offset)
        kind = joint.nq
        if kind == 2:
            offsets[joint.idx_q] = 1.0
        angle_of.append((joint.idx_q, kind, joint.idx_v))
    return mapping, offsets, angle_of


def _points(shape: Any) -> np.ndarray:
    """A geometry's points in its own frame: a hull's vertices, else its bounding box's corners
    (a box's own), a sphere of radius 0: its centre."""
    if hasattr(shape, "points") and hasattr(shape, "num_points"):
        return np.array(shape.points(), dtype=float).reshape(-1, 3)
    if type(shape).__name__ == "Sphere" and shape.radius == 0:
        return np.zeros((1, 3))
    shape.computeLocalAABB()
    lo, hi = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a in (0, 1) for b in (0, 1) for c in (0, 1)])


def _speed_bounds(scene: Scene) -> np.ndarray:
    """(geometries, f): the speed of any point of a geometry is at most sum_k S[g, k] |qd_k|:
    per revolute ancestor joint, its distance to the point (bounded by the joint offsets
    down the chain plus the geometry's radius about its own joint), 1 per prismatic one."""
    model, objects = scene.model, scene.geometry.geometryObjects
    out = np.zeros((len(objects), len(scene.names)))
    for g, obj in enumerate(objects):
        j = obj.parentJoint
        if j == 0:
            continue
        pts = scene.vertices[g] @ obj.placement.rotation.T + obj.placement.translation
        radius = float(np.max(np.linalg.norm(pts, axis=1)))
        chain = []
        while j != 0:
            chain.append(j)
            j = model.parents[j]
        reach = radius
        for k, a in enumerate(chain):                     # from the geometry's joint up to the root
            if k > 0:
                reach += float(np.linalg.norm(model.jointPlacements[chain[k - 1]].translation))
            prismatic = "P" in model.joints[a].shortname().replace("JointModel", "")[:2]
            lever = 1.0 if prismatic else reach
            out[g] += lever * np.abs(scene.mapping[model.joints[a].idx_v])
    return out


MotionAt = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
DEPTH = 6                    # halvings of an interval whose guarantee falls short


def guaranteed(scene: Scene, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
               motion: MotionAt | None = None) -> tuple[np.ndarray, list[str], np.ndarray]:
    """(at samples (N, items), labels, guaranteed (N - 1, items)): the distances at the
    samples ``t`` and, per interval between two samples, a lower bound on every distance
    within it: each point is within h/2 of a sample, and a distance shrinks at most as fast
    as the item's speed bound (|qd| at the sample plus the peak |qdd| times h/2, 1 % added).
    With ``motion(t) -> (q, qd, qdd)`` an interval whose bound breaks the clearance is
    halved (DEPTH times at most), so the bound is the motion's, not the sampling's."""
    at, _, labels = scene.distances(q)
    peak = np.max(np.abs(qdd), axis=0) if len(qdd) else np.zeros(q.shape[1])

    def bounds(times: np.ndarray, values: np.ndarray, qd_: np.ndarray) -> np.ndarray:
        h = np.diff(times)[:, None]                                   # (N - 1, 1)
        rate = scene.item_speed((np.abs(qd_) + 0.5 * float(np.max(h)) * peak) * 1.01)
        return np.minimum(values[:-1] - 0.5 * h * rate[:-1], values[1:] - 0.5 * h * rate[1:])

    low = bounds(t, at, qd)
    if motion is not None:
        for k in np.nonzero(slack(scene, low) < 0)[0]:
            low[k] = _refined(scene, motion, float(t[k]), float(t[k + 1]), peak, DEPTH)
    return at, labels, low


def _refined(scene: Scene, motion: MotionAt, a: float, b: float, peak: np.ndarray, depth: int) -> np.ndarray:
    """The guarantee over [a, b] from samples at a, the middle and b, halving further where
    it still breaks the clearance."""
    times = np.array([a, (a + b) / 2, b])
    q, qd, _ = motion(times)
    values = scene.distances(q)[0]
    h = (b - a) / 2
    rate = scene.item_speed((np.abs(qd) + 0.5 * h * peak) * 1.01)
    low = values - 0.5 * h * rate
    halves = [np.minimum(low[0], low[1]), np.minimum(low[1], low[2])]
    if depth > 1:
        for i, (lo, hi) in enumerate(((a, (a + b) / 2), ((a + b) / 2, b))):
            if slack(scene, halves[i][None])[0] < 0:
                halves[i] = _refined(scene, motion, lo, hi, peak, depth - 1)
    return np.minimum(halves[0], halves[1])


def slack(scene: Scene, distances: np.ndarray) -> np.ndarray:
    """Per sample (rows of ``distances`` (N, items)) the smallest distance less what that item
    must keep (>= 0: every item keeps its clearance)."""
    return np.min(distances - scene.required, axis=1) if distances.shape[1] else np.full(len(distances), np.inf)
