"""Bodies that move together through a closed loop: loads the data may not tell apart.

A parallelogram's links turn together (its back, front and end links all turn with the
pitch) or translate together (its top and bottom beams keep the base's orientation and move
with the back link's points). A load on one then acts on the torques as a load on another,
for every motion of the loop itself: 205 g on the top beam of ``parallelogram_arm`` was left
ambiguous between ``body:pitch_top`` and ``body:pitch_back`` (|corr| 0.9999), nothing named
(issue 49). Such a group is one change with its physical alternatives, and the motion that
could separate them is what the geometry allows, never "a wider range of positions".

Found numerically, as :mod:`baseparams.dynamics.tied` finds tied coordinates: the bodies'
ten inertial columns at states independent of any recording (the default trajectory's
positions, random velocities and accelerations, loops closed). Two bodies are *alike* under
a set of motions when every load on one (the one whose columns span less) is a load on the
other: the rank of their columns together is the larger of their ranks. Alike at every
state: no motion separates them. Alike whenever one independent coordinate is held still:
only motions that move all such coordinates at once separate them (on the arm: the yaw
turning while the pitch moves, through the links' distances from the yaw axis).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter
from scipy.special import fdtrc

from baseparams.diagnose.changesearch import Search, noise_filters
from baseparams.diagnose.selection import Candidate
from baseparams.diagnose.wald import orthonormal_basis, project_out
from baseparams.dynamics.forces import Motion, evaluate, independent_names, inertial_columns
from baseparams.dynamics.trajectory import Trajectory
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Float64

STATES = 64          # states per batch (x the independent coordinates: rows)
BATCHES = 2          # independent batches of random speeds and accelerations
RANK_TOL = 1e-9      # singular values of the unit-scaled columns below this fraction are zero


@dataclass(frozen=True)
class Equivalence:
    """Bodies of one closed loop whose loads the motion may not tell apart. ``loops``: the
    loop joints that tie them; ``separated_by``: the independent coordinates that must all
    move for a motion to separate them (each held still makes them alike); empty when no
    motion can; ``reason`` and ``separate_by`` say so in words."""
    bodies: tuple[str, ...]
    loops: tuple[str, ...]
    separated_by: tuple[str, ...]
    reason: str
    separate_by: str

    def to_json(self) -> dict:
        return {"bodies": list(self.bodies), "loops": list(self.loops), "separated_by": list(self.separated_by),
                "reason": self.reason, "separate_by": self.separate_by}


def cycle(mechanism: Mechanism, loop_name: str) -> frozenset[int]:
    """The bodies on a loop joint's cycle: the tree paths from its two bodies up to where they
    meet, that body included."""
    parent = {edge.new: edge.known for edge in mechanism.tree}
    joint = next(j for j in mechanism.loops if j.name == loop_name)

    def path(body: int) -> list[int]:
        out = [body]
        while out[-1] in parent:
            out.append(parent[out[-1]])
        return out

    a, b = path(joint.parent), path(joint.child)
    meet = next(x for x in a if x in b)
    return frozenset(a[:a.index(meet) + 1] + b[:b.index(meet) + 1])


def _meet(mechanism: Mechanism, loop_name: str) -> int:
    """The body where a loop joint's two tree paths meet."""
    parent = {edge.new: edge.known for edge in mechanism.tree}
    joint = next(j for j in mechanism.loops if j.name == loop_name)
    up = [joint.parent]
    while up[-1] in parent:
        up.append(parent[up[-1]])
    body = joint.child
    while body not in up:
        body = parent[body]
    return body


def tying_loops(mechanism: Mechanism, labels: Sequence[int]) -> tuple[str, ...]:
    """The loop joints whose cycles (chained through shared bodies) hold every body of
    ``labels``; () when no chain of loops holds them all. A cycle's meeting body (the loop's
    base: the arm's yaw link) is not among the bodies the loop moves together: a load on it
    and one on a link are alike only as any parent's and child's are (Gautier's regrouping)."""
    cycles = {j.name: cycle(mechanism, j.name) - {_meet(mechanism, j.name)} for j in mechanism.loops}
    wanted = set(labels)
    for start, bodies in cycles.items():
        if not wanted & bodies:
            continue
        chain, held, grew = [start], set(bodies), True
        while grew:
            grew = False
            for name, more in cycles.items():
                if name not in chain and held & more:
                    chain.append(name)
                    held |= more
                    grew = True
        if wanted <= held:
            return tuple(chain)
    return ()


