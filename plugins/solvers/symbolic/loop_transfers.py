"""Null generators of planar loops on a moving base: a dependency no single joint or body has.

A *planar loop* is a cycle of the joint graph whose joints are all revolute with parallel
axes (direction b). Relative to any one of its bodies, its bodies then rotate about b
only: body k's angular velocity is ``omega_k = Omega + thetadot_k b`` (Omega that of a
reference body of the loop, thetadot_k its rate relative to it). Let the loop be
traversed body after body, body k entered at joint point P_in and left at P_out (joint
origins, in body k's axes), and ``a_k = P_out - P_in`` (fixed in body k). The loop closes:
``sum_k a_k = 0``, hence, differentiating in the reference body,
``sum_k thetadot_k b x a_k = 0``.

Put on each body of the loop the quadrupole ``Q_k = b w_k^T + w_k b^T`` with
``w_k = b x a_k`` (perpendicular to b; with z = b and x along the link's projection, this
is the product of inertia Iyz of size |a_k|). Its kinetic energy is

  1/2 sum_k omega_k^T Q_k omega_k = sum_k (b.omega_k)(w_k.omega_k)
                                  = sum_k (b.Omega + thetadot_k)(w_k.Omega)   (w_k perpendicular to b)
                                  = (b.Omega) (sum_k w_k).Omega + (sum_k thetadot_k w_k).Omega = 0,

since ``sum_k w_k = b x sum_k a_k = 0`` and ``sum_k thetadot_k w_k = sum_k thetadot_k b x a_k = 0``
(the differentiated closure). A quadrupole has no potential energy. So
``n = sum_k Q_k`` (each Q_k as body k's six inertia entries) is an exact null vector of W,
whatever the loop's base does: a Lagrangian identity of the loop as a whole, not of any
joint or body. It is not a sum of null transfers across the loop's joints: split edge by
edge it is the "rotated dipole" ``sym(b (b x r))`` (r the joint point from the body's
origin) moved across each joint, which is null only summed around the closed loop.
(The same construction with ``w_k = a_k`` is null too, but it is the joints' dipole
transfers along b carried around the loop: already in the joint rules' span.)

When ground is in the loop, Omega = 0 and every body of the loop rotates about the fixed
direction b: each Q_k alone has no effect (condition 5) and the body conditions already
give it; such cycles are skipped. Loops with prismatic joints (a sliding length in the
closure) or other joints are not covered.

The generators are exact (geometry symbols allowed): the axes must be parallel
identically, not only at the mechanism's values. One generator per independent cycle of
each group of R joints with parallel axes (a cycle basis: the generator is linear in the
cycle, so every planar cycle's generator is a combination of the basis's).
"""

from collections.abc import Sequence
from typing import Any

import sympy

from baseparams.model.mechanism import Joint, Mechanism
from baseparams.dynamics.transfers import Generator, add_vectors, as_vector, joint_frames, map_direction, \
    map_point, quadrupole_params

CONDITION = 7          # not one of the paper's conditions (0-6): a loop's, see the module doc
ORIGIN = (0, 0, 0)
Z = (0, 0, 1)


def is_revolute(joint: Joint) -> bool:
    """One rotation about the joint frames' common z axis (the kinematics of R)."""
    return tuple(joint.type.motions) == (("R", "z"),)


def _cross(a: Sequence[Any], b: Sequence[Any]) -> list[Any]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _parallel(a: Sequence[Any], b: Sequence[Any]) -> bool:
    return all(sympy.simplify(c) == 0 for c in _cross(a, b))


def _groups(mechanism: Mechanism, joints: Sequence[Joint], axes: dict[str, Any]) -> list[list[Joint]]:
    """Joints grouped by parallel axes: two R joints on one body whose axes are parallel
    there are in one group (relative rotations about b keep b, so this is transitive
    along the group)."""
    parent = {j.name: j.name for j in joints}

    def find(x: str) -> str:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    by_body: dict[int, list[Joint]] = {}
    for j in joints:
        for b in (j.parent, j.child):
            by_body.setdefault(b, []).append(j)
    for body, incident in by_body.items():
        if body == 0:
            continue            # ground: its cycles are skipped, no need to join through it
        for i, e in enumerate(incident):
            for f in incident[i + 1:]:
                if find(e.name) != find(f.name) and _parallel(axes[e.name][body], axes[f.name][body]):
                    parent[find(e.name)] = find(f.name)
    groups: dict[str, list[Joint]] = {}
    for j in joints:
        groups.setdefault(find(j.name), []).append(j)
    return list(groups.values())


