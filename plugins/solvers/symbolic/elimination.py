"""Symbolic base parameters by multipole transfers (Ros et al. 2012), automated.

The seed paper applies the method by hand to the SLA suspension (its section 3, Tabs. 4-5
and appendix). Here it runs on any mechanism:

1. *Generators* (exact null vectors n of the observation matrix, W n = 0, entries in the
   geometry symbols): per body, the directions without effect found from its motion
   (:mod:`baseparams.plugins.solvers.symbolic.body_conditions`, the paper's conditions 1-6 of section 3.2); per
   joint, every multipole-transfer rule its joint type declares (:mod:`baseparams.dynamics.transfers`).
2. *Elimination*: the generators are taken one at a time in a documented order; each is
   reduced by the earlier ones (exact arithmetic in the field of rational functions of the
   geometry symbols) and, if something is left, one of its parameters (its *pivot*) is
   eliminated: the transferred multipole is chosen so that this parameter becomes zero, as
   in the paper. A generator with nothing left is redundant (another rule already gave it).
3. *Base parameters*: applying the transfers in that order leaves every kept parameter
   as ``phi_k + sum beta_ke phi_e``; the coefficients come out as simplified expressions in
   the geometry symbols and as exact rationals for the mechanism's geometry.
4. *The count is checked, not assumed* (:func:`certify`), on W computed in ball
   arithmetic at D digits on N states: ``baseparams.numeric.certify.analyse`` proves rank >= the
   number of kept columns (they are shown independent); every generator n, evaluated in
   balls at the geometry, gives W n whose entries all contain 0. The latter is evidence,
   not proof, that rank <= 70 - (pivots) (a proof would need the generators verified
   symbolically). Only when the bound and the count meet, with every generator tested, is
   the result ``certified``.

Default order of generators and pivots (reproduces the paper's choice on the SLA):

- body conditions first (quadrupoles, dipoles, a monopole at the body origin), each
  eliminating the parameter it acts on (Tab. 4);
- then transfers, joints whose donor is farthest from the *root* first. The root is the
  moving body with the most joints (ties: lowest label); distances count joints from
  ground or the root. Across a joint the donor is the body farther from them (ties: the
  higher label): masses move toward the root (the hub of the SLA), inertia toward ground.
  Pivots: a monopole between moving bodies removes the donor's mass; a monopole at a
  ground joint removes the first diagonal inertia entry (Ixx, Iyy, Izz) it changes (the
  mass is kept for its transfer toward the root: the paper's Iyy1, Iyy2, Iyy4); a dipole
  removes the donor's first moment along its direction; an axisymmetric quadrupole the
  last diagonal entry of the donor it touches (the paper's Izz5); "any quadrupole" the
  donor's matching entry;
- then the planar-loop generators (condition 7, :mod:`.loop_transfers`: one per cycle of
  parallel R joints off ground), each removing a product of inertia of the closing joint's
  donor;
- then the remaining body conditions (monopoles at other points at rest), usually redundant.

``keep=[...]`` never eliminates the named parameters when another choice exists;
``eliminate_first=[...]`` eliminates the named parameters whenever a generator allows it.
"""

import functools
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, cast

import numpy as np
import sympy
from flint import arb, arb_mat, fmpq
from sympy import QQ

from baseparams import registry
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import Subset, observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.transfers import Generator, transfer_generators
from baseparams.errors import InputError, KinematicsError
from baseparams.model.mechanism import Joint, Mechanism
from baseparams.model.params import PARAMETER_KINDS, parameter_name
from baseparams.numeric.backends import Arb, Float64
from baseparams.numeric.certify import analyse
from baseparams.solvers.result import BaseParameterResult, Coefficient, Diagnostics, parse_coefficient

from .body_conditions import BodyMotion, analyse_bodies
from .loop_transfers import CONDITION as LOOP_CONDITION, planar_loop_generators
from .rank_bound import choose_rows, columns_independent
from .sampled_transfers import sampled_joint_transfers

DIAGONAL = ("Ixx", "Iyy", "Izz")
FIRST_MOMENTS = ("mx", "my", "mz")


