"""Diagnosis candidates that are not registered effects: they are built from the model's own
predicted torque or from the bodies' inertial columns, so they exist only inside a diagnosis.

- ``load_friction:COORD``: |tau| sign(qd) on a coordinate (gear friction growing with the
  transmitted load), tau the model's predicted torque there.
- ``delay:all``: one time delay d between the measured positions and the torques (a filter's
  or a bus's lag): tau_measured(t) = tau(t - d) = tau(t) - d dtau/dt to first order, so the
  column is -dtau/dt and the coefficient is d in seconds (fractional samples).
- With ``--params`` (the simulation held as given): ``gain:COORD`` (the torque on a
  coordinate scaled by 1 + g: a current-to-torque constant off), and a payload or a changed
  body: ``mass:BODY`` (a point mass at the body's frame origin: one column, exact) and
  ``body:BODY`` (all ten parameters: a rigid payload anywhere on it, or the body itself
  changed). The first is the second's special case; selection names the simpler one when
  the data cannot tell them apart (``generalises``). Between them ``payload:BODY``: a
  compact load near the origin, its mass and first moments (four columns, m and m c: "0.097
  kg at (x, y, z) m"). A point mass at an unknown position is not linear in its position:
  its inertia about the origin, m (|c|^2 1 - c c^T), is left out; where the data see it, the
  rigid body (which generalises the payload) is named instead. Why: a 94 g load 3-5 cm off a
  UR5's wrist_3 origin was named as a mass at the origin 11-25 % heavy (the mass took the
  first moments' force); as a payload, 2-4 % off.
"""

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import bilinear, butter, lfilter, sosfiltfilt

from baseparams.diagnose.selection import Candidate
from baseparams.model.mechanism import Mechanism