@functools.lru_cache(maxsize=8)
def _columns(mechanism: Mechanism, held: tuple[str, ...]) -> np.ndarray | None:
    """K's rows (states x f, 10 x bodies) at the default trajectory's positions with random
    speeds and accelerations, the ``held`` coordinates' set to zero; None when the mechanism
    has no default trajectory or a state does not close."""
    names = independent_names(mechanism)
    try:
        trajectory = Trajectory.default(mechanism, samples=STATES)
        t = np.array([float(x) for x in trajectory.times])
        z, zd, zdd = trajectory.independent_values(mechanism, Float64(), t)
        q = np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in z], axis=1)
        speed = np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in zd], axis=1).std(axis=0)
        accel = np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in zdd], axis=1).std(axis=0)
        rng = np.random.default_rng(0)
        still = np.array([c in held for c in names])
        blocks = []
        for _ in range(BATCHES):
            qd = np.where(still, 0.0, rng.standard_normal(q.shape) * np.where(speed > 0, speed, 1.0))
            qdd = np.where(still, 0.0, rng.standard_normal(q.shape) * np.where(accel > 0, accel, 1.0))
            motion = Motion(t, q, qd, qdd)
            k = inertial_columns(evaluate(mechanism, motion), motion.count)
            blocks.append(k.reshape(-1, k.shape[-1]))
    except (InputError, KinematicsError):
        return None
    return np.concatenate(blocks)


def _rank(columns: np.ndarray) -> int:
    norms = np.linalg.norm(columns, axis=0)
    live = columns[:, norms > RANK_TOL * max(float(norms.max(initial=0.0)), 1e-300)]
    if live.shape[1] == 0:
        return 0
    s = np.linalg.svd(live / np.linalg.norm(live, axis=0), compute_uv=False)
    return int(np.sum(s > RANK_TOL * s[0]))


def _alike(K: np.ndarray, a: int, b: int) -> bool:
    """Whether every load on one of bodies ``a``, ``b`` (indices in file order) is a load on
    the other at the rows of ``K``: their columns together span no more than the larger."""
    ka, kb = K[:, 10 * a:10 * a + 10], K[:, 10 * b:10 * b + 10]
    return _rank(np.concatenate([ka, kb], axis=1)) == max(_rank(ka), _rank(kb))


def equivalence(mechanism: Mechanism, names: Sequence[str]) -> Equivalence | None:
    """When the bodies ``names`` (two or more, :func:`~baseparams.diagnose.derived.body_name`)
    lie on closed loops that tie them and are alike (module docstring) at every state or
    whenever some independent coordinate is held still: how, and which motion separates
    them. None otherwise (an ordinary ambiguity, which a richer motion may resolve)."""
    from baseparams.diagnose.derived import body_name
    index = {body_name(mechanism, b.label): k for k, b in enumerate(mechanism.bodies)}
    distinct = list(dict.fromkeys(names))
    if len(distinct) < 2 or not all(n in index for n in distinct):
        return None
    labels = [mechanism.bodies[index[n]].label for n in distinct]
    loops = tying_loops(mechanism, labels)
    if not loops:
        return None
    members = [index[n] for n in distinct]

    def alike(held: tuple[str, ...]) -> bool | None:
        K = _columns(mechanism, held)
        if K is None:
            return None
        return all(_alike(K, members[0], m) for m in members[1:])

    everywhere = alike(())
    if everywhere is None:
        return None
    separated_by = () if everywhere else tuple(c for c in independent_names(mechanism) if alike((c,)))
    if not everywhere and not separated_by:
        return None
    K = _columns(mechanism, separated_by[:1])
    assert K is not None                      # alike() computed it
    ranks = {n: _rank(K[:, 10 * k:10 * k + 10]) for n, k in zip(distinct, members)}
    return Equivalence(tuple(distinct), loops, separated_by, _reason(ranks, loops, separated_by),
                       _separate_by(separated_by))