# ----- exact field ------------------------------------------------------------------------
class ExactField:
    """Rational functions of the geometry symbols (sympy's sparse polys), with the mechanism's
    exact geometry for evaluation. Square roots left by non-unit axes become extra symbols
    (their squares are not reduced, so zero tests are always made at the actual geometry).

    A mechanism whose generators use no geometry symbol and no radical (no ``[geometry]``,
    numbers written inline) still gets a one-generator field: a placeholder symbol that
    occurs in no expression (sympy's zero-generator fields cannot evaluate elements). It is
    a :class:`sympy.Dummy`, as are the radicals, so no geometry name can clash with them.

    When every generator entry is a rational number (no symbol, no radical: generated
    mechanisms, numbers written inline) the field is *constant*: its elements are
    python-flint ``fmpq`` rationals rather than sympy fractions of the placeholder, the same
    values with the same printed forms, and arithmetic in C instead of a polynomial gcd per
    operation (most of the elimination's time on a 48-body chain went to sympy's ``cancel``)."""

    def __init__(self, mechanism: Mechanism, expressions: Iterable[Any], rationals: bool = True):
        """``rationals=False`` keeps sympy's field even when it could be constant (the
        reference the constant path is tested against)."""
        self.mechanism = mechanism
        self.radicals: dict[Any, sympy.Dummy] = {}          # sympy Pow (b**(1/q)) -> Dummy
        atoms: set[Any] = set()
        converted = [self._replace(sympy.sympify(e)) for e in expressions]
        self.constant = rationals and all(e.is_Rational for e in converted)
        self.values = mechanism.geometry_subs
        self.exact = True
        if self.constant:
            self.symbols: list[Any] = []
            self.K: Any = None
            self.pairs: list[Any] = []
            self.one: Any = fmpq(1)
            return
        for e in converted:
            atoms |= e.free_symbols
        names = sorted(mechanism.geometry)
        symbols = [sympy.Symbol(n) for n in names if sympy.Symbol(n) in atoms]
        symbols += sorted(set(self.radicals.values()), key=lambda s: s.name)
        if not symbols:
            symbols = [sympy.Dummy("unit")]
        self.symbols = symbols
        self.K = QQ.frac_field(*symbols)
        self.one = self.K.one
        ring = self.K.field.ring
        values = self.values
        radical_of = {sym: root for root, sym in self.radicals.items()}
        pairs = []
        for gen, sym in zip(ring.gens, symbols):
            if sym in values:
                v = values[sym]
            elif sym in radical_of:
                v = sympy.simplify(radical_of[sym].subs(values))
                if not v.is_Rational:
                    self.exact = False
                    v = sympy.Rational(0)
            else:                   # the placeholder: occurs nowhere, any value will do
                v = sympy.Rational(0)
            pairs.append((gen, QQ(v.p, v.q)))
        self.pairs = pairs
        self.points = [Fraction(int(v.numerator), int(v.denominator)) for _, v in pairs]

    def _replace(self, e: Any) -> Any:
        def repl(p: Any) -> Any:
            b, x = p.as_base_exp()
            if x.is_Rational and not x.is_Integer:
                root = b ** sympy.Rational(1, x.q)
                if root not in self.radicals:
                    self.radicals[root] = sympy.Dummy(f"r{len(self.radicals)}")
                return self.radicals[root] ** x.p
            return p
        return e.replace(lambda p: p.is_Pow, repl) if e.has(sympy.Pow) else e

    def convert(self, expr: Any) -> Any:
        expr = sympy.sympify(expr)
        if self.constant:
            if not expr.is_Rational:
                raise ValueError(f"{expr} is not a rational number (the field is constant)")
            return fmpq(int(expr.p), int(expr.q))
        return self.K.from_sympy(self._replace(expr))

    def to_sympy(self, elem: Any) -> Any:
        if self.constant:
            return sympy.Rational(int(elem.p), int(elem.q))
        expr = self.K.to_sympy(elem)
        if self.radicals:
            expr = expr.subs({v: k for k, v in self.radicals.items()})
        return expr

    def value(self, elem: Any) -> Fraction | Any:
        """Exact value at the mechanism's geometry: Fraction (or sympy number with radicals)."""
        if self.constant:
            return Fraction(int(elem.p), int(elem.q))
        if self.exact:
            return self._at_geometry(elem.numer) / self._at_geometry(elem.denom)
        return sympy.simplify(self.to_sympy(elem).subs(self.values))

    def _at_geometry(self, poly: Any) -> Fraction:
        """A polynomial of the field's ring at the geometry, exactly (a Fraction): term by term
        over its monomials (sympy's ``evaluate`` builds a ring per variable: 40 times slower)."""
        total = Fraction(0)
        for monomial, c in poly.items():
            term = Fraction(int(c.numerator), int(c.denominator))
            for x, k in zip(self.points, monomial):
                if k:
                    term *= x ** k
            total += term
        return total

    def nonzero_at_geometry(self, elem: Any) -> bool:
        return bool(elem) and self.value(elem) != 0


