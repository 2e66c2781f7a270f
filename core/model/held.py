"""A mechanism with some joints held still: a recording's ``[held]`` coordinates.

A robot's model often has joints its recording does not log because they did not move: a
gripper's fingers, a tool changer, a rail parked for the run. Fitted as joints, their
parameters have no motion to be told apart by (a Panda's still fingers made its fit's
condition number 5e13 and base parameters of 1e7 +- 1e13); and a log without their channels
could not be read at all. Held, each becomes a rigid connection at its value: its child
moves with its parent, the base parameters are the held mechanism's, and it has no force to
measure. The bodies and their standard parameters stay as they were, so results over them
(``identify``, ``--params``) mean the same.

The joint's parent frame is moved to where the child's frame is at the held value: along z
for a sliding motion, turned about z for a turning one (by an exact rational rotation within
1e-12 rad of the value: geometry stays exact).
"""

from collections.abc import Mapping
from dataclasses import replace
from fractions import Fraction

import sympy

from baseparams import registry
from baseparams.errors import InputError
from baseparams.model.mechanism import Frame, Joint, Mechanism, TreeEdge, _default_ref
from baseparams.numeric.backends import Symbolic

# The held angle's half-angle tangent as a fraction with at most this denominator: cos and
# sin of the rotation are then exact rationals, within about 1e-12 rad of the value.
ANGLE_DENOMINATOR = 10 ** 12


def hold(mechanism: Mechanism, values: Mapping[str, Fraction], *, file: str | None = None,
         key: str = "held") -> Mechanism:
    """``mechanism`` with each coordinate of ``values`` held at its value (a rigid connection);
    a coordinate that follows a held one (``<mimic>``) is held with it (it may be listed too,
    at the value it follows), a motor that turns with held joints only stops (it is dropped),
    and the mechanism's effects on held coordinates and stopped motors are dropped. Bad
    requests are InputErrors at ``key``."""
    if not values:
        return mechanism
    if mechanism.loops:
        raise InputError(f"{mechanism.name} has closed loops: holding a joint would change which coordinates "
                         "are independent; hold joints of open chains and trees only", file=file, key=key)
    held = dict(values)
    for name in values:
        where = f"{key}.{name}"
        if name not in mechanism.coordinates:
            raise InputError(f"{name!r} is not a joint coordinate of {mechanism.name} "
                             f"({', '.join(mechanism.coordinates)})", file=file, key=where)
        coupling = next((c for c in mechanism.couplings if c.coordinate == name), None)
        if coupling is not None:
            follows = coupling.ratio * values[coupling.leader] + coupling.offset if coupling.leader in values else None
            if follows is None or abs(float(values[name] - follows)) > 1e-9 * max(1.0, abs(float(follows))):
                at = f" (at {float(follows):.6g} with it)" if follows is not None else ""
                raise InputError(f"{name!r} follows {coupling.leader!r} (a coupling): hold {coupling.leader!r}, and "
                                 f"{name!r} is held with it{at}", file=file, key=where)
    for coupling in mechanism.couplings:
        if coupling.leader in held:
            held[coupling.coordinate] = coupling.ratio * held[coupling.leader] + coupling.offset
    still_motors = {m.name for m in mechanism.motors if all(c in held for c, _ in m.ratios)}
    for motor in mechanism.motors:
        turning = [c for c, _ in motor.ratios if c in held]
        if turning and motor.name not in still_motors:
            raise InputError(f"motor {motor.name!r} turns with {turning[0]!r} and with joints that move: a "
                             "coupled motor's joints cannot be held apart", file=file, key=f"{key}.{turning[0]}")
    fixed_type = registry.joint_types()["Fixed"].item
    swapped: dict[int, Joint] = {}
    for joint in mechanism.joints:
        on = [c for c in joint.coordinates if c in held]
        if not on:
            continue
        where = f"{key}.{on[0]}"
        motions = tuple(getattr(joint.type, "motions", ()))
        if len(joint.coordinates) != 1 or len(motions) != 1 or motions[0][1] != "z" or motions[0][0] not in "RP":
            raise InputError(f"{on[0]!r} is a coordinate of a {joint.type.name} joint: only joints of one turning "
                             "or sliding motion along their z axis (R, P) can be held", file=file, key=where)
        frame = _moved(mechanism, joint.parent_frame, motions[0][0], held[on[0]])
        swapped[id(joint)] = replace(joint, type=fixed_type, parent_frame=frame, coordinates=(), limits={},
                                     drive_limits={})
    kept = tuple(c for c in mechanism.coordinates if c not in held)

    def new(joint: Joint) -> Joint:
        return swapped.get(id(joint), joint)

    trajectory = mechanism.trajectory
    if trajectory is not None:
        trajectory = replace(trajectory, expressions={c: e for c, e in trajectory.expressions.items() if c not in held})
    return replace(
        mechanism,
        joints=tuple(new(j) for j in mechanism.joints),
        tree=tuple(TreeEdge(new(e.joint), e.reversed) for e in mechanism.tree),
        coordinates=kept,
        independent=tuple(c for c in mechanism.independent if c not in held),
        couplings=tuple(c for c in mechanism.couplings if c.coordinate not in held),
        motors=tuple(m for m in mechanism.motors if m.name not in still_motors),
        effects=tuple(e for e in mechanism.effects if e.coordinate not in held and e.coordinate not in still_motors),
        trajectory=trajectory,
        gruebler=mechanism.gruebler - sum(1 for c in values if c in mechanism.independent),
    )


def _moved(mechanism: Mechanism, frame: Frame, motion: str, value: Fraction) -> Frame:
    """The parent's joint frame where the child's joint frame sits at ``value``: moved
    ``value`` along its z (P), or turned by ``value`` about it (R)."""
    axis = [sympy.sympify(c) for c in frame.axis]
    length = sympy.sqrt(sum((c.xreplace(mechanism.geometry_subs)) ** 2 for c in axis))
    if motion == "P":
        step = sympy.Rational(value.numerator, value.denominator) / length
        return replace(frame, point=tuple(p + step * a for p, a in zip(frame.point, axis)))
    if value == 0:
        return frame
    ref = [sympy.sympify(c) for c in frame.ref] if frame.ref is not None else \
        _default_ref(frame.axis, mechanism.geometry_subs, Symbolic())       # the frame's own default
    along = sum(r * a for r, a in zip(ref, axis)) / length ** 2
    perpendicular = [r - along * a for r, a in zip(ref, axis)]
    cross = [axis[1] * ref[2] - axis[2] * ref[1], axis[2] * ref[0] - axis[0] * ref[2],
             axis[0] * ref[1] - axis[1] * ref[0]]
    half = _half_angle_tangent(value)
    t = sympy.Rational(half.numerator, half.denominator)
    cos, sin = (1 - t ** 2) / (1 + t ** 2), 2 * t / (1 + t ** 2)
    return replace(frame, ref=tuple(cos * p + sin * c / length for p, c in zip(perpendicular, cross)))


def _half_angle_tangent(value: Fraction) -> Fraction:
    """tan(value / 2) as a fraction (denominator at most :data:`ANGLE_DENOMINATOR`)."""
    import mpmath
    with mpmath.workdps(40):
        exact = mpmath.tan(mpmath.mpf(value.numerator) / value.denominator / 2)
        return Fraction(str(mpmath.nstr(exact, 35))).limit_denominator(ANGLE_DENOMINATOR)
