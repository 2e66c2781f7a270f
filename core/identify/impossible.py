"""Estimates no robot has: a negative friction or rotor inertia, a base parameter that is a
mass or a moment of inertia and comes out negative, a body whose identified parameters are
not a mass distribution. ``identify`` lists them; ``diagnose --params`` says which held
values are such before it runs (docs/identification.md, "Impossible estimates").

What is claimed, and why it is sound:

- **Effect coefficients.** An effect kind's coefficients that must be positive are those of
  diagnosis's physical rule (:data:`POSITIVE`, judged by
  :func:`implausible`: friction, rotor inertia, stiffness):
  one home for the rule.
- **Base parameters.** A base parameter is a linear combination ``c . phi`` of the standard
  parameters, so its sign is not that of any one body's value. A body's ten parameters are a
  mass distribution exactly when its pseudo-inertia ``J(phi_b)`` is positive semidefinite
  (Wensing, Kim and Slotine 2017, :mod:`.physical`); ``J`` is a linear bijection onto the
  symmetric 4 x 4 matrices, so ``c_b . phi_b = <D_b, J(phi_b)>`` for one symmetric ``D_b``,
  and ``c . phi >= 0`` for every physically consistent set of bodies exactly when every
  ``D_b`` is positive semidefinite (the cone is self-dual). Only such base parameters are
  judged: a lone mass (``m3 + m4``), a lone moment of inertia about an axis, ``Izz1 + 0.1
  m2``; never ``Ixx - Iyy`` or a first moment, which may have either sign.
- **Bodies.** Where the base parameters that involve one body alone determine all ten of its
  parameters, its pseudo-inertia's smallest eigenvalue is judged (with its standard deviation
  to first order). Where they determine fewer, nothing is claimed about the body: the rest
  of its mass distribution is free.
- An effect coefficient absorbed into an estimate (its column a combination of the others)
  changes what the estimate stands for; the estimate is judged only when every coefficient
  absorbed into it must be positive and enters with a positive factor (the sum of positives
  is positive), else not at all.

Each is judged with its standard deviation: a value more than :data:`IMPOSSIBLE_STD` std below
zero is impossible; a negative value within that is consistent with zero (listed apart).

- **Beyond any physical scale** (:func:`beyond_scale`): an effect coefficient whose value or
  standard deviation exceeds :data:`PHYSICAL_SCALE` in SI units (a viscous friction of 1e6 N m
  s/rad, a Coulomb friction or offset of 1e6 N m) is no estimate of the effect: the motion
  does not determine it (a joint that never moves: fv = -8.5e18 +- 1.0e18 on a Kinova file),
  or the data are read wrong (a time column of sample indices). Its sign is not judged, its
  size is. A standard deviation far above the value alone is not flagged: a coefficient whose
  effect is absent is zero within its noise, whatever the ratio.
- **Base parameters beyond the mechanism's scale** (:func:`beyond_body_scale`): a base
  parameter ``c . phi`` whose value or standard deviation exceeds ``sum |c_i| S_i``, with S_i
  :data:`SCALE_FACTOR` times what a body of the mechanism could have (its bodies' total mass
  M for a mass, M L for a first moment, M L^2 for an inertia, L its reach: the lengths of
  every joint's frames added up, at least 1 m). No load or error in the model's masses
  reaches a hundred times the whole robot, so such a value is no estimate: a real Kinova's
  first link had mx = -7e4 kg m, its column seen only through an axis 4e-6 rad off vertical
  (the URDF's rpy 1.5708 for pi/2). Judged only when the mechanism gives its bodies' masses.
"""

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism


IMPOSSIBLE_STD = 3.0            # std below zero beyond which a value is impossible, not noise
# SI magnitude of an effect coefficient (value or std) beyond which no joint has it; a kind's own
# where its coefficients can be larger (a prismatic spring's stiffness in N/m)
PHYSICAL_SCALE = 1e6
PHYSICAL_SCALES = {"spring": 1e9}
SCALE_FACTOR = 100.0            # times the mechanism's own mass and size: beyond any load it carries
_PSD_TOLERANCE = 1e-9           # relative: D's eigenvalues this far below 0 are rounding
_KIND_NAMES = {"m": "a mass", "Ixx": "a moment of inertia", "Iyy": "a moment of inertia",
               "Izz": "a moment of inertia"}