# ----- the mechanism's graph: root, distances, donors -------------------------------------
def body_distances(mechanism: Mechanism) -> tuple[int | None, dict[int, int]]:
    """(root, {body: distance}) with distances counted in joints from ground or the root."""
    degree = {b: 0 for b in mechanism.body_labels}
    neighbours: dict[int, set[int]] = {0: set(), **{b: set() for b in mechanism.body_labels}}
    for j in mechanism.joints:
        for b in (j.parent, j.child):
            if b != 0:
                degree[b] += 1
        neighbours[j.parent].add(j.child)
        neighbours[j.child].add(j.parent)
    root = min(mechanism.body_labels, key=lambda b: (-degree[b], b)) if degree else None
    dist = {0: 0}
    if root is not None:
        dist[root] = 0
    frontier = list(dist)
    while frontier:
        nxt = []
        for b in frontier:
            for n in neighbours[b]:
                if n not in dist:
                    dist[n] = dist[b] + 1
                    nxt.append(n)
        frontier = nxt
    for b in mechanism.body_labels:
        dist.setdefault(b, len(mechanism.body_labels) + 1)
    return root, dist


def donor_acceptor(joint: Joint, dist: dict[int, int]) -> tuple[int, int]:
    a, b = joint.parent, joint.child
    if a == 0 or b == 0:
        return 0, (b if a == 0 else a)            # ground gives: the body is the acceptor
    if (dist[a], a) > (dist[b], b):
        return a, b
    return b, a


# ----- pivot preferences ------------------------------------------------------------------
def _largest_component(direction: Sequence[Any], field: ExactField) -> int:
    values = [abs(float(sympy.N(sympy.sympify(c).subs(field.values)))) for c in direction]
    return max(range(3), key=lambda k: (round(values[k], 12), -k))


def transfer_preference(gen: Generator, mechanism: Mechanism, field: ExactField) -> list[str]:
    """Parameters a transfer generator should eliminate, most wanted first (see module doc)."""
    body = gen.acceptor if gen.donor == 0 else gen.donor
    assert body is not None
    side = gen.sides.get(body, {})
    key = mechanism.body_key(body)
    names = lambda kinds: [parameter_name(k, key) for k in kinds]  # noqa: E731
    if gen.multipole == "monopole":
        if gen.donor != 0:
            return names(["m"]) + names(DIAGONAL) + names(FIRST_MOMENTS)
        return names(DIAGONAL) + names(FIRST_MOMENTS) + names(["m"])
    if gen.multipole == "dipole":
        k = _largest_component(side["direction"], field)
        return names([FIRST_MOMENTS[k]]) + names(FIRST_MOMENTS) + names(reversed(DIAGONAL))
    if gen.condition == LOOP_CONDITION:       # planar loop: the donor's products of inertia
        return names(["Iyz", "Ixz", "Ixy"]) + names(reversed(DIAGONAL))
    if gen.label.startswith("quadrupole ") and gen.label.split()[-1] in PARAMETER_KINDS:
        own = gen.label.split()[-1]
        return names([own]) + names(["Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz"])
    return names(reversed(DIAGONAL)) + names(["Ixy", "Ixz", "Iyz"])


# ----- elimination ------------------------------------------------------------------------
@dataclass
class Step:
    """An accepted generator: its reduced vector, the parameter it eliminates, and (after
    :func:`apply_steps`) the multipole amount and the parameters it changed."""
    generator: Generator
    vector: dict[str, Any]         # parameter -> field element (reduced)
    pivot: str
    amount: dict[str, Any] = field(default_factory=dict)       # linear form: parameter -> field element
    changes: dict[str, Any] = field(default_factory=dict)      # parameter -> new linear form


