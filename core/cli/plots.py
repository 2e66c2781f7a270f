"""Figures (matplotlib, no display needed): one function per figure.

Figures are made with :class:`matplotlib.figure.Figure` directly (the Agg canvas), so
importing this module never changes matplotlib's global backend for a caller.
"""

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baseparams.dynamics.trajectory import Trajectory, samples_float64
from baseparams.kinematics.tree import TreeKinematics
from baseparams.numeric.backends import Float64
from baseparams.errors import InputError
from baseparams.io.figures import new_figure as _figure, save_figure as _save
from baseparams.model.mechanism import Mechanism

if TYPE_CHECKING:
    from baseparams.solvers.result import BaseParameterResult

Poses = dict[int, list[tuple[np.ndarray, np.ndarray]]]     # body label -> (R, p) per instant

PIVOT = 0.07        # half-length of a ground joint's axis stub, relative to the mechanism's size


# ----- the mechanism in 3D -------------------------------------------------------
def plot_mechanism(mech: Mechanism, path: str | Path, instants: int = 4, fmt: str | None = None) -> Path:
    """Draw ``mech`` at a few instants of its default trajectory; return the path written.

    The instants are chosen to span the range of the first independent coordinate (so a
    suspension is shown from rebound to bump, not at four nearly equal positions); later
    instants (larger values) are drawn darker. A body is drawn as segments from its origin
    to each of its joint points (to its centre of mass when all its joints sit at its
    origin); a body on a revolute joint to the ground also reaches both ends of that
    joint's axis stub, so control arms look like wishbones. A wheel (a body hanging on one
    revolute joint with its centre of mass on the axis) is a disc whose radius gives its
    inertia about the axis, with a spoke so that its rotation shows. Ground joints are
    black markers with a stub along their axis; prismatic joints show their stroke.
    Without a default trajectory the reference configuration (all coordinates 0) is drawn.
    """
    poses, labels = _poses(mech, instants)
    geometry = _body_geometry(mech)
    size = _size(mech, poses, geometry)
    fig = _figure(figsize=(10, 7))
    ax = fig.add_subplot(projection="3d")
    colours = _colours(len(mech.bodies))
    alphas = np.linspace(0.3, 1.0, len(labels)) if len(labels) > 1 else np.array([1.0])
    drawn: list[Any] = []
    linkage: list[Any] = []

    for k, alpha in enumerate(alphas):
        for body, colour in zip(mech.bodies, colours):
            rot, pos = poses[body.label][k]
            points = _draw_body(ax, body, geometry[body.label], rot, pos, colour, alpha, size)
            drawn += points
            if geometry[body.label]["rotor"] is None:
                linkage += points
        for joint in mech.joints:
            if joint.type.name == "P":
                a = _world(poses, joint.parent, k, geometry[joint.parent]["frames"][joint.name][1])
                b = _world(poses, joint.child, k, geometry[joint.child]["frames"][joint.name][1])
                colour = colours[mech.body_labels.index(joint.child)]
                ax.plot(*np.array([a, b]).T, color=colour, alpha=alpha, lw=5, solid_capstyle="butt")
    ground = _draw_ground(ax, mech, size)
    _label_bodies(ax, mech, poses, geometry, len(labels) - 1)
    # the view is chosen from the linkage alone: a wheel's disc would turn it side-on
    _frame_axes(ax, np.array(drawn + ground), np.array(linkage + ground))
    _legend(fig, mech, colours, alphas, labels)
    title = f"{mech.name}: {mech.title}" if mech.title else mech.name
    fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0, right=0.7, bottom=0.02, top=0.95)
    return _save(fig, path, fmt)