def _reason(ranks: dict[str, int], loops: Sequence[str], separated_by: Sequence[str]) -> str:
    """Which loads act as which (the body whose columns span most holds the others'), and when."""
    names = list(ranks)
    widest = max(names, key=lambda n: ranks[n])
    same = [n for n in names if n != widest and ranks[n] == ranks[widest]]
    fewer = [n for n in names if n != widest and ranks[n] < ranks[widest]]
    parts = ([f"a load on {' or '.join(same)} acts as one on {widest} and back"] if same else []) + \
        ([f"every load on {' or '.join(fewer)} acts as one on {widest}"] if fewer else [])
    through = f"the closed loop{'s' if len(loops) > 1 else ''} {', '.join(loops)}"
    when = "at every state" if not separated_by else f"whenever {' or '.join(separated_by)} is still"
    return f"{', '.join(names[:-1])} and {names[-1]} move together through {through}: {when}, {'; '.join(parts)}"


def _separate_by(separated_by: Sequence[str]) -> str:
    if not separated_by:
        return "no motion can: the loop moves these bodies alike at every state"
    if len(separated_by) == 1:
        return (f"only a motion of {separated_by[0]} while the loop moves (with {separated_by[0]} still they are "
                "alike); a wider range of the loop's own motion does not")
    together = " and ".join(separated_by)
    return (f"only a motion in which {together} move at once (any of them still makes them alike); a wider "
            "range of the loop's own motion does not")


def body_group(mechanism: Mechanism, candidates: Sequence[Candidate]) -> Equivalence | None:
    """The :func:`equivalence` of a group of body and mass candidates (an ambiguous group of a
    diagnosis); None when any is of another kind or the bodies are not loop-equivalent."""
    if not candidates or any(c.kind not in ("body", "mass") for c in candidates):
        return None
    return equivalence(mechanism, [c.coordinate for c in candidates])


def named_groups(mechanism: Mechanism, chosen: Search, kept: set, changes: list[dict], ambiguous: list[dict],
                 y: np.ndarray, alpha: float, entries: Callable[[Search, set], list[dict]]
                 ) -> tuple[list[dict], list[dict]]:
    """(changes, ambiguous) with each body or mass change on a loop body, or ambiguous group
    of them, named as one change with its physical alternatives: of the group and the changes
    on the bodies that move with it through the loop (:func:`equivalence`), those the
    difference ``y`` does not reject (:func:`_undominated`). Named: the alternative whose mass
    the data fix best (its ``entries``, a search with it alone in the group's place), with
    ``"equivalent"`` (the bodies, the loops, why, the motion that would separate them) and
    ``"alternatives"``: the same change on each other, in physical terms. Why: 205 g on the
    arm's top beam was ambiguous between the top beam and the back link, nothing named, yet
    the top beam's alternative carries the 205 g; and a back-link change stood for it with no
    word of the beam, which explained more (issue 49)."""
    body_at = {c.coordinate: i for i, c in enumerate(chosen.candidates) if c.kind == "body"}
    for head in [i for i in chosen.added if i in kept]:
        group = [head] + list(chosen.ambiguous.get(head, []))
        cands = [chosen.candidates[j] for j in group]
        if any(c.kind not in ("body", "mass") for c in cands):
            continue
        rest = [j for j in chosen.in_model if j in kept and j not in group]
        pool = [j for name, j in body_at.items() if j not in group + rest
                and equivalence(mechanism, [cands[0].coordinate, name]) is not None]
        if not pool and (len(group) < 2 or equivalence(mechanism, [c.coordinate for c in cands]) is None):
            continue                  # no loop body among them: the search's own answer stands
        members = _undominated(chosen, y, rest, group + pool, alpha)
        found = equivalence(mechanism, [chosen.candidates[j].coordinate for j in members])
        if members == [head] or (len(members) > 1 and found is None):
            continue
        alternatives = []
        for j in members:
            alone = dataclasses.replace(chosen, added=[j if a == head else a for a in chosen.added],
                                        ambiguous={h: r for h, r in chosen.ambiguous.items() if h != head},
                                        tests={**chosen.tests, j: chosen.tests[head]})
            cand = chosen.candidates[j]
            made = entries(alone, (set(kept) - set(group + members)) | {j})
            alternatives.append(next(e for e in made if (e["kind"], e["coordinate"]) == (cand.kind, cand.coordinate)))
        # named where the data fix a load's mass best (the top beam's, not the back link's first
        # moment that stands in for it)
        alternatives.sort(key=_unidentified)
        labels = {(c.kind, c.coordinate) for c in cands}
        named = {**alternatives[0], "equivalent": found.to_json(), "alternatives": alternatives[1:]} \
            if found is not None else alternatives[0]
        changes = [e for e in changes if (e["kind"], e["coordinate"]) not in labels] + [named]
        ambiguous = [g for g in ambiguous if {(c["kind"], c["coordinate"]) for c in g["candidates"]} != labels]
    return changes, ambiguous