@dataclass
class Derivation:
    mechanism: Mechanism
    field: ExactField
    bodies: list[BodyMotion]       # BodyMotion per body
    steps: list[Step]              # Step, in order
    redundant: list[tuple[Generator, str]]  # (Generator, reason)
    missing_rules: list[Joint]     # joints whose type has no rules
    base: dict[str, dict[str, Any]]  # kept parameter -> linear form (parameter -> field element)
    eliminated: list[str]
    warnings: list[str]
    root: int | None = None        # the body the elimination grows from (body_distances)
    distances: dict[int, int] | None = None  # joints from ground or the root, per body

    @property
    def conditions(self) -> list[Step]:
        return [s for s in self.steps if s.generator.kind == "condition"]

    @property
    def transfers(self) -> list[Step]:
        return [s for s in self.steps if s.generator.kind == "transfer"]


def _reduce(vector: dict[str, Any], steps: Sequence[Step]) -> dict[str, Any]:
    g = dict(vector)
    for step in steps:
        c = g.get(step.pivot)
        if not c:
            continue
        f = c / step.vector[step.pivot]
        for p, v in step.vector.items():
            s = g.get(p, 0) - f * v
            if s:
                g[p] = s
            else:
                g.pop(p, None)
    return g


def _order_generators(mechanism: Mechanism, bodies: Sequence[BodyMotion], transfers: list[Generator],
                      loops: Sequence[Generator] = ()) -> tuple[list[Generator], int | None, dict[int, int]]:
    root, dist = body_distances(mechanism)
    phase_a: list[Generator] = []
    phase_c: list[Generator] = []
    for motion in bodies:
        for g in motion.generators:
            late = g.multipole == "monopole" and g.sides[g.bodies[0]].get("where") != "origin"
            (phase_c if late else phase_a).append(g)
    joint_index = {j.name: i for i, j in enumerate(mechanism.joints)}
    for g in transfers:
        g.donor, g.acceptor = donor_acceptor(cast(Joint, g.joint), dist)

    def place(g: Any) -> tuple[bool, int, int]:
        return g.condition == 0, -(dist[g.donor] if g.donor else dist[g.acceptor]), joint_index[g.joint.name]

    transfers = sorted(transfers, key=place)
    for g in loops:                      # donor: the closing joint's (the report's grouping)
        g.donor, g.acceptor = donor_acceptor(cast(Joint, g.joint), dist)
    return phase_a + transfers + list(loops) + phase_c, root, dist


def eliminate(mechanism: Mechanism, keep: Sequence[str] = (), eliminate_first: Sequence[str] = (),
              states: list | None = None, seed: int = 1) -> Derivation:
    """Run the whole derivation (generators, elimination, base expressions)."""
    params = list(mechanism.parameters)

    def own(name: str, opt: str) -> str:         # either form: m3 or m_forearm (issue 45)
        try:
            return mechanism.parameter(name)
        except ValueError:
            raise InputError(f"{name!r} is not a parameter of {mechanism.name} "
                             f"({params[0]} ... {params[-1]})", key=opt) from None

    keep = [own(n, "keep") for n in keep]
    eliminate_first = [own(n, "eliminate_first") for n in eliminate_first]
    bodies, forms = analyse_bodies(mechanism, states=states, seed=seed)
    transfers, missing = transfer_generators(mechanism, registry.transfer_rules)
    for joint in mechanism.joints:
        if joint in missing:
            continue
        known = {g.multipole for g in transfers if g.joint is joint and g.multipole != "quadrupole"}
        transfers += sampled_joint_transfers(mechanism, joint, forms, known)
    loops = planar_loop_generators(mechanism)
    ordered, root, dist = _order_generators(mechanism, bodies, transfers, loops)
    field_ = ExactField(mechanism, [v for g in ordered for v in g.vector.values()])
    warnings = []
    for motion in bodies:
        if motion.missing > 0:
            warnings.append(f"body {motion.label}: sampling finds {motion.null_dimension} parameter "
                            f"directions without effect but exact data (body or joint axes and "
                            f"points) for only {len(motion.generators)}")
    for joint in missing:
        warnings.append(f"joint {joint.name}: no plugin gives transfer rules for joint type "
                        f"{joint.type.name!r}; multipoles across it are not used")
    keep_set = set(keep)
    first = list(eliminate_first)
    order = {p: i for i, p in enumerate(params)}
    steps: list[Step] = []
    redundant: list[tuple[Generator, str]] = []
    for gen in ordered:
        vector = {p: field_.convert(v) for p, v in gen.vector.items()}
        vector = {p: v for p, v in vector.items() if v}
        g = _reduce(vector, steps)
        live = [p for p in sorted(g, key=lambda p: order[p]) if field_.nonzero_at_geometry(g[p])]
        if not live:
            reason = "implied by the generators before it" if not g else \
                "vanishes at this geometry (special values of the geometry symbols)"
            redundant.append((gen, reason))
            continue
        if gen.kind == "transfer":
            gen.preference = transfer_preference(gen, mechanism, field_)
        donor = gen.donor if gen.kind == "transfer" and gen.donor else None
        fallback = sorted(live, key=lambda p: (mechanism.parameter_body(p)[1] != donor, order[p]))
        ranked = [p for p in first if p in live] + [p for p in gen.preference if p in live] + fallback
        choice = next((p for p in ranked if p not in keep_set), None)
        if choice is None:
            choice = ranked[0]
            warnings.append(f"{describe(gen)} can only eliminate kept parameters; {choice} eliminated")
        steps.append(Step(gen, g, choice))
    base = apply_steps(steps, params, field_.one)
    eliminated = [s.pivot for s in steps]
    derivation = Derivation(mechanism, field_, bodies, steps, redundant, missing,
                            {p: base[p] for p in params if p not in set(eliminated)},
                            eliminated, warnings)
    derivation.root, derivation.distances = root, dist
    return derivation