TORQUE_KINDS = ("load_friction", "delay")
GIVEN_KINDS = ("gain", "mass", "payload", "body")
KINDS = TORQUE_KINDS + GIVEN_KINDS
COEFFICIENTS = {"load_friction": ("mu",), "delay": ("d",), "gain": ("g",), "mass": ("m",),
                "payload": ("m", "mx", "my", "mz"),
                "body": ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")}
BODY_PARTS = {"mass": slice(0, 1), "payload": slice(0, 4), "body": slice(0, 10)}
GENERALISES = {"payload": ("mass",), "body": ("mass", "payload")}
# The body kinds a diagnosis between recordings offers by default (``--baseline``: its rates were
# measured with these two, and a payload there is named as a body); --params offers all three.
CHANGE_BODY_KINDS = ("mass", "body")


def body_name(mechanism: Mechanism, label: int) -> str:
    body = mechanism.body(label)
    return body.name or f"body{label}"


def body_columns(mechanism: Mechanism, name: str) -> slice:
    """Where the body a mass/body candidate names (:func:`body_name`) has its ten standard
    parameters."""
    k = next(k for k, b in enumerate(mechanism.bodies) if body_name(mechanism, b.label) == name)
    return slice(10 * k, 10 * k + 10)


# Where a bare KIND (and the default selection) puts a derived kind, when not everywhere it may
# act: one drive's own delay (delay:COORD) is a candidate only when named. Why: an elastic
# joint's lag is, to first order, a delay on that joint; with every joint's delay a candidate,
# it was named for one in 15 % of such datasets (35 % without the second-order check).
DEFAULT_PLACES = {"delay": ("all",)}


def places(mechanism: Mechanism, kind: str, coordinates: tuple[str, ...]) -> tuple[str, ...]:
    """Where a derived kind acts: the independent coordinates, the bodies, or 'all'."""
    if kind == "delay":              # one for the recording, or one drive's own (several coordinates)
        return ("all",) + (coordinates if len(coordinates) > 1 else ())
    if kind in BODY_PARTS:
        return tuple(body_name(mechanism, b.label) for b in mechanism.bodies)
    return coordinates


def default_places(mechanism: Mechanism, kind: str, coordinates: tuple[str, ...]) -> tuple[str, ...]:
    """Where a bare KIND puts a derived kind: :data:`DEFAULT_PLACES`, else every place, less
    the bodies that are another's candidate under a second name (:func:`welded_duplicates`;
    name them with KIND:BODY to test them anyway)."""
    if kind in DEFAULT_PLACES:
        return DEFAULT_PLACES[kind]
    twins = welded_duplicates(mechanism, kind)
    return tuple(p for p in places(mechanism, kind, coordinates) if p not in twins)


def welded(mechanism: Mechanism) -> dict[int, int]:
    """Each body's rigid body: the bodies joined by joints without coordinates (a URDF's fixed
    joints to a flange, a tool or sensor frame) move as one, and each maps to the one of its
    group placed first from the ground (the tree's order), the link the group's moving joint
    carries."""
    parent = {0: 0} | {b.label: b.label for b in mechanism.bodies}        # ground is body 0

    def root(label: int) -> int:
        while parent[label] != label:
            label = parent[label]
        return label

    placed = [0] + [edge.new for edge in mechanism.tree]
    rank = {b: placed.index(b) if b in placed else len(placed) for b in parent}
    for joint in mechanism.joints:
        if not joint.coordinates:
            a, b = root(joint.parent), root(joint.child)
            if a != b:
                first, second = (a, b) if rank[a] <= rank[b] else (b, a)
                parent[second] = first
    return {b: root(b) for b in parent}


# Two frame origins closer than this (m) are one point: URDF angles written to five or six
# digits (so100's 1.57079 for pi/2) move a frame 0.1 m away by up to 1e-6 m.
SAME_POINT = 1e-6


def welded_duplicates(mechanism: Mechanism, kind: str) -> dict[str, str]:
    """The bodies whose ``kind`` candidate is another's under a second name -> that other:
    for ``body`` and ``payload`` every body welded to another (their ten, or four, parameters
    span the same forces: one rigid body's, in another frame); for ``mass`` a welded body whose frame origin is
    that of a body of its group before it (a point mass at the same point). Why: a UR10's
    payload was reported as ambiguous between its last link and the tool0 and ee_link frames
    fixed to it (|corr| 1.000), with advice to move through a wider range, which cannot
    separate them."""
    if kind not in BODY_PARTS:
        return {}
    group = welded(mechanism)
    origins = _welded_origins(mechanism, group) if kind == "mass" else {}
    out: dict[str, str] = {}
    kept: dict[int, list[int]] = {}
    for label in sorted(group, key=lambda b: b != group[b]):          # each group's first body first
        representative = group[label]
        if label == 0:
            kept.setdefault(0, []).append(0)
            continue
        twin: int | None = None
        if kind in ("body", "payload") and label != representative:
            twin = representative
        elif kind == "mass":
            twin = next((k for k in kept.get(representative, [])
                         if np.max(np.abs(origins[k] - origins[label])) <= SAME_POINT), None)
            if twin is None:
                kept.setdefault(representative, []).append(label)
        if twin is not None:
            out[body_name(mechanism, label)] = "ground" if twin == 0 else body_name(mechanism, twin)
    return out


def _welded_origins(mechanism: Mechanism, group: dict[int, int]) -> dict[int, np.ndarray]:
    """Each body's frame origin in its rigid body's axes (:func:`welded`), through the fixed
    joints' frames (floats: only compared with each other)."""
    from baseparams.numeric.backends import Float64
    backend = Float64()
    pose = {b: (np.eye(3), np.zeros(3)) for b in group if group[b] == b}     # body axes -> group axes
    fixed = [j for j in mechanism.joints if not j.coordinates]
    while len(pose) < len(group):
        grown = False
        for joint in fixed:
            for known, new in ((joint.parent, joint.child), (joint.child, joint.parent)):
                if known in pose and new not in pose:
                    r_k, p_k = (np.array(x, float) for x in mechanism.numeric_frame(
                        joint.parent_frame if known == joint.parent else joint.child_frame, backend))
                    r_n, p_n = (np.array(x, float) for x in mechanism.numeric_frame(
                        joint.child_frame if known == joint.parent else joint.parent_frame, backend))
                    rotation = r_k @ r_n.T                    # new's axes -> known's (the frames coincide)
                    origin = p_k - rotation @ p_n
                    r, p = pose[known]
                    pose[new] = (r @ rotation, p + r @ origin)
                    grown = True
        if not grown:
            break
    return {b: pose[b][1] if b in pose else np.full(3, np.nan) for b in group}


def torque_candidates(coordinates: tuple[str, ...], t: np.ndarray, qd: np.ndarray, torque: np.ndarray,
                      wanted: set | None = None,
                      delay: Sequence[tuple[dict, np.ndarray]] | None = None) -> list[Candidate]:
    """load_friction on each coordinate and one delay, from the model's ``torque`` (n, f; fitted
    with the load friction: :func:`fitted_torque`) and the independent speeds ``qd`` (n, f);
    ``wanted``: (kind, place) pairs to keep (None: all). ``delay``: the delay's column at each
    low-pass (shape, columns (n, f, 1); :func:`delay_column`), variants of one candidate;
    default -dtorque/dt."""
    n, f = torque.shape
    out = []
    load = load_columns(torque, qd)
    for j, c in enumerate(coordinates):
        if wanted is None or ("load_friction", c) in wanted:
            out.append(Candidate("load_friction", c, (f"mu_{c}",), np.ascontiguousarray(load[:, :, j:j + 1])))
    if (wanted is None or any(kind == "delay" for kind, _ in wanted)) and n > 2:
        forms = list(delay) if delay else [({}, -np.gradient(torque, t, axis=0)[:, :, None])]

        def candidate(place: str, name: str, keep: Callable[[np.ndarray], np.ndarray]) -> Candidate:
            shapes, columns = tuple(shape for shape, _ in forms), tuple(keep(c) for _, c in forms)
            if len(forms) == 1:
                return Candidate("delay", place, (name,), columns[0], shape=dict(shapes[0]))
            return Candidate("delay", place, (name,), columns[0], columns, shapes, dict(shapes[0]))

        if wanted is None or ("delay", "all") in wanted:
            out.append(candidate("all", "d", lambda column: column))
        for j, c in enumerate(coordinates):      # one drive's own lag, when asked for (DEFAULT_PLACES)
            if f > 1 and wanted is not None and ("delay", c) in wanted:
                def own(column: np.ndarray, j: int = j) -> np.ndarray:
                    on_j = np.zeros_like(column)
                    on_j[:, j] = column[:, j]
                    return on_j
                out.append(candidate(c, f"d_{c}", own))
    return out


# Rounds of the alternating fit of the model with the effects built from its torque, and the
# change in the torque (in units of its RMS) at which it stops.
FIT_ROUNDS = 20
FIT_TOLERANCE = 1e-4
# The delay's column is the derivative of the model's torque low-passed at this multiple of the
# speeds' bandwidth (Gautier's rule for positions, as a recording's filter: recording.py) ...
DELAY_CUTOFF_PER_BANDWIDTH = 10.0
# ... or at these, a shape of the delay chosen by the data (variable projection over the grid,
# one more degree of freedom in its tests). Why: after whitening coloured noise (AR(1) 0.9) the
# fast part of the derivative is what tells a delay from viscous friction on a one-coordinate
# four-bar (on one dataset the delay added over viscous friction at p 0.03 with the column at
# 10 times, 6e-4 at 20 times; viscous friction was named for the delay in 2 of 20 such
# datasets, 1 of 20 with the grid). The data chose 20 or 40 times on most datasets, white
# noise too, and the fitted delay stayed within 1 % (white) and 5 % (AR) of the truth as before.
DELAY_CUTOFFS_PER_BANDWIDTH = (DELAY_CUTOFF_PER_BANDWIDTH, 20.0, 40.0)


def rate(torque: np.ndarray, t: np.ndarray, cutoff: float | None) -> np.ndarray:
    """d torque / dt (n, f), the torque first low-passed at ``cutoff`` Hz (zero-phase
    Butterworth, order 4) when that is below the Nyquist frequency."""
    step = float(np.median(np.diff(t)))
    if cutoff is not None and 0 < cutoff < 0.5 / step and len(t) > 27:
        torque = sosfiltfilt(butter(4, cutoff, fs=1 / step, output="sos"), torque, axis=0)
    return np.gradient(torque, t, axis=0)


def fitted_torque(model: np.ndarray, y: np.ndarray, rows: slice, known: np.ndarray, torque: np.ndarray,
                  fit: Callable[[np.ndarray], np.ndarray],
                  columns_of: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The model's torque (``known`` + model @ coefficients, every row) fitted together with the
    effects built from it (``columns_of(torque)``: (n, f, k)), by alternating least squares
    from ``torque`` (the model fitted alone; ``fit(extra)`` gives the coefficients of the
    model's columns and ``extra``'s, fitted to ``y`` on the training ``rows``). Why: the model fitted alone bends towards what it misses, and an
    effect built from that torque is built from a wrong one: on a generated four-bar (one
    coordinate, 21 identifiable parameters) a delay was named viscous friction in half the
    datasets, and load friction Coulomb or position friction in 11 of 20. With none of the
    effects in the data the rounds stop at once."""
    scale = max(float(np.sqrt(np.mean(torque[rows] ** 2))), 1e-300)
    p = model.shape[-1]
    for _ in range(FIT_ROUNDS):
        coefficients = fit(columns_of(torque)[rows])
        new = known + model @ coefficients[:p]
        change = float(np.sqrt(np.mean((new[rows] - torque[rows]) ** 2))) / scale
        torque = new
        if change <= FIT_TOLERANCE:
            break
    return torque


def load_columns(torque: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Every coordinate's load friction |tau_j| sign(qd_j) (n, f, f), each on its own coordinate."""
    n, f = torque.shape
    out = np.zeros((n, f, f))
    out[:, np.arange(f), np.arange(f)] = np.abs(torque) * np.sign(qd)
    return out


# A resonant lag that a named delay must outdo (diagnose._resonant_rival): damping ratios and
# natural frequencies (multiples of the speeds' bandwidth) of the grid. Why this range: an
# elastic joint resonating 1.5-3 times above the motion's band lags it like a delay of
# 2 zeta / w; resonances above 4 times the band lag like a delay within it (the vocabulary's
# "delay or phase lag"), and above zeta 0.35 there is no resonance to tell.
RESONANT_DAMPING = (0.1, 0.2, 0.35)
RESONANT_FREQUENCIES = tuple(np.geomspace(1.0, 4.0, 17))


@dataclass(frozen=True)
class LagEvidence:
    """What tells a delay from other lags: the model's torque fitted together with the delay
    (n, f), its second-order term -d2tau/dt2 (n, f), the sample step (s) and the speeds'
    bandwidth (Hz; 0 when unknown)."""
    torque: np.ndarray
    curvature: np.ndarray
    step: float
    band: float

    def rows(self, index: slice) -> "LagEvidence":
        return LagEvidence(self.torque[index], self.curvature[index], self.step, self.band)

    def resonant(self, acts: np.ndarray) -> Iterator[tuple[float, float, np.ndarray]]:
        """(zeta, w in rad/s, columns (n, f, 1)) over the grid: the torque on the coordinates
        ``acts`` (f,) through a second-order low-pass w^2 / (s^2 + 2 zeta w s + w^2)
        (bilinear, from the first sample at rest), minus the torque: what an elastic
        transmission or a resonant filter adds, up to its coefficient."""
        if self.band <= 0:
            return
        for zeta in RESONANT_DAMPING:
            for multiple in RESONANT_FREQUENCIES:
                w = 2 * np.pi * self.band * multiple
                if w >= np.pi / self.step:              # at or above the Nyquist frequency
                    continue
                b, a = bilinear([w ** 2], [1.0, 2 * zeta * w, w ** 2], fs=1.0 / self.step)
                columns = np.zeros(self.torque.shape + (1,))
                start = self.torque[0, acts]
                columns[:, acts, 0] = lfilter(b, a, self.torque[:, acts] - start, axis=0) + start - self.torque[:, acts]
                yield zeta, w, columns


def delay_column(model: np.ndarray, y: np.ndarray, rows: slice, known: np.ndarray, t: np.ndarray,
                 torque: np.ndarray, fit: Callable[[np.ndarray], np.ndarray],
                 cutoff: float | None, band: float = 0.0) -> tuple[np.ndarray, LagEvidence]:
    """The delay's column (n, f, 1) -dtau/dt, tau the model's torque fitted together with the
    delay (y = tau - d dtau/dt; :func:`fitted_torque`), differentiated after a low-pass at
    ``cutoff``; and the evidence that tells a delay from an elastic lag (``diagnose``), with
    the speeds' bandwidth ``band``. Why the low-pass: the fitted noise lies partly in fast
    directions of the model's span, whose derivative is large: on a generated four-bar the
    column differed from the true -dtau/dt by 24-51 % when taken from the model fitted alone
    and differentiated as it was, 3-8 % after both."""
    torque = fitted_torque(model, y, rows, known, torque, fit, lambda tau: -rate(tau, t, cutoff)[:, :, None])
    first = rate(torque, t, cutoff)
    step = float(np.median(np.diff(t)))
    return -first[:, :, None], LagEvidence(torque, -np.gradient(first, t, axis=0), step, band)


# A body's column this many times smaller than its largest is rounding of a structural zero.
ROUNDING = 1e-10


def _without_rounding(block: np.ndarray) -> np.ndarray:
    """A body's columns (n, f, 10) with those at rounding level set to zero. Why: the TX40's
    second link's mz moves no joint (its column's norm 5e-16 against 1e2 for the others),
    and a changed body was named with mz = -4.8e15 +- 4.6e15."""
    norms = np.sqrt(np.sum(block ** 2, axis=(0, 1)))
    dead = norms <= ROUNDING * norms.max()
    if not dead.any():
        return block
    out = block.copy()
    out[:, :, dead] = 0.0
    return out


def given_candidates(mechanism: Mechanism, coordinates: tuple[str, ...], torque: np.ndarray,
                     inertial: np.ndarray, wanted: set | None = None,
                     kinds: Sequence[str] = CHANGE_BODY_KINDS, shape: dict | None = None) -> list[Candidate]:
    """gain per coordinate (columns: the given torque) and the body ``kinds`` per body (their
    columns of the inertial regressor ``inertial`` (n, f, 10 bodies), taken at ``shape``: a
    lag, for the report); by default (``wanted`` None) not a candidate a welded body repeats
    (:func:`welded_duplicates`), and no payload where a mass at the frame's origin moves nothing
    (a rocker pivoting about its own origin): there a load shows only through its first moments
    and its inertia about the origin, which a payload leaves out and takes into its first
    moments (a 1.5 kg load on a generated four-bar's rocker, named as a payload, had mx 9
    standard deviations off); the body's identifiable combinations are not biased."""
    n, f = torque.shape
    out = []
    for j, c in enumerate(coordinates):
        if wanted is None or ("gain", c) in wanted:
            columns = np.zeros((n, f, 1))
            columns[:, j, 0] = torque[:, j]
            out.append(Candidate("gain", c, (f"g_{c}",), columns))
    twins = {kind: welded_duplicates(mechanism, kind) for kind in BODY_PARTS} if wanted is None else {}
    for k, body in enumerate(mechanism.bodies):
        name = body_name(mechanism, body.label)
        block = inertial[:, :, 10 * k: 10 * k + 10]
        if not np.any(block):
            continue                                   # the ground, or a body nothing moves
        block = _without_rounding(block)
        for kind, part in BODY_PARTS.items():
            if kind == "payload" and wanted is None and not np.any(block[:, :, 0]):
                continue                # a mass at its origin moves nothing: the body alone
            if (kind, name) in wanted if wanted is not None else kind in kinds and name not in twins[kind]:
                out.append(Candidate(kind, name, tuple(f"{p}_{name}" for p in COEFFICIENTS[kind]),
                                     np.ascontiguousarray(block[:, :, part]), shape=dict(shape or {}),
                                     generalises=GENERALISES.get(kind, ())))
    return out