def _poses(mech: Mechanism, instants: int) -> tuple[Poses, list[str]]:
    """{label: [(R, p) per instant]} and a legend label per instant."""
    if mech.trajectory is None:
        states = TreeKinematics(mech, Float64()).forward([0.0] * len(mech.coordinates))
        poses = {b.label: [(_arr(states[b.label].rot, 0, 1), _arr(states[b.label].pos, 0, 1))]
                 for b in mech.bodies}
        return poses, ["reference configuration"]

    sample, t = samples_float64(mech, Trajectory.default(mech))
    n = len(t)
    name = mech.independent[0] if mech.independent else mech.coordinates[0]
    z = np.broadcast_to(np.asarray(sample.q[mech.coordinates.index(name)], float), (n,))
    order = np.argsort(z, kind="stable")
    picks = [order[round(i * (n - 1) / max(instants - 1, 1))] for i in range(instants)]
    if instants == 1:
        picks = [order[n // 2]]
    picks = list(dict.fromkeys(int(p) for p in picks))      # drop repeats, keep order
    poses = {}
    for b in mech.bodies:
        s = sample.states[b.label]
        poses[b.label] = [(_arr(s.rot, k, n), _arr(s.pos, k, n)) for k in picks]
    labels = [f"{name} = {z[k]:+.3f}  (t = {t[k]:.2f} s)" for k in picks]
    return poses, labels


def _arr(values: Any, k: int, n: int) -> np.ndarray:
    """Entry ``k`` of a (nested) list of float64 scalars or length-n arrays."""
    a = np.array([[np.broadcast_to(np.asarray(v, float), (n,))[k] for v in row]
                  if isinstance(row, list) else np.broadcast_to(np.asarray(row, float), (n,))[k]
                  for row in values])
    return a


def _body_geometry(mech: Mechanism) -> dict[int, dict[str, Any]]:
    """Per body: joint frames {joint name: (R, p)} in body coordinates and the points to draw."""
    backend = Float64()
    out: dict[int, dict[str, Any]] = {0: {"frames": {}}}
    out.update({b.label: {"frames": {}} for b in mech.bodies})
    for joint in mech.joints:
        for label, frame in ((joint.parent, joint.parent_frame), (joint.child, joint.child_frame)):
            rot, p = mech.numeric_frame(frame, backend)
            out[label]["frames"][joint.name] = (np.array(rot, float), np.array(p, float))
    for label, g in out.items():
        g["points"] = [np.zeros(3)] + [p for _, p in g["frames"].values()]
        com = _centre_of_mass(mech.body(label)) if label else None
        if com is not None and all(np.linalg.norm(p) < 1e-12 for p in g["points"]):
            g["points"].append(com)        # a body with all its joints at its origin: show its extent
        # revolute joints to the ground: the body reaches both ends of the axis (a wishbone)
        g["pivots"] = [(g["frames"][j.name][1], g["frames"][j.name][0][:, 2]) for j in mech.joints
                       if j.type.name == "R" and label and 0 in (j.parent, j.child)
                       and label in (j.parent, j.child)]
        g["rotor"] = _rotor_axis(mech, label, g) if label else None
    return out


def _centre_of_mass(body: Any) -> np.ndarray | None:
    if body.inertia is None or body.inertia[0] <= 0:
        return None
    return np.array([float(v) for v in body.inertia[1:4]]) / float(body.inertia[0])


def _rotor_axis(mech: Mechanism, label: int, g: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """(centre, R of the joint frame) for a wheel: a body hanging on one R joint only, with
    its centre of mass on that joint's axis (off by less than 5 % of the disc radius)."""
    joints = [j for j in mech.joints if label in (j.parent, j.child)]
    body = mech.body(label)
    com = _centre_of_mass(body)
    if len(joints) != 1 or joints[0].type.name != "R" or com is None:
        return None
    rot, centre = g["frames"][joints[0].name]
    if np.linalg.norm(np.cross(com - centre, rot[:, 2])) > 0.05 * _disc_radius(body, rot[:, 2], 0.0):
        return None
    return centre, rot


def _size(mech: Mechanism, poses: Poses, geometry: dict[int, dict[str, Any]]) -> float:
    pts = [_world(poses, b.label, 0, p) for b in mech.bodies for p in geometry[b.label]["points"]]
    pts += [p for p in geometry[0]["points"]]
    return max(float(np.ptp(np.array(pts), axis=0).max()), 1e-3)


def _world(poses: Poses, label: int, k: int, p: Any) -> np.ndarray:
    if label == 0:
        return np.asarray(p, float)
    rot, pos = poses[label][k]
    return rot @ p + pos


def _disc_radius(body: Any, u: np.ndarray, size: float) -> float:
    """Radius of a uniform disc with the body's inertia about the spin axis ``u``."""
    if body.inertia is None or body.inertia[0] <= 0:
        return 0.12 * size
    m, _, _, _, ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in body.inertia)
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    inertia = float(u @ tensor @ u)
    return float(np.sqrt(2 * inertia / m)) if inertia > 0 else 0.12 * size


def _draw_body(ax: Any, body: Any, g: dict[str, Any], rot: np.ndarray, pos: np.ndarray, colour: Any, alpha: float,
               size: float) -> list[Any]:
    world = [rot @ p + pos for p in g["points"]]
    if g["rotor"] is not None:
        centre, frame = g["rotor"]
        r = _disc_radius(body, frame[:, 2], size)
        a = np.linspace(0, 2 * np.pi, 73)
        rim = np.array([rot @ (centre + r * (np.cos(x) * frame[:, 0] + np.sin(x) * frame[:, 1])) + pos for x in a])
        ax.plot(*rim.T, color=colour, alpha=alpha, lw=0.6 + 1.4 * alpha)
        spoke = np.array([rot @ centre + pos, rim[0]])
        ax.plot(*spoke.T, color=colour, alpha=alpha, lw=0.6 + alpha)
        return list(rim)
    origin = world[0]
    distinct = [w for w in world[1:] if np.linalg.norm(w - origin) > 1e-9 * size]
    if not distinct:
        ax.scatter(*origin, color=colour, alpha=alpha, s=30, depthshade=False)
    for w in distinct:
        ax.plot(*np.array([origin, w]).T, color=colour, alpha=alpha, lw=1 + 2 * alpha, solid_capstyle="round")
    for p, u in g["pivots"]:
        if np.linalg.norm(np.cross(p, u)) < 1e-3 * size:     # the origin is on the axis
            continue
        for end in (p - PIVOT * size * u, p + PIVOT * size * u):
            ax.plot(*np.array([origin, rot @ end + pos]).T, color=colour, alpha=alpha, lw=1.5)
    ax.scatter(*np.array(world).T, color=colour, alpha=alpha, s=10, depthshade=False)
    return world


def _draw_ground(ax: Any, mech: Mechanism, size: float) -> list[Any]:
    """Ground joints: black triangles, with a stub along the joint axis (R, U, P)."""
    drawn: list[Any] = []
    for joint in mech.joints:
        if 0 not in (joint.parent, joint.child):
            continue
        frame = joint.parent_frame if joint.parent == 0 else joint.child_frame
        rot, origin = mech.numeric_frame(frame, Float64())
        p = np.array(origin, float)
        ax.scatter(*p, color="black", marker="^", s=60, depthshade=False, zorder=5)
        drawn.append(p)
        if joint.type.uses_axis and joint.type.dof:
            u = np.array(rot, float)[:, 2] * PIVOT * size
            ax.plot(*np.array([p - u, p + u]).T, color="black", lw=2.5)
    return drawn


def _label_bodies(ax: Any, mech: Mechanism, poses: Poses, geometry: dict[int, dict[str, Any]], k: int) -> None:
    for body in mech.bodies:
        g = geometry[body.label]
        rot, pos = poses[body.label][k]
        if g["rotor"] is not None:
            where = rot @ g["rotor"][0] + pos
        else:       # half-way to the farthest joint: on the body's longest segment
            far = max(g["points"], key=lambda p: float(np.linalg.norm(p)))
            where = rot @ (far / 2) + pos
        ax.text(*where, f" {body.label}", fontsize=11, fontweight="bold", zorder=10)


def _frame_axes(ax: Any, pts: np.ndarray, view_pts: np.ndarray) -> None:
    """Equal scale on the three axes, and a view across the plane of least extent."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = max(float((hi - lo).max()), 1e-3)
    spans = np.maximum(hi - lo, 0.15 * span)
    mid = (lo + hi) / 2
    pad = 0.06 * span
    for set_lim, m, s in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, spans):
        set_lim(m - s / 2 - pad, m + s / 2 + pad)
    ax.set_box_aspect(spans + 2 * pad)
    for axis in "xyz":
        getattr(ax, f"set_{axis}label")(f"{axis} (m)", fontsize=8, labelpad=2)
    ax.tick_params(labelsize=7, pad=0)
    # look along the direction in which the mechanism is thinnest, tilted for depth
    centred = view_pts - view_pts.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
    if normal[2] < 0 or (abs(normal[2]) < 1e-9 and normal[1] > 0):
        normal = -normal
    azim = np.degrees(np.arctan2(normal[1], normal[0]))
    elev = np.degrees(np.arcsin(np.clip(normal[2], -1, 1)))
    ax.view_init(elev=min(elev + 12, 80), azim=azim + 15)


def _colours(n: int) -> list[Any]:
    from matplotlib import colormaps
    cmap = colormaps["tab10"]
    return [cmap(i % 10) for i in range(n)]


def _legend(fig: Any, mech: Mechanism, colours: list[Any], alphas: Any, labels: list[str]) -> None:
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color=c, lw=3, label=f"{b.label} {b.name}".rstrip())
               for b, c in zip(mech.bodies, colours)]
    handles += [Line2D([], [], color="0.2", alpha=a, lw=3, label=text) for a, text in zip(alphas, labels)]
    handles.append(Line2D([], [], color="black", marker="^", ls="", label="ground joint"))
    fig.legend(handles=handles, loc="center right", fontsize=8, frameon=False)


# ----- singular values of W (the seed paper's DP-versus-VP figure) -----------------
_MARKERS = {"dp": "*", "vp": "+"}


def _log10_text(text: str | float) -> float | None:
    """log10 of a decimal string (any exponent: 1e-500 does not underflow), None for 0."""
    import mpmath
    value = abs(mpmath.mpf(str(text)))
    return None if value == 0 else float(mpmath.log10(value))


def plot_singular_values(results: "list[BaseParameterResult]", path: str | Path, fmt: str | None = None) -> Path:
    """One log-scale series of singular values per result (``BaseParameterResult`` with
    ``singular_values``), each solver's rank marked; return the path written.

    The axis shows log10 of the values, so that values far below double precision's
    range (a 500-digit run's 1e-500) are drawn too. Exact zeros sit on the lower edge as
    open triangles. Where a result's diagnostics give a rank tolerance
    (``diagnostics.rank_tolerance``, dp) or a proven bound after the ridge
    (``diagnostics.tail_bound``, vp), it is drawn as a horizontal line in the series' colour.
    """
    fig = _figure(figsize=(8, 5))
    ax = fig.add_subplot()
    colours = _colours(len(results))
    series = []
    for result in results:
        logs = [_log10_text(v) for v in result.singular_values or []]
        series.append(logs)
    finite = [v for logs in series for v in logs if v is not None]
    if not finite:
        raise InputError("no nonzero singular value to plot")
    bottom = min(finite) - 2
    for k, (result, logs, colour) in enumerate(zip(results, series, colours)):
        marker = _MARKERS.get(result.solver, "o x s d ^".split()[k % 5])
        label = f"{result.solver}" + (f" ({result.digits} digits)" if result.digits else "") \
            + f": rank {result.rank}" + (" (certified)" if result.certified else "")
        xs = [i + 1 for i, v in enumerate(logs) if v is not None]
        ax.plot(xs, [v for v in logs if v is not None], ls="", marker=marker, ms=7, color=colour,
                label=label, mfc="none" if marker == "o" else None)
        zeros = [i + 1 for i, v in enumerate(logs) if v is None]
        if zeros:
            ax.plot(zeros, [bottom] * len(zeros), ls="", marker="v", mfc="none", color=colour,
                    label=f"{result.solver}: exactly 0")
        ax.axvline(result.rank + 0.5, color=colour, ls=":", lw=1)
        diag = result.diagnostics
        if diag.rank_tolerance:
            ax.axhline(_log10_text(diag.rank_tolerance), color=colour, ls="--", lw=0.8,
                       label=f"{result.solver}: rank tolerance")
        if diag.tail_bound is not None:
            level = _log10_text(diag.tail_bound)
            if level is not None:
                ax.plot([result.rank + 0.5, len(logs) + 0.5], [level, level], color=colour, ls="--",
                        lw=0.8, label=f"{result.solver}: proven bound after the ridge")
    ax.set_xlabel("index i")
    ax.set_ylabel("log10 s_i  (W with columns scaled by powers of two)")
    ax.set_ylim(bottom - 1, max(finite) + 1)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{results[0].mechanism}: singular values of W", fontsize=10)
    fig.tight_layout()
    return _save(fig, path, fmt)