def apply_steps(steps: Sequence[Step], params: Sequence[str], one: Any = 1) -> dict[str, dict[str, Any]]:
    """Apply the transfers in order; returns every parameter's final value as a linear form
    in the original parameters (eliminated ones end at zero). Fills ``amount``/``changes``."""
    current: dict[str, dict[str, Any]] = {}

    def value(p: str) -> dict[str, Any]:
        return current.get(p, {p: one})

    for step in steps:
        pv = value(step.pivot)
        scale = -1 / step.vector[step.pivot]
        amount = {q: c * scale for q, c in pv.items()}
        step.amount = amount
        for p, coeff in step.vector.items():
            new = dict(value(p))
            for q, c in amount.items():
                s = new.get(q, 0) + c * coeff
                if s:
                    new[q] = s
                else:
                    new.pop(q, None)
            current[p] = new
            step.changes[p] = new
    return {p: value(p) for p in params}


def describe(gen: Generator) -> str:
    if gen.kind == "condition":
        return f"body {gen.bodies[0]} condition {gen.condition} ({gen.label})"
    return f"joint {gen.joint_name} ({gen.joint_type}) {gen.label}"


# ----- certification ----------------------------------------------------------------------
@dataclass
class Certificate:
    """What :func:`certify` established on W in balls (``rows`` x parameters at ``samples``
    states: the random states and the trajectory states of the proof, or every state when
    the shared analysis decided; ball arithmetic at ``digits``).

    Proven: ``rank(W) >= lower`` (``kept_proven``: the solver's kept columns themselves are
    proven independent; otherwise ``lower`` is the shared ball analysis's own rank).
    Evidence: each tested generator n gave balls ``W n`` that all contain 0 (``failed``:
    those that did not); ``residual`` is the largest ``max|W n| / (max|W| max|n|)``
    (upper bounds) over the tested generators, None when none was tested.
    """
    digits: int
    samples: int
    rows: int
    lower: int
    kept_proven: bool
    generators: int = 0
    random_states: int = 0          # of ``samples``: drawn independently of the trajectory
    tested: int = 0
    residual: float | None = None
    failed: list[tuple[str, Any]] = field(default_factory=list)      # (description, relative residual)
    untested: list[tuple[str, str]] = field(default_factory=list)    # (description, reason)

    @property
    def passed(self) -> int:
        return self.tested - len(self.failed)

    def info(self) -> dict[str, Any]:
        """The ``diagnostics.certificate`` entry of the result (JSON-ready)."""
        return {"digits": self.digits, "samples": self.samples, "random_states": self.random_states,
                "rows": self.rows,
                "rank_lower_bound": self.lower, "kept_columns_proven": self.kept_proven,
                "generators": self.generators, "generators_tested": self.tested,
                "generators_passed": self.passed,
                "generator_residual": None if self.residual is None else f"{self.residual:.2e}",
                "generators_failed": [{"source": s, "residual": f"{r:.2e}"} for s, r in self.failed],
                "generators_untested": [{"source": s, "reason": r} for s, r in self.untested]}


