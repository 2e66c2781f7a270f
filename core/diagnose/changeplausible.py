"""Changes no robot makes (issue 42): a friction change that leaves the changed runs' friction
at or below zero, and a body change beyond any physical scale of the mechanism; each stands
for another force (a payload's, or what the shared model misses on motions it was not fitted
to) and is not named.

Viscous and Coulomb friction resist the motion on every robot: the rule is diagnosis's own
for a named effect (:func:`.impossible.implausible`: a friction coefficient is positive),
applied to the changed runs' friction (the shared model's + the change's estimate). Why:
the real TX40's two halves (other motions) with a 2 kg load's torque added to the second
named 'coulomb_friction on joint_3: -7.26 +- 0.98' against a shared 5.67 (the changed joint
pushing with 1.6 N m), a gain of +88 % beside it and a body on link_2, instead of the load.

A body's ten columns nearly cancel one another on a short motion: the real Kinova repeat (133
paired samples) with a 1 kg load on spherical_wrist_1_link named 'body on half_arm_2_link:
-2900 +- 900 kg'. A change of a coefficient above a hundred times what the mechanism's bodies
could have (:func:`.impossible.body_scales`: its total mass, times its reach for a first
moment, its square for an inertia) is no change of a body.
"""

from collections.abc import Mapping, Sequence

import numpy as np

from baseparams import registry
from baseparams.diagnose.candidates import known_values
from baseparams.model.mechanism import EffectSpec, Mechanism

# the friction kinds a change is judged on, and the coefficient that must stay positive
FRICTION = {"viscous_friction": "fv", "coulomb_friction": "fc"}


def shared_values(mechanism: Mechanism, effects: Sequence[EffectSpec], theta: np.ndarray,
                  offset: int) -> dict[tuple[str, str], float]:
    """The shared model's friction on each coordinate ((kind, coordinate) -> value): fitted
    (``effects``' coefficients in ``theta`` from ``offset`` on, in order) or known (the
    mechanism's given values); what a change of that kind there adds to."""
    values: dict[tuple[str, str], float] = {}
    at = offset
    for spec in effects:
        effect = registry.effects()[spec.kind].item
        names = effect.coefficients
        if spec.kind in FRICTION:
            values[(spec.kind, spec.coordinate)] = float(theta[at + names.index(FRICTION[spec.kind])])
        at += len(names)
    for spec in mechanism.effects:
        if spec.kind in FRICTION and (spec.kind, spec.coordinate) not in values:
            given = known_values(mechanism, spec.kind, spec.coordinate)
            if FRICTION[spec.kind] in given:
                values[(spec.kind, spec.coordinate)] = float(given[FRICTION[spec.kind]])
    return values


def impossible_changes(changes: Sequence[Mapping], shared: Mapping[tuple[str, str], float],
                       limits: Mapping[str, float] | None = None) -> list[tuple[str, str, str]]:
    """(kind, coordinate, why) of each change in ``changes`` (the named entries: kind,
    coordinate, value, std) no robot makes: a friction change whose changed friction (shared
    + change) is not positive; a body's or mass's coefficient above its ``limits``
    (:func:`.impossible.body_limits`)."""
    out = []
    for entry in changes:
        key = (str(entry["kind"]), str(entry["coordinate"]))
        value = entry.get("value")
        if key in shared and isinstance(value, float):
            std = float(entry["std"])
            changed = shared[key] + value
            if changed <= 0:
                out.append((*key, f"{key[0]}:{key[1]} would leave the changed runs' friction at {shared[key]:.3g} "
                                  f"{value:+.3g} = {changed:.3g} (+- {std:.2g}): no friction drives the motion; it "
                                  "stands for another change, searched for without it"))
        elif key[0] in ("body", "mass") and limits:
            values = value if isinstance(value, Mapping) else {"m": value}
            beyond = [(n, v) for n, v in values.items() if isinstance(v, float) and n in limits and abs(v) > limits[n]]
            if beyond:
                n, v = beyond[0]
                out.append((*key, f"{key[0]}:{key[1]} changes {n} by {v:.3g}, beyond any physical scale of this "
                                  f"mechanism (above {limits[n]:.3g}: a hundred times what its bodies could have): "
                                  "its columns cancel one another; it stands for another change, searched for "
                                  "without it"))
    return out