@dataclass(frozen=True)
class Flag:
    """One estimate no robot has (``impossible``) or negative within its noise (not)."""
    name: str
    value: float
    std: float
    reason: str
    impossible: bool
    inertial: bool = True            # a base parameter or a body (else an effect's coefficient)
    beyond: float | None = None      # beyond any physical scale: the scale it exceeds (:func:`beyond_scale`)

    @property
    def below(self) -> float:
        """How many std below zero (inf for an exact value)."""
        return -self.value / self.std if self.std > 0 else float("inf")

    def to_json(self) -> dict:
        below = self.below
        return {"name": self.name, "value": float(self.value), "std": float(self.std), "reason": self.reason,
                "std_below_zero": float(below) if np.isfinite(below) else None}

    def text(self) -> str:
        if self.beyond is not None:
            return f"{self.name} = {self.value:.4g} +- {self.std:.2g}: {self.reason}"
        below = self.below
        where = f"{below:.3g} std below 0" if np.isfinite(below) else "an exact value"
        return f"{self.name} = {self.value:.4g} +- {self.std:.2g} ({where}): {self.reason}"



DELAY_LIMIT = 0.1           # s: a longer delay between positions and torques is not plausible
# ----- physical plausibility ---------------------------------------------------------------------
POSITIVE = {"viscous_friction": ("fv",), "coulomb_friction": ("fc",), "stribeck_friction": ("fs",),
            "rotor_inertia": ("Ia",), "spring": ("k",), "load_friction": ("mu",), "mass": ("m",),
            }


def implausible(kind: str, values: dict) -> str:
    """Why an effect's estimated coefficients are not physical ('' when they are): dissipative
    friction, stiffness, rotor inertia, load friction and masses are positive; a load
    friction coefficient is below 1 (it would dissipate more than the load); a delay is
    shorter than DELAY_LIMIT; a torque gain scale is above -1."""
    for name in POSITIVE.get(kind, ()):
        if name in values and values[name] <= 0:
            return f"{name} = {values[name]:.3g} <= 0 (must be positive)"
    if kind == "load_friction" and values.get("mu", 0) >= 1:
        return f"mu = {values['mu']:.3g} >= 1 (more than the load itself)"
    if kind == "delay" and abs(values.get("d", 0)) > DELAY_LIMIT:
        return f"|d| = {abs(values['d']):.3g} s > {DELAY_LIMIT} s"
    if kind == "gain" and values.get("g", 0) <= -1:
        return f"g = {values['g']:.3g} <= -1 (the torque would change sign)"
    return ""


def _flag(name: str, value: float, std: float, reason: str, inertial: bool = True) -> Flag | None:
    if not (np.isfinite(value) and value < 0):
        return None
    std = float(std) if np.isfinite(std) else 0.0
    return Flag(name, float(value), std, reason, impossible=std == 0 or -value > IMPOSSIBLE_STD * std,
                inertial=inertial)


def must_be_positive(kind: str, coefficient: str) -> bool:
    """Whether an effect of ``kind`` has no physical meaning with ``coefficient`` < 0."""
    return coefficient in POSITIVE.get(kind, ()) and bool(implausible(kind, {coefficient: -1.0}))


# ----- the pseudo-inertia's dual ----------------------------------------------------------------
def pseudo_inertia(phi: np.ndarray) -> np.ndarray:
    """:func:`baseparams.identify.physical.pseudo_inertia` (the same formula; that module
    imports cvxpy, which every identify would then pay for)."""
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (float(v) for v in phi)
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    sigma = np.trace(inertia) / 2 * np.eye(3) - inertia
    h = np.array([mx, my, mz])
    return np.block([[sigma, h[:, None]], [h[None, :], np.array([[m]])]])


@functools.lru_cache(maxsize=1)
def _pseudo_inertia_basis() -> np.ndarray:
    """(10, 4, 4): J(e_i) for each of a body's ten parameters (m mx my mz Ixx Ixy Ixz Iyy Iyz Izz);
    once per process, read-only (built anew for each of TIAGo's 723 body rows it was 0.3 s of
    identify, issue 47)."""
    basis = np.array([pseudo_inertia(np.eye(10)[i]) for i in range(10)])
    basis.setflags(write=False)
    return basis


_UPPER = [(i, j) for i in range(4) for j in range(i, 4)]


@functools.lru_cache(maxsize=1)
def _dual_map() -> np.ndarray:
    """L (10 x 10) with L d = coefficients for the upper triangle d of :func:`dual`'s D."""
    L = np.array([[a[i, j] * (1.0 if i == j else 2.0) for i, j in _UPPER] for a in _pseudo_inertia_basis()])
    L.setflags(write=False)
    return L


