"""Multipole transfers across a joint found by sampling, beyond the joint type's rules.

A joint type's rules (:mod:`baseparams.dynamics.transfers`) state what may cross it whatever the
mechanism. Some mechanisms allow more: across a prismatic joint whose sliding axis stays
parallel to the common angular velocity (a SCARA quill) dipoles cross in every direction,
and across a prismatic joint of a planar motion a dipole along the rotation axis crosses
(an axis that need not be one of the joint frame's), which no general rule for P joints
can say. So across each joint between two moving bodies, a monopole at the joint centre
and dipoles there are tried, along the joint frame's axes and along every candidate
direction of either body (its axes and its joints' axes, seen from the joint frame at the
reference configuration), on the two bodies' sampled Lagrangian rows (:func:`baseparams.plugins.solvers.symbolic.body_conditions.lagrangian_rows`).
Those that pass (relative residual below 1e-14 on the sampled states) are generators of
condition 0, accepted on numerical evidence like the body conditions and re-checked in
ball arithmetic by the solver.

Each try is first made in working-precision numbers (the joint frames evaluated once):
most are far from null, and only those whose residual is below ``PREFILTER`` (1e3 times
the tolerance, far beyond any rounding) are built exactly in sympy and tested as before.
"""

from collections.abc import Callable
from typing import Any

import mpmath

from baseparams.plugins.solvers.symbolic.body_conditions import (NULL_TOL, body_candidates, dedupe, lagrangian_rows,
                                                                residual, to_number)
from baseparams.model.mechanism import Joint, Mechanism
from baseparams.dynamics.transfers import (Generator, as_vector, dipole_params, joint_frames, map_direction, map_point,
                        monopole_params)

with mpmath.workprec(53):       # a fixed constant, whatever precision is current at import
    PREFILTER = NULL_TOL * 1000  # a try whose numeric residual is above this is not null


def sampled_joint_transfers(mechanism: Mechanism, joint: Joint, forms: list, known: set[str],
                            digits: int = 30) -> list[Generator]:
    """Generators (condition 0) of the transfers across ``joint`` that leave the Lagrangian
    unchanged on every sampled state ``forms`` (from
    :func:`baseparams.plugins.solvers.symbolic.body_conditions.analyse_bodies`), except the multipoles ``known``
    (names) the joint type's rules already give. Nothing across a joint with ground: a
    transfer there changes one body only, which the body conditions cover."""
    if joint.parent == 0 or joint.child == 0:
        return []
    dps = digits - 2                # the forms' digits (analyse_bodies at the same ``digits``)
    with mpmath.workdps(dps):
        rows = lagrangian_rows(mechanism, [joint.parent, joint.child], forms, dps)
        frames = joint_frames(mechanism, joint)
        subs = mechanism.geometry_subs
        zero = [0, 0, 0]
        # each try: its exact vector's maker, and the same in working-precision numbers on
        # the numeric frames (rotation rows, point): most tries are far from null (residual
        # >= 1e3 NULL_TOL, beyond any rounding) and need no exact vector at all
        tries: list[tuple[str, Any, Callable[..., Any], Callable[..., Any]]] = []
        if "monopole" not in known:
            tries.append(("monopole", None, lambda fr: monopole_params(map_point(fr, zero)),
                          lambda fr: monopole_params(fr[1])))
        for text, u, u_num in joint_directions(mechanism, joint, frames, dps):
            tries.append(("dipole", (text, u),
                          lambda fr, u=u: dipole_params(map_point(fr, zero), map_direction(fr, u)),
                          lambda fr, u=u_num: dipole_params(fr[1], [mpmath.fsum(fr[0][i][k] * u[k] for k in range(3))
                                                                     for i in range(3)])))
        names = mechanism.body_parameters(joint.parent) + mechanism.body_parameters(joint.child)
        numeric = {b: ([[to_number(c, subs, dps) for c in row] for row in frames[b][0]],
                       [to_number(c, subs, dps) for c in frames[b][1]]) for b in (joint.parent, joint.child)}
        out = []
        for multipole, axis, make, make_num in tries:
            num = [v * sign for body, sign in ((joint.parent, 1), (joint.child, -1)) for v in make_num(numeric[body])]
            if residual(rows, num) >= PREFILTER:
                continue
            vector: dict[str, Any] = {}
            for body, sign in ((joint.parent, 1), (joint.child, -1)):
                for name, v in as_vector(mechanism.body_parameters(body), make(frames[body]), sign).items():
                    vector[name] = vector.get(name, 0) + v
            num = [to_number(vector.get(n, 0), subs, dps) for n in names]
            if residual(rows, num) >= NULL_TOL:
                continue
            sides = {b: {"point": map_point(frames[b], zero),
                         "direction": None if axis is None else map_direction(frames[b], axis[1])}
                     for b in (joint.parent, joint.child)}
            label = "monopole" if axis is None else f"dipole along {axis[0]}"
            out.append(Generator(vector={k: v for k, v in vector.items() if v != 0}, kind="transfer",
                                 multipole=multipole, condition=0, bodies=(joint.parent, joint.child),
                                 joint=joint, sides=sides, label=label + " (sampled)"))
        return out


def joint_directions(mechanism: Mechanism, joint: Joint, frames: dict, dps: int) -> list:
    """Unit directions in the joint frame to try dipoles along, without repeats (lines):
    the joint frame's x, y, z axes, then each body's candidate directions
    (:func:`baseparams.plugins.solvers.symbolic.body_conditions.body_candidates`) as the joint frame sees them
    at the reference configuration (``u = R^T d`` with R the frame's axes in that body)."""
    items = [(f"the joint's {a} axis", [int(i == k) for i in range(3)]) for k, a in enumerate("xyz")]
    for body in (joint.parent, joint.child):
        r, _ = frames[body]
        _, dirs = body_candidates(mechanism, body)
        for name, d in dirs:
            items.append((f"{name} of body {body}", [sum(r[k][i] * d[k] for k in range(3)) for i in range(3)]))
    return dedupe(items, mechanism.geometry_subs, dps, directions=True)