def _undominated(chosen: Search, y: np.ndarray, rest: list[int], members: list[int], alpha: float) -> list[int]:
    """The ``members`` (the first: the search's choice) that no other beats: x is beaten by y
    when y adds over x beside ``rest`` at ``alpha`` and x adds nothing over y (F tests on rows
    weighted by the search's noise weights and whitened by each coordinate's autoregression of
    the residual with the first member, as the search tests its rivals), each at ``alpha``
    over the number of ordered pairs (Bonferroni: an alternative is dropped only on strong
    evidence, as the truth among five was beaten at p = 0.035 otherwise). Why both ways: on a
    top beam's load the back link was chosen first (its columns span more), and the beam,
    which it does not beat, added over it at p = 0.04."""
    weights = chosen.weights
    columns = {j: chosen.candidates[j].columns * weights[None, :, None] for j in rest + members}
    wy0 = y * weights[None, :]
    empty = np.zeros(y.shape + (0,))
    model = np.concatenate([empty] + [columns[j] for j in rest + members[:1]], axis=-1)
    flat = model.reshape(-1, model.shape[-1])
    residual = wy0 - (flat @ np.linalg.lstsq(flat, wy0.reshape(-1), rcond=None)[0]).reshape(y.shape)
    filters = noise_filters(residual, model, unit=chosen.unit)
    start = max(len(f) for f in filters) - 1

    def whitened(x: np.ndarray) -> np.ndarray:
        if x.shape[-1] == 0:
            return np.zeros(((x.shape[0] - start) * x.shape[1], 0))
        out = np.stack([lfilter(f, [1.0], x[:, k], axis=0) for k, f in enumerate(filters)], axis=1)[start:]
        return out.reshape(out.shape[0] * out.shape[1], -1)

    wy = whitened(wy0[:, :, None]).reshape(-1)
    base = whitened(np.concatenate([empty] + [columns[j] for j in rest], axis=-1))
    white = {j: whitened(columns[j]) for j in members}
    level = alpha / max(len(members) * (len(members) - 1), 1)      # Bonferroni over the ordered pairs
    adds = {(x, z): _adds(wy, np.concatenate([base, white[x]], axis=1), white[z], level)
            for x in members for z in members if x != z}
    return [x for x in members if not any(adds[(x, z)] and not adds[(z, x)] for z in members if z != x)]


def _adds(wy: np.ndarray, model: np.ndarray, extra: np.ndarray, alpha: float) -> bool:
    """Whether ``extra``'s directions add to ``model``'s at ``alpha`` (an F test, whitened rows)."""
    basis = orthonormal_basis(model, 1e-9)
    r = wy - basis @ (basis.T @ wy)
    beyond = orthonormal_basis(project_out(extra, basis), 1e-7)
    k, dof = beyond.shape[1], len(wy) - basis.shape[1] - beyond.shape[1]
    if k == 0 or dof <= 0:
        return False
    explained = beyond.T @ r
    ss = float(explained @ explained)
    stat = (ss / k) / (max(float(r @ r) - ss, 1e-300) / dof)
    return float(fdtrc(k, dof, stat)) <= alpha


def _unidentified(entry: dict) -> tuple[bool, float]:
    """(whether the data leave the change without a mass a load can have: undetermined, or not
    above twice its std; minus the mass over its std): the first a reader asks of a load is its
    mass, and it is read where the data fix it best (a front link's "-0.18 kg" or "0.025 kg"
    standing in for a bottom beam's 0.2 +- 0.003 kg is no reading of it)."""
    coefficients = entry["coefficients"]
    m = coefficients.get("m", {})
    physical = m.get("value") is not None and m["value"] > 2 * (m.get("std") or 0.0)
    z = m["value"] / m["std"] if physical and m.get("std") else float("inf") if physical else 0.0
    return not physical, -z