def dual(coefficients: np.ndarray) -> np.ndarray:
    """The symmetric D with <D, J(phi_b)> = coefficients . phi_b for every phi_b."""
    return _duals(np.asarray(coefficients, float)[None])[0]


def _duals(coefficients: np.ndarray) -> np.ndarray:
    """:func:`dual` of each row of ``coefficients`` (k, 10): (k, 4, 4)."""
    d = np.linalg.solve(_dual_map(), coefficients[:, :, None])[:, :, 0]
    D = np.zeros((len(coefficients), 4, 4))
    for k, (i, j) in enumerate(_UPPER):
        D[:, i, j] = D[:, j, i] = d[:, k]
    return D


def nonnegative_on_bodies(row: np.ndarray) -> bool:
    """Whether ``row . phi >= 0`` for every physically consistent ``phi`` (ten per body).
    Every body the row touches at once (one batched solve and eigenvalue call, each matrix's
    the same as alone: 723 bodies of TIAGo's rows were 0.03 CPU s one by one, issue 47)."""
    row = np.asarray(row, float)
    if not np.any(row) or row.size % 10:
        return False
    scale = float(np.abs(row).max())          # rounding-level terms on another body do not count
    blocks = row.reshape(-1, 10)
    touched = blocks[np.any(blocks, axis=1)]
    if not np.all(np.isfinite(touched)):       # body by body, as always (LAPACK refuses a NaN)
        return all(not np.linalg.eigvalsh(dual(c))[0] < -_PSD_TOLERANCE * scale for c in touched)
    return not np.any(np.linalg.eigvalsh(_duals(touched))[:, 0] < -_PSD_TOLERANCE * scale)


def _what(row: np.ndarray, parameters: Sequence[str]) -> str:
    nonzero = np.flatnonzero(row)
    if len(nonzero) == 1:
        from baseparams.model.params import split_name
        kind = split_name(parameters[nonzero[0]])[0]
        if kind in _KIND_NAMES:
            return f"{_KIND_NAMES[kind]} ({parameters[nonzero[0]]})"
    terms = [f"{'-' if row[i] < 0 else '+'} {'' if row[i] in (1, -1) else f'{abs(row[i]):.4g} '}{parameters[i]}"
             for i in nonzero[:4]]
    text = " ".join(terms).lstrip("+ ") + (" + ..." if len(nonzero) > 4 else "")
    return f"{text} (>= 0 for every physical body)"


# ----- the judgement ----------------------------------------------------------------------------
def judge(*, parameters: Sequence[str], base_map: np.ndarray, names: Sequence[str], values: np.ndarray,
          std: np.ndarray, covariance: np.ndarray | None, effects: Mapping[str, tuple[str, str]],
          absorbed: Mapping[str, Mapping[str, float]], bodies: Mapping[int, str] | None = None) -> list[Flag]:
    """Every estimate no robot has or that is negative within its noise, in ``names``' order
    then the bodies. ``parameters``: the standard parameters (ten per body); ``base_map``
    (r, P): each of the first r ``names``' expression over them; ``effects``: effect
    coefficient name -> (kind, coefficient); ``absorbed``: coefficient name -> {kept name:
    factor} (what each kept estimate also stands for); ``bodies``: label -> name for text."""
    values, std = np.asarray(values, float), np.asarray(std, float)
    r = base_map.shape[0]
    into: dict[str, list[tuple[str, float]]] = {}
    for name, kept in absorbed.items():
        for kept_name, factor in kept.items():
            into.setdefault(kept_name, []).append((name, float(factor)))

    def absorbed_positive(name: str) -> tuple[bool, str]:
        extra = into.get(name, [])
        ok = all(a in effects and must_be_positive(*effects[a]) and f > 0 for a, f in extra)
        return ok, (f" (with {', '.join(a for a, _ in extra)} absorbed, also positive)" if extra else "")

    flags: list[Flag] = []
    for k, name in enumerate(names):
        if k < r:
            row = base_map[k]
            if not nonnegative_on_bodies(row):
                continue
            reason = f"{_what(row, parameters)} cannot be negative"
        elif name in effects:
            kind, coefficient = effects[name]
            if not must_be_positive(kind, coefficient):
                continue
            reason = f"{kind.replace('_', ' ')} must be positive"
            if kind == "stribeck_friction" and "fc" + name[len(coefficient):] in effects:
                reason += " (lower near rest than in motion: the Coulomb friction may be smooth, tanh(qd/vs))"
        else:
            continue
        ok, also = absorbed_positive(name)
        if not ok:
            continue
        flag = _flag(name, float(values[k]), float(std[k]), reason + also, inertial=k < r)
        if flag is not None:
            flags.append(flag)
    if covariance is not None:
        flags += _bodies(parameters, base_map, values[:r], covariance[:r, :r], [n for n in names[:r]
                                                                                 if n not in into], names, bodies)
    return flags