def _cycles(group: Sequence[Joint]) -> list[tuple[Joint, list[tuple[Any, ...]]]]:
    """A cycle basis of the group's joints: per joint outside a spanning forest (in the
    mechanism's joint order), the cycle it closes as [(body, joint in, joint out), ...]."""
    neighbours: dict[int, list[tuple[int, Joint]]] = {}
    for j in group:
        neighbours.setdefault(j.parent, []).append((j.child, j))
        neighbours.setdefault(j.child, []).append((j.parent, j))
    up: dict[int, Any] = {}                    # body -> (parent body, joint) in the forest
    depth = {}
    tree = set()
    for start in sorted(neighbours):
        if start in depth:
            continue
        depth[start], up[start] = 0, None
        frontier = [start]
        while frontier:
            nxt = []
            for b in frontier:
                for n, j in neighbours[b]:
                    if n not in depth:
                        depth[n], up[n] = depth[b] + 1, (b, j)
                        tree.add(j.name)
                        nxt.append(n)
            frontier = nxt
    out = []
    for j in group:
        if j.name in tree:
            continue
        # path child -> ... -> common ancestor <- ... <- parent, closed by j (parent -> child)
        a, b = j.child, j.parent
        left, right = [], []                     # (body, joint towards the ancestor)
        while a != b:
            if depth[a] >= depth[b]:
                left.append((a, up[a][1]))
                a = up[a][0]
            else:
                right.append((b, up[b][1]))
                b = up[b][0]
        # walk: enter the child by j, climb to the ancestor, descend to the parent, leave by j
        path = [body for body, _ in left] + [a] + [body for body, _ in reversed(right)]
        links = [jj for _, jj in left] + [jj for _, jj in reversed(right)]
        joints_in = [j] + links
        joints_out = links + [j]
        out.append((j, list(zip(path, joints_in, joints_out))))
    return out


def planar_loop_generators(mechanism: Mechanism) -> list[Generator]:
    """One generator (condition 7) per independent planar loop without ground (module doc)."""
    joints = [j for j in mechanism.joints if is_revolute(j)]
    if len(joints) < 3:
        return []
    frames = {j.name: joint_frames(mechanism, j) for j in joints}
    axes = {j.name: {b: map_direction(frames[j.name][b], Z) for b in (j.parent, j.child)} for j in joints}
    out = []
    for group in _groups(mechanism, joints, axes):
        if len(group) < 3:
            continue
        for closing, cycle in _cycles(group):
            bodies = [body for body, _, _ in cycle]
            if 0 in bodies:
                continue
            vector: dict[str, Any] = {}
            for body, j_in, j_out in cycle:
                p_in = map_point(frames[j_in.name][body], ORIGIN)
                p_out = map_point(frames[j_out.name][body], ORIGIN)
                b = axes[j_in.name][body]
                norm2 = sum(c * c for c in b)          # 1 for the frames' unit axes
                w = _cross(b, [p_out[i] - p_in[i] for i in range(3)])
                q = [[sympy.simplify((b[r] * w[c] + w[r] * b[c]) / norm2) for c in range(3)] for r in range(3)]
                vector = add_vectors(vector, as_vector(mechanism.body_parameters(body), quadrupole_params(q)))
            if not vector:
                continue
            first = bodies.index(min(bodies))
            loop = "-".join(str(b) for b in bodies[first:] + bodies[:first])
            out.append(Generator(vector=vector, kind="transfer", multipole="quadrupole", condition=CONDITION,
                                 bodies=tuple(bodies), joint=closing,
                                 label=f"planar-loop quadrupole (loop {loop})"))
    return out