def certify(mechanism: Mechanism, derivation: Derivation, digits: int = 40,
            trajectory: Trajectory | None = None) -> Certificate:
    """Check the symbolic count on W computed in ball arithmetic at ``digits`` (a
    :class:`Certificate`).

    W is the trajectory's observation matrix stacked with rows at independent random states
    (kept as blocks: nothing needs them copied into one matrix). It is computed in float64
    at every state, to choose, and in balls where claims are made:

    - Lower bound (a proof): the kept columns are proven independent, so rank(W) >= their
      number: by :func:`.rank_bound.columns_independent` (rows and a preconditioner chosen
      on the float64 W, the claim ||I - W_RK X|| < 1 made in balls), first on the random
      states' rows alone (they are at least as many as the parameters), else on rows
      chosen among all, with balls at the trajectory states holding some of them
      (:class:`~baseparams.dynamics.observation.Subset`, the same balls as in W at the
      whole trajectory). Should that fail too, W in balls at every state and
      ``baseparams.numeric.certify.analyse`` with the kept columns imposed decide; if it
      cannot either, that analysis without them gives the rank it can prove.
    - Generators (evidence): every accepted generator, reduced as in the elimination, is
      evaluated at the geometry in balls (exact rationals, or balls around square roots
      of non-squares) and passes when every entry of W n contains 0 and
      |W n| <= 10^-(digits/2) max|W| max|n| (max|W| from the float64 W, a scale only),
      on every state W has in balls: all the random states (ceil(parameters / dof) of them,
      drawn independently of the trajectory: a vector that is not a null vector of the
      mechanism gives W n != 0 at almost every state, so these generic states are the
      evidence; the trajectory's states lie on one curve of the state space and add no
      power of their own) and any trajectory states of the proof. W's balls enclose the
      exact W at the states, so a true null vector always passes; passing on N states is
      not a proof that n is one.
    """
    backend = Arb(digits)
    trajectory = trajectory or Trajectory.default(mechanism)
    # W in float64 at every state: choices (rows, preconditioner) and max|W|, never claims;
    # without it (float64 refused, e.g. over the memory limit) the shared analysis decides
    wf_trajectory: Any = None
    wf_random: Any = None
    try:
        wf_trajectory = observation_matrix(mechanism, Float64(), trajectory)[0]
    except (InputError, KinematicsError, MemoryError):
        pass
    # rows at random states independent of the trajectory, so that a trajectory which does
    # not excite the mechanism cannot lower the proven rank (core/excitation.py)
    batch = random_batch(mechanism, trajectory, seed=7919)
    random_block: Any = observation_matrix(mechanism, backend, cast(Any, batch))[0]
    params = list(mechanism.parameters)
    kept = [params.index(p) for p in derivation.base]
    index = {p: i for i, p in enumerate(params)}
    try:
        if wf_trajectory is not None:
            wf_random = cast(np.ndarray, observation_matrix(mechanism, Float64(), cast(Any, batch))[0])
    except (InputError, KinematicsError, MemoryError):
        pass
    usable = wf_random is not None and wf_trajectory.shape[1] == wf_random.shape[1] == len(params)
    wf = np.vstack([wf_trajectory, wf_random]) if usable else np.zeros((0, 0))
    width = random_block.nrows() // max(1, batch.count)
    lower = None
    with backend.activate():
        if usable and columns_independent([random_block], wf_random, kept):
            # the random states' rows alone: no trajectory state in balls at all
            blocks, lower, kept_proven, samples = [random_block], len(kept), True, batch.count
        chosen = choose_rows(wf[:, kept]) if usable and lower is None else None
        if chosen is not None:
            # rows chosen among all: balls at the trajectory states that hold some of them
            states = tuple(sorted({i // width for i in chosen if i < wf_trajectory.shape[0]}))
            subset: Any = Subset(trajectory, states)
            blocks = [observation_matrix(mechanism, backend, subset)[0]] if states else []
            blocks.append(random_block)
            rows_used = [s * width + k for s in states for k in range(width)]
            if columns_independent(blocks, np.vstack([wf_trajectory[rows_used], wf_random]), kept):
                lower, kept_proven, samples = len(kept), True, len(states) + batch.count
        if lower is None:           # every state in balls, and the shared analysis
            W, info = observation_matrix(mechanism, backend, trajectory)
            blocks = [W, random_block]
            samples = int(info["samples"]) + batch.count
            stacked = backend.stack(*blocks)
            try:
                lower, kept_proven = analyse(stacked, digits, kept=kept, approximate_spectrum=False).rank, True
            except ValueError:      # not proven independent: what can be proven instead
                lower, kept_proven = analyse(stacked, digits, approximate_spectrum=False).rank, False
        rows = sum(b.nrows() for b in blocks)
        cert = Certificate(digits, samples, rows, lower, kept_proven,
                           generators=len(derivation.steps), random_states=batch.count)
        if usable:
            wmax = float(np.max(np.abs(wf), initial=0.0)) or 1.0
        else:
            wmax = max((abs(float(x.mid())) for b in blocks for x in b.entries()), default=0.0) or 1.0
        tolerance = 10.0 ** (-(digits // 2))
        for step in derivation.steps:
            n = arb_mat(len(params), 1)
            try:
                for p, v in step.vector.items():
                    x = derivation.field.value(v)
                    n[index[p], 0] = arb(fmpq(x.numerator, x.denominator)) if isinstance(x, Fraction) \
                        else backend.evaluate(x)
            except ValueError as exc:       # a radical the backend cannot evaluate
                cert.untested.append((describe(step.generator), str(exc)))
                continue
            res = [x for block in blocks for x in (block * n).entries()]
            nmax = max(abs(float(n[index[p], 0].mid())) for p in step.vector) if step.vector else 0.0
            r = max((float(x.abs_upper()) for x in res), default=0.0) / (wmax * (nmax or 1.0))
            cert.tested += 1
            cert.residual = max(cert.residual or 0.0, r)
            if r > tolerance or not all(x.contains(0) for x in res):
                cert.failed.append((describe(step.generator), r))
    return cert


# ----- result -------------------------------------------------------------------------------
def coefficient_text(field_: ExactField, elem: Any) -> str:
    """The coefficient as text: sympy's factored form (a rational number prints as itself,
    which python-flint's ``str`` of an fmpq gives without sympy)."""
    if field_.constant:
        return str(elem)
    return _factored(field_.to_sympy(elem))


@functools.lru_cache(maxsize=4096)
def _factored(expression: sympy.Expr) -> str:
    """sympy's factored form, once per distinct expression (on the SLA 98 coefficients are
    33 distinct expressions, 53 of them 1: each is factored once)."""
    return str(expression) if expression.is_Number else str(sympy.factor(expression))


def value_text(field_: ExactField, elem: Any) -> str:
    v = field_.value(elem)
    return str(v)


def solve(mechanism: Mechanism, keep: Sequence[str] = (), eliminate_first: Sequence[str] = (),
          certify_rank: bool = True, digits: int = 40, seed: int = 1,
          trajectory: Trajectory | None = None) -> BaseParameterResult:
    """The symbolic solver: a :class:`BaseParameterResult` with the derivation in
    ``diagnostics.derivation``."""
    start = time.perf_counter()
    der = eliminate(mechanism, keep=keep, eliminate_first=eliminate_first, seed=seed)
    f = der.field
    params = list(mechanism.parameters)
    order = {p: i for i, p in enumerate(params)}
    base, values, coefficients = [], [], []
    for k, (kept, form) in enumerate(der.base.items(), start=1):
        terms = sorted(form.items(), key=lambda t: (t[0] != kept, order[t[0]]))
        texts, value_texts, coefficient_row = {}, {}, {}
        for p, c in terms:
            texts[p], v = coefficient_text(f, c), f.value(c)
            value_texts[p] = str(v)
            # an exact value is kept as it is (not printed and parsed back)
            coefficient_row[p] = Coefficient.of_exact(v, texts[p]) if isinstance(v, Fraction) \
                else _coefficient(texts[p], value_texts[p])
        base.append({"name": f"phi_b{k:02d}", "expression": texts})
        values.append(value_texts)
        coefficients.append(coefficient_row)
    rank = len(der.base)
    warnings = list(der.warnings)
    diagnostics: dict[str, Any] = {"conditions": [_step_json(s, f) for s in der.conditions],
                   "transfers": [_step_json(s, f) for s in der.transfers],
                   "redundant": [{"source": describe(g), "reason": r} for g, r in der.redundant],
                   "root": der.root}
    certified = upper_bound = False
    if certify_rank:
        cert = certify(mechanism, der, digits=digits, trajectory=trajectory)
        diagnostics["certificate"] = cert.info()
        warnings += _certificate_warnings(cert, rank)
        upper_bound = not cert.failed and cert.lower < rank
        certified = not cert.failed and not cert.untested and cert.lower == rank
    else:
        warnings.append("rank not checked (certify off): the count rests on the generators alone, "
                        "body conditions among them accepted on sampled numerical evidence")
    summary = [f"{len(der.conditions)} parameters without effect (body conditions), "
               f"{len(der.transfers)} eliminated by multipole transfers, "
               f"{len(der.redundant)} redundant generators"]
    if certify_rank:
        summary.append(f"ball arithmetic at {cert.digits} digits on {cert.samples} states proves "
                       f"rank >= {cert.lower}; {cert.passed} of {cert.generators} generators n give "
                       f"balls W n that contain 0 (evidence for rank <= {len(params) - cert.passed})")
    summary.append("derivation: `baseparams report MECH` (text, markdown or latex)")
    if any(not _is_fraction_text(t) for row in values for t in row.values()):
        warnings.append("square roots of non-squares in the geometry: some expression values are algebraic")
    return BaseParameterResult(
        mechanism=mechanism.name, solver="symbolic", parameters=params, rank=rank, base=base,
        eliminated=der.eliminated, certified=certified,
        geometry=mechanism.geometry_text,
        warnings=warnings, elapsed_s=time.perf_counter() - start, expression_values=values,
        rank_is_upper_bound=upper_bound, coefficients=coefficients,
        diagnostics=Diagnostics(summary=summary, derivation=der, details=diagnostics))


def _coefficient(text: str, value_text_: str) -> Coefficient:
    """An expression's data: its exact rational value, or an algebraic value to 50 digits."""
    if _is_fraction_text(value_text_):
        return Coefficient.of_exact(Fraction(value_text_), text)
    return Coefficient(text=text, value=parse_coefficient(value_text_), exact=False, digits=50)


def _certificate_warnings(cert: Certificate, rank: int) -> list[str]:
    """Why a checked result is not certified (nothing when it is)."""
    out = []
    if cert.failed:
        names = "; ".join(f"{s} (relative residual {r:.2e})" for s, r in cert.failed)
        out.append(f"{len(cert.failed)} generator(s) failed the null-vector check at {cert.digits} digits "
                   f"(a ball of W n excludes 0, or is too wide to tell): {names}. The symbolic count "
                   f"{rank} may be too low: not certified")
    if cert.untested:
        names = "; ".join(f"{s} ({why})" for s, why in cert.untested)
        out.append(f"{len(cert.untested)} generator(s) could not be evaluated in ball arithmetic and "
                   f"were not tested: {names}. Not certified")
    if not cert.failed and cert.lower < rank:
        out.append(f"the rank is only proven >= {cert.lower}; the symbolic count {rank} is an upper bound "
                   f"(a dependency the rules and conditions do not know?)")
    if not cert.failed and cert.lower > rank:
        out.append(f"ball arithmetic proves rank >= {cert.lower}, above the symbolic count {rank}: some "
                   f"generator is not a null vector although it passed at {cert.digits} digits. "
                   f"Not certified")
    if not cert.kept_proven and cert.lower == rank and not cert.failed:
        out.append("the kept columns are not proven independent (another set of that size is)")
    return out


def _is_fraction_text(text: str) -> bool:
    try:
        Fraction(text)
        return True
    except (ValueError, ZeroDivisionError):
        return False


def _step_json(step: Step, f: ExactField) -> dict[str, Any]:
    g = step.generator
    out = {"kind": g.kind, "condition": g.condition, "multipole": g.multipole, "label": g.label,
           "bodies": list(g.bodies), "eliminated": step.pivot}
    if g.kind == "transfer":
        out.update({"joint": g.joint_name, "joint_type": g.joint_type, "donor": g.donor,
                    "acceptor": g.acceptor})
    return out