def _bodies(parameters: Sequence[str], base_map: np.ndarray, values: np.ndarray, covariance: np.ndarray,
            clean: Sequence[str], names: Sequence[str], labels: Mapping[int, str] | None) -> list[Flag]:
    """Bodies whose ten parameters the base parameters on that body alone determine."""
    from baseparams.model.params import split_name
    out = []
    basis = _pseudo_inertia_basis()
    r, P = base_map.shape
    bodies = P // 10
    # which bodies each base row involves (r, bodies); a row on one body alone, of a clean name
    involved = (base_map[:, :10 * bodies] != 0).reshape(r, bodies, 10).any(axis=2)
    alone = (involved.sum(axis=1) == 1) & ~(base_map[:, 10 * bodies:] != 0).any(axis=1)
    kept = set(clean)
    alone &= np.array([names[k] in kept for k in range(r)], dtype=bool)
    for b in range(bodies):
        rows = [int(k) for k in np.nonzero(alone & involved[:, b])[0]]
        if len(rows) < 10:
            continue
        E = base_map[np.ix_(rows, range(10 * b, 10 * b + 10))]
        if np.linalg.matrix_rank(E) < 10:
            continue
        G = np.linalg.pinv(E)
        phi = G @ values[rows]
        C = G @ covariance[np.ix_(rows, rows)] @ G.T
        if not np.all(np.isfinite(C)):
            continue
        eigenvalues, vectors = np.linalg.eigh(pseudo_inertia(phi))
        v = vectors[:, 0]
        gradient = np.array([v @ a @ v for a in basis])
        sd = float(np.sqrt(max(gradient @ C @ gradient, 0.0)))
        key = split_name(parameters[10 * b])[1]       # a label, or a named body's name (issue 45)
        who = f"body {key}" + (f" ({labels[key]})" if isinstance(key, int) and labels and labels.get(key) else "")
        flag = _flag(who, float(eigenvalues[0]), sd,
                     "its ten identified parameters are not a mass distribution (the pseudo-inertia's "
                     "smallest eigenvalue is negative: a negative mass, or an inertia that is not positive "
                     "definite or breaks the triangle inequality)")
        if flag is not None:
            out.append(flag)
    return out


def split(flags: Sequence[Flag]) -> tuple[list[Flag], list[Flag]]:
    """(impossible, negative within the noise: consistent with zero); flags beyond any
    physical scale are in neither (:func:`beyond`)."""
    return ([f for f in flags if f.impossible and f.beyond is None],
            [f for f in flags if not f.impossible and f.beyond is None])


def beyond(flags: Sequence[Flag]) -> list[Flag]:
    """The flags of estimates beyond any physical scale."""
    return [f for f in flags if f.beyond is not None]


def beyond_scale(names: Sequence[str], values: np.ndarray, std: np.ndarray,
                 effects: Mapping[str, tuple[str, str]]) -> list[Flag]:
    """Effect coefficients (``effects``: name -> (kind, coefficient)) whose value or standard
    deviation is above their kind's physical scale (:data:`PHYSICAL_SCALE`), or not finite."""
    out = []
    for k, name in enumerate(names):
        if name not in effects:
            continue
        kind, _ = effects[name]
        scale = PHYSICAL_SCALES.get(kind, PHYSICAL_SCALE)
        value, sd = float(values[k]), float(std[k])
        if np.isfinite(value) and np.isfinite(sd) and abs(value) <= scale and sd <= scale:
            continue
        what = "its value" if not np.isfinite(value) or abs(value) > scale else "its standard deviation"
        out.append(Flag(name, value, sd, f"beyond any physical scale ({what} above {scale:.0e} in SI units): the "
                        "data do not determine it (a joint that barely moves, an unfiltered ramp) or are read "
                        "wrong (a time column of sample indices read as seconds)", impossible=False,
                        inertial=False, beyond=scale))
    return out


def advice(flags: Sequence[Flag]) -> list[str]:
    """What to do about the impossible ones among ``flags``."""
    impossible = [f for f in flags if f.impossible]
    out = []
    if any(f.inertial for f in impossible):
        out.append("`identify --physical` fits standard parameters whose bodies are mass distributions (needs "
                   "cvxpy), as near the base estimates as they allow")
    if any(not f.inertial for f in impossible):
        out.append("--physical does not constrain effect coefficients: a negative friction or rotor inertia "
                   "stands for something the model lacks or shapes otherwise (`diagnose` names it: a delay, a "
                   "smooth Coulomb law), or for a coefficient the motion barely excites")
    return out


def body_scales(parameters: Sequence[str], masses: Sequence[float], lengths: Sequence[float]) -> np.ndarray | None:
    """Each standard parameter's physical scale S_i (:data:`SCALE_FACTOR` times the bodies'
    total mass M, times the reach L for a first moment, L^2 for an inertia), from the
    bodies' ``masses`` and the ``lengths`` of the joints' frames; None when M is not
    positive (a mechanism without masses: nothing to scale by)."""
    from baseparams.model.params import split_name
    total = float(np.sum(masses))
    if not np.isfinite(total) or total <= 0:
        return None
    reach = max(float(np.sum(lengths)), 1.0)
    powers = {"m": 0, "mx": 1, "my": 1, "mz": 1}
    return np.array([SCALE_FACTOR * total * reach ** powers.get(split_name(p)[0], 2) for p in parameters])


def beyond_body_scale(base_names: Sequence[str], base_map: np.ndarray, names: Sequence[str], values: np.ndarray,
                      std: np.ndarray, scales: np.ndarray | None) -> list[Flag]:
    """Base parameters (``base_names``, their rows of ``base_map`` over the standard
    parameters) among ``names`` whose value or std exceeds ``sum |c_i| S_i`` (``scales``:
    :func:`body_scales`); none when ``scales`` is None."""
    if scales is None:
        return []
    out = []
    rows = {name: k for k, name in enumerate(base_names)}
    for k, name in enumerate(names):
        if name not in rows:
            continue
        bound = float(np.abs(base_map[rows[name]]) @ scales)
        value, sd = float(values[k]), float(std[k])
        if np.isfinite(value) and np.isfinite(sd) and abs(value) <= bound and sd <= bound:
            continue
        what = "its value" if not np.isfinite(value) or abs(value) > bound else "its standard deviation"
        out.append(Flag(name, value, sd, f"beyond any physical scale of this mechanism ({what} above {bound:.2g} "
                        f"in SI units, {SCALE_FACTOR:g} times what its bodies' total mass and reach allow): the "
                        "data do not determine it (a direction seen only through an axis a few microradians off a "
                        "symmetry, a joint that barely moves) or are read wrong", impossible=False,
                        inertial=True, beyond=bound))
    return out


def mechanism_size(mechanism: "Mechanism") -> tuple[list[float], list[float]] | None:
    """(its bodies' masses as given, the lengths of its joints' frames); None when a body's
    inertia or a frame's position is not a number (nothing to scale by)."""
    inertias = [b.inertia for b in mechanism.bodies]
    if any(inertia is None for inertia in inertias):
        return None
    try:
        masses = [float(inertia[0]) for inertia in inertias if inertia is not None]
        lengths = [float(np.linalg.norm([float(c) for c in frame.point])) for joint in mechanism.joints
                   for frame in (joint.parent_frame, joint.child_frame)]
    except (TypeError, ValueError):
        return None
    return masses, lengths


def mechanism_scales(mechanism: "Mechanism", parameters: Sequence[str]) -> np.ndarray | None:
    """:func:`body_scales` of ``mechanism`` (:func:`mechanism_size`) for its standard
    ``parameters``; None when it gives no masses."""
    size = mechanism_size(mechanism)
    return None if size is None else body_scales(parameters, *size)


def body_limits(mechanism: "Mechanism") -> dict[str, float]:
    """Each body coefficient's physical scale (name -> :func:`body_scales`); {}
    when the mechanism gives no masses."""
    size = mechanism_size(mechanism)
    names = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")
    scales = None if size is None else body_scales([f"{n}_body" for n in names], *size)
    return {} if scales is None else dict(zip(names, (float(v) for v in scales)))
