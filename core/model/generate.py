"""Random mechanisms, as mechanism-file text, for cross-checking the solvers.

Each function takes a seed and returns the TOML text of a mechanism file (the format of
docs/mechanism-format.md): :func:`baseparams.io.loader.parse_mechanism` reads it, and a
user may save it and run the CLI on it. The same seed always gives the same text.

What is random, and why:

- *Topology* (:func:`serial_chain`, :func:`tree`): 2-12 bodies, R and P joints (S and U
  on request), so that the solvers meet chains and branches of every length and mix.
- *Joint frames*, drawn independently on each side of each joint, so that the bodies'
  reference poses are random too. Axes along a body axis (with or without ``ref``),
  Pythagorean axes in a coordinate plane such as (3, 4, 0) (with or without ``ref``: the
  default x axis is then still rational) and fully general rational frames from integer
  quaternions such as axis (1, 2, 2)/3 with an explicit ``ref``; axes are written
  normalised or as unnormalised integer vectors. Every frame is rational, so the exact
  solver applies; ``irrational`` (a probability) adds axes such as (1, 1, 1) without
  ``ref``, whose default x axis has an irrational length.
- *Offsets*: decimal strings, each component zero with probability ``zero_offset`` so that
  intersecting and parallel axes (special geometry, where parameters regroup) are common.
- *Inertia*: mass > 0, a centre of mass, and an inertia at the COM ``R diag R^T`` with R a
  rational rotation and principal moments from positive second moments (so positive
  definite with the triangle inequalities). Base parameters do not depend on these
  values; they make the file complete for simulation.
- *Trajectory*: per coordinate an offset and three sines of distinct frequencies (a
  Fourier trajectory), amplitudes by joint type (S joints stay far from their Cardan
  singularity). *Gravity*: along -z, along another axis, or a random rational vector.

:func:`four_bar` gives a closed loop: a planar four-bar with random rational link
lengths, its plane and its bodies' frames rotated at random, exactly closed at the
reference configuration, and a crank motion that stays well inside its assembly range.
"""

import math
import random
import re
from collections.abc import Sequence
from fractions import Fraction

from baseparams.model.expressions import exact_text

_UNIT = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
_PYTHAGOREAN = [(3, 4, 5), (5, 12, 13), (8, 15, 17), (7, 24, 25), (20, 21, 29)]


# ----- exact little vectors ---------------------------------------------------------------
Q = Fraction | int                   # an exact rational
Vec = tuple[Q, ...]                  # three of them
Rows = tuple[Vec, ...]               # a 3 x 3 matrix by rows


def _dot(a: Vec, b: Vec) -> Q:
    return sum(x * y for x, y in zip(a, b))


def _scale(v: Vec, s: Q) -> Vec:
    return tuple(x * s for x in v)


def _sub(a: Vec, b: Vec) -> Vec:
    return tuple(x - y for x, y in zip(a, b))


def _add(a: Vec, b: Vec) -> Vec:
    return tuple(x + y for x, y in zip(a, b))


def _matvec(rows: Rows, v: Vec) -> Vec:
    return tuple(_dot(row, v) for row in rows)


def _transpose(rows: Rows) -> Rows:
    return tuple(tuple(rows[i][j] for i in range(3)) for j in range(3))


def _matmul(a: Rows, b: Rows) -> Rows:
    bt = _transpose(b)
    return tuple(tuple(_dot(a[i], bt[j]) for j in range(3)) for i in range(3))


def _integer_multiple(v: Vec) -> tuple[int, ...]:
    """The shortest integer vector along the rational vector ``v``."""
    fr = [Fraction(x) for x in v]
    den = math.lcm(*(x.denominator for x in fr))
    ints = [int(x * den) for x in fr]
    g = math.gcd(*ints) or 1
    return tuple(x // g for x in ints)


def _text(x: Q) -> str:
    return exact_text(Fraction(x))


def _vector(v: Sequence[Q]) -> str:
    return "[" + ", ".join(f'"{_text(x)}"' for x in v) + "]"


class _Draw:
    """The seeded random source, with the rational draws the generators share."""

    def __init__(self, seed: int | str) -> None:
        self.rng = random.Random(seed)

    def decimal(self, lo: Q | float, hi: Q | float, places: int = 2) -> Fraction:
        """A decimal with ``places`` places in [lo, hi]."""
        k = 10 ** places
        return Fraction(self.rng.randint(round(lo * k), round(hi * k)), k)

    def sign(self) -> int:
        return self.rng.choice((1, -1))

    def rotation(self, small: int = 3) -> Rows:
        """A rational rotation (rows) from an integer quaternion: entries p/n, n = |q|^2."""
        while True:
            a, b, c, d = (self.rng.randint(-small, small) for _ in range(4))
            n = a * a + b * b + c * c + d * d
            if n:
                break
        r = ((a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)),
             (2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)),
             (2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d))
        return tuple(tuple(Fraction(x, n) for x in row) for row in r)

    def signed_permutation(self) -> Rows:
        """A rotation (rows) that maps body axes onto body axes."""
        while True:
            perm = self.rng.sample(range(3), 3)
            signs = [self.sign() for _ in range(3)]
            rows = tuple(tuple(Fraction(signs[i]) if j == perm[i] else Fraction(0) for j in range(3))
                         for i in range(3))
            if _det(rows) == 1:
                return rows

    def pythagorean_rotation(self) -> Rows:
        """A rotation about a body axis by an angle with rational cosine and sine."""
        a, b, c = self.rng.choice(_PYTHAGOREAN)
        co, si = Fraction(a, c) * self.sign(), Fraction(b, c) * self.sign()
        k = self.rng.randrange(3)
        i, j = [m for m in range(3) if m != k]
        rows = [[Fraction(int(r == s)) for s in range(3)] for r in range(3)]
        rows[i][i], rows[i][j], rows[j][i], rows[j][j] = co, -si, si, co
        return tuple(tuple(row) for row in rows)


def _det(r: Rows) -> Q:
    return (r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]))


# ----- frames -------------------------------------------------------------------------------
def _frame_text(point: Vec, rot: Rows, draw: _Draw, irrational: bool = False) -> str:
    """A joint frame (inline table) with origin ``point`` and axes the columns of ``rot``;
    ``ref`` is usually left out when the loader's default x axis is the frame's own.
    ``irrational``: instead an axis with no zero component and no ``ref`` (its default x
    axis, made perpendicular to it, has an irrational length)."""
    x, z = _transpose(rot)[0], _transpose(rot)[2]
    if irrational:
        skew = tuple(draw.sign() * draw.rng.randint(1, 3) for _ in range(3))
        return f"{{ point = {_vector(point)}, axis = {_vector(skew)} }}"
    unnormalised = draw.rng.random() < 0.5
    axis: Vec = _integer_multiple(z) if unnormalised else z
    ref: Vec = _integer_multiple(x) if unnormalised else x
    if x == _default_x(z) and draw.rng.random() < 0.7:
        return f"{{ point = {_vector(point)}, axis = {_vector(axis)} }}"
    return f"{{ point = {_vector(point)}, axis = {_vector(axis)}, ref = {_vector(ref)} }}"


def _default_x(z: Vec) -> Vec | None:
    """The loader's default x axis for the unit axis ``z`` when it is rational, else None
    (docs/mechanism-format.md: the body axis least aligned with z, made perpendicular)."""
    k = min(range(3), key=lambda i: (abs(z[i]), i))
    e = _UNIT[k]
    d = _dot(e, z)
    v = _sub(e, _scale(z, d))
    n2 = _dot(v, v)
    root = Fraction(math.isqrt(n2.numerator), math.isqrt(n2.denominator))
    if root * root != n2:
        return None
    return _scale(v, 1 / root)


def _random_rotation(draw: _Draw) -> Rows:
    """A frame orientation: body axes (often), a rational turn about a body axis, or general."""
    u = draw.rng.random()
    if u < 0.5:
        return draw.signed_permutation()
    if u < 0.75:
        return _matmul(draw.signed_permutation(), draw.pythagorean_rotation())
    return draw.rotation()


def _default_frame(draw: _Draw, rot: Rows) -> Rows:
    """``rot`` with its x axis replaced by the loader's default when that is rational and a
    coin says so (a frame written without ``ref``)."""
    cols = _transpose(rot)
    x = _default_x(cols[2])
    if x is None or draw.rng.random() < 0.5:
        return rot
    y = _cross(cols[2], x)
    return _transpose((x, y, cols[2]))


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _point(draw: _Draw, zero_offset: float, scale: Fraction = Fraction(3, 10)) -> Vec:
    return tuple(Fraction(0) if draw.rng.random() < zero_offset else draw.decimal(-scale, scale)
                 for _ in range(3))


# ----- bodies, trajectory, gravity ----------------------------------------------------------
def _body_text(label: int, draw: _Draw) -> str:
    """Mass, COM and an inertia at the COM that is positive definite (triangle inequalities)."""
    mass = draw.decimal(Fraction(1, 2), 5, 1)
    com = tuple(draw.decimal(Fraction(-2, 10), Fraction(2, 10)) for _ in range(3))
    s = [mass * draw.decimal(Fraction(1, 1000), Fraction(3, 100), 3) for _ in range(3)]
    principal = (s[1] + s[2], s[0] + s[2], s[0] + s[1])
    rot = draw.rotation(2) if draw.rng.random() < 0.5 else draw.signed_permutation()
    tensor = [[sum(rot[i][k] * principal[k] * rot[j][k] for k in range(3)) for j in range(3)]
              for i in range(3)]
    entries = [tensor[i][j] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))]
    return (f"[[bodies]]\nlabel = {label}\nmass = \"{_text(mass)}\"\ncom = {_vector(com)}\n"
            f"inertia_com = {_vector(entries)}\n")


def _fourier(draw: _Draw, amplitude: Q, offset: Q = Fraction(0)) -> str:
    """An offset plus three sines of distinct frequencies, total amplitude <= ``amplitude``."""
    freqs = draw.rng.sample([Fraction(k, 10) for k in range(5, 31)], 3)
    weights = [draw.decimal(Fraction(2, 10), 1) for _ in range(3)]
    total = sum(weights)
    terms = [_text(offset)] if offset else []
    for w, f in zip(weights, freqs):
        a = Fraction(round(amplitude * w / total * 1000), 1000)
        phase = draw.decimal(0, 3, 1)
        terms.append(f"{_text(a)}*sin({_text(f)}*t + {_text(phase)})")
    return " + ".join(terms)


AMPLITUDE = {"R": Fraction(12, 10), "P": Fraction(2, 10), "U": Fraction(1)}


def _trajectory(draw: _Draw, coordinates: Sequence[tuple[str, str]], samples: int) -> str:
    q = []
    for name, kind in coordinates:
        if kind == "S":          # Cardan angles: b stays within 0.6 rad of 0, far from 90 deg
            expr = _fourier(draw, Fraction(6, 10))
        elif kind == "P":
            expr = _fourier(draw, AMPLITUDE["P"], draw.decimal(Fraction(-1, 10), Fraction(1, 10)))
        else:
            expr = _fourier(draw, AMPLITUDE.get(kind, Fraction(1)), draw.decimal(Fraction(-5, 10), Fraction(5, 10), 1))
        q.append(f'{name} = "{expr}"')
    return (f'[trajectory]\nt_start = "0"\nt_end = "10"\nsamples = {samples}\n'
            f"q = {{ {', '.join(q)} }}\n")


def _gravity(draw: _Draw) -> Vec:
    u = draw.rng.random()
    if u < 0.5:
        return (Fraction(0), Fraction(0), Fraction(-981, 100))
    if u < 0.7:
        k = draw.rng.randrange(3)
        return tuple(Fraction(-981, 100) * draw.sign() if i == k else Fraction(0) for i in range(3))
    return tuple(draw.decimal(-10, 10, 1) for _ in range(3))


# ----- open mechanisms ----------------------------------------------------------------------
def serial_chain(seed: int, bodies: int | None = None, max_bodies: int = 6, types: str = "RP",
                 spherical: float = 0.0, irrational: float = 0.0, zero_offset: float = 0.3,
                 samples: int = 100) -> str:
    """A random serial chain (TOML text); see the module docstring for what is random.

    ``bodies``: the number of moving bodies (default: random in 2..``max_bodies``);
    ``types``: the 1-coordinate joint types drawn from (R three times as often as P);
    ``spherical``: the probability of an S or U joint; ``irrational``: of a frame without
    ``ref`` whose default x axis is irrational (the exact solver refuses those).
    """
    draw = _Draw(f"chain:{seed}")
    n = bodies or draw.rng.randint(2, max_bodies)
    return _open(f"gen_chain_{seed}", draw, list(range(n)), types, spherical, irrational,
                 zero_offset, samples)


def tree(seed: int, bodies: int | None = None, max_bodies: int = 6, types: str = "RP",
         spherical: float = 0.0, irrational: float = 0.0, zero_offset: float = 0.3,
         samples: int = 100) -> str:
    """A random tree (TOML text): each body hangs from an earlier one (or from ground,
    for at most two bodies), the previous body preferred so that branches are long."""
    draw = _Draw(f"tree:{seed}")
    n = bodies or draw.rng.randint(3, max(3, max_bodies))
    parents, grounded = [0], 1
    for b in range(2, n + 1):
        if grounded < 2 and draw.rng.random() < 0.15:
            parents.append(0)
            grounded += 1
        elif draw.rng.random() < 0.5:
            parents.append(b - 1)
        else:
            parents.append(draw.rng.randint(1, b - 1))
    return _open(f"gen_tree_{seed}", draw, parents, types, spherical, irrational, zero_offset, samples)


def _open(name: str, draw: _Draw, parents: Sequence[int], types: str, spherical: float, irrational: float,
          zero_offset: float, samples: int) -> str:
    """Mechanism text for the tree given by ``parents`` (body b + 1 hangs from parents[b];
    a serial chain when parents[b] == b)."""
    pool = [t for t in types for _ in range(3 if t == "R" else 1)]
    out = [f'[mechanism]\nname = "{name}"\ntitle = "Generated: {name}"\n'
           f'description = "Random mechanism from baseparams.model.generate (seed in the name)."\n'
           f"gravity = {_vector(_gravity(draw))}\n"]
    out += [_body_text(b, draw) for b in range(1, len(parents) + 1)]
    coordinates = []
    for index, parent in enumerate(parents):
        child = index + 1
        jtype = draw.rng.choice("SU") if draw.rng.random() < spherical else draw.rng.choice(pool)
        names = [f"q{child}"] if jtype in "RP" else [f"q{child}{s}" for s in ("abc" if jtype == "S" else "xy")]
        coordinates += [(c, jtype) for c in names]
        frames = []
        for side in ("parent", "child"):
            rot = _default_frame(draw, _random_rotation(draw))
            point = _point(draw, zero_offset) if side == "parent" or draw.rng.random() < 0.5 else (0, 0, 0)
            odd = draw.rng.random() < irrational
            frames.append(_frame_text(point, rot, draw, irrational=odd))
        quoted = ", ".join(f'"{c}"' for c in names)
        out.append(f'[[joints]]\ntype = "{jtype}"\nparent = {parent}\nchild = {child}\n'
                   f"coordinates = [{quoted}]\n"
                   f"parent_frame = {frames[0]}\nchild_frame = {frames[1]}\n")
    out.append(_trajectory(draw, coordinates, samples))
    return "\n".join(out)


def coupled_chain(seed: int, bodies: int | None = None, max_bodies: int = 6, types: str = "RP",
                  samples: int = 100) -> str:
    """A random serial chain (as :func:`serial_chain`) in which one coordinate follows an
    earlier one of the same kind: ``[[couplings]]`` with a random nonzero rational ratio and
    offset (a gear train between joints, URDF ``<mimic>``); its trajectory expression is
    left out (it is not independent)."""
    text = serial_chain(seed, bodies=bodies or None, max_bodies=max_bodies, types=types, samples=samples)
    draw = _Draw(f"coupling:{seed}")
    kinds = re.findall(r'type = "([RP])"\nparent = \d+\nchild = (\d+)', text)
    pairs = [(f"q{b}", f"q{a}") for i, (kind_b, b) in enumerate(kinds) for kind_a, a in kinds[:i]
             if kind_a == kind_b]
    if not pairs:
        raise ValueError(f"chain {seed} has no two coordinates of one kind to couple")
    follower, leader = draw.rng.choice(pairs)
    text = re.sub(rf'(, )?{follower} = "[^"]*"(, )?', lambda m: ", " if m.group(1) and m.group(2) else "", text)
    ratio = draw.sign() * draw.decimal(0.3, 3, 1)
    offset = draw.decimal(-0.2, 0.2, 2)
    return (text.replace(f'name = "gen_chain_{seed}"', f'name = "gen_coupled_{seed}"')
            + f'\n[[couplings]]\ncoordinate = "{follower}"\nleader = "{leader}"\n'
              f'ratio = "{exact_text(ratio)}"\noffset = "{exact_text(offset)}"\n')


# ----- a closed loop ------------------------------------------------------------------------
def _unit_2d(draw: _Draw) -> Vec:
    """A rational unit vector of the plane (a Pythagorean direction, or an axis)."""
    if draw.rng.random() < 0.2:
        return draw.rng.choice([(1, 0), (0, 1), (-1, 0), (0, -1)])
    a, b, c = draw.rng.choice(_PYTHAGOREAN)
    if draw.rng.random() < 0.5:
        a, b = b, a
    return (Fraction(a, c) * draw.sign(), Fraction(b, c) * draw.sign())


def _four_bar_ok(a: tuple[float, ...], b: tuple[float, ...], c: tuple[float, ...], d: tuple[float, ...],
                 swing: float) -> bool:
    """Float check that the crank can swing by +-``swing`` rad from the reference with the
    coupler-rocker angle (transmission) kept within 25..155 degrees (no dead point)."""
    l1, l2, l3 = math.dist((0, 0), b), math.dist(b, c), math.dist(c, d)
    ang0 = math.atan2(b[1], b[0])
    for k in range(-20, 21):
        t = ang0 + swing * k / 20
        bx, by = l1 * math.cos(t), l1 * math.sin(t)
        e = math.dist((bx, by), d)
        cos_mu = (l2 * l2 + l3 * l3 - e * e) / (2 * l2 * l3)
        if not -math.cos(math.radians(25)) < cos_mu < math.cos(math.radians(25)):
            return False
    return True


def four_bar(seed: int, samples: int = 100, parallelogram: bool = False) -> str:
    """A random planar four-bar (TOML text): crank A-B, coupler B-C, rocker D-C, the
    coupler-rocker joint closing the loop; the crank angle is independent.

    Random: the reference directions of the three links (rational unit vectors, so that
    the loop closes exactly with rational lengths: D = B + L2 u2 - L3 u3), the lengths
    (decimals), the plane's orientation in ground axes and each body's frame (rational
    rotations about the joint axis and offsets along it), inertias, gravity and a crank
    motion of at most 0.5 rad about the reference that keeps the transmission angle in
    25..155 degrees. ``parallelogram``: the rocker parallel to the crank and as long, so
    that exactly ``qb = -qa`` and ``qd = qa`` everywhere (every joint axis is the plane's
    normal): the loop has a tree form with couplings to check it against."""
    draw = _Draw(f"{'parallelogram' if parallelogram else 'four_bar'}:{seed}")
    while True:
        lengths = [draw.decimal(Fraction(1, 10), Fraction(6, 10)) for _ in range(3)]
        u1, u2, u3 = (_unit_2d(draw) for _ in range(3))
        if parallelogram:
            u3, lengths[2] = u1, lengths[0]
        b = _scale(u1, lengths[0])
        c = _add(b, _scale(u2, lengths[1]))
        d = _sub(c, _scale(u3, lengths[2]))
        a_, b_, c_, d_ = (tuple(map(float, p)) for p in ((0, 0), b, c, d))
        # a parallelogram's change point (links collinear: it may fold into the crossed
        # form) kept beyond the random states' reach too (the trajectory's range + 0.3 rad)
        if math.dist((0, 0), d) > 0.05 and _four_bar_ok(a_, b_, c_, d_, 0.9 if parallelogram else 0.5):
            break
    plane = _random_rotation(draw)              # the plane's axes (x, y in plane, z normal) in ground
    origin = _point(draw, 0.5)

    def world(p2: Vec) -> Vec:                               # a plane point in ground coordinates
        return _add(origin, _matvec(plane, (p2[0], p2[1], 0)))

    # body frames (in the plane's axes): origin at the proximal joint, x along the link,
    # then turned by a random rational rotation (about the normal or in general) and shifted
    links = {1: ((0, 0), u1), 2: (b, u2), 3: (d, u3)}
    poses = {}
    for body, (p2, u) in links.items():
        x = (u[0], u[1], 0)
        link = _transpose(((x[0], x[1], 0), (-x[1], x[0], 0), (0, 0, 1)))
        turn = _random_rotation(draw)
        rot = _matmul(_matmul(plane, link), turn)
        poses[body] = (rot, _add(world(p2), _matvec(plane, (0, 0, draw.decimal(Fraction(-1, 10), Fraction(1, 10))))))
    poses[0] = (((1, 0, 0), (0, 1, 0), (0, 0, 1)), (0, 0, 0))
    joints = [("JA", 0, 1, (0, 0), False), ("JB", 1, 2, b, False), ("JD", 0, 3, d, False), ("JC", 2, 3, c, True)]
    out = [f'[mechanism]\nname = "gen_four_bar_{seed}"\ntitle = "Generated: gen_four_bar_{seed}"\n'
           f'description = "Random planar four-bar from baseparams.model.generate."\n'
           f"gravity = {_vector(_gravity(draw))}\n"]
    out += [_body_text(label, draw) for label in (1, 2, 3)]
    for name, parent, child, p2, loop in joints:
        joint_rot = _matmul(plane, _random_turn_about_z(draw))     # z: the plane's normal
        sides = []
        for body in (parent, child):
            rot, o = poses[body]
            local_rot = _matmul(_transpose(rot), joint_rot)
            local_point = _matvec(_transpose(rot), _sub(world(p2), o))
            sides.append(_frame_text(local_point, local_rot, draw))
        out.append(f'[[joints]]\nname = "{name}"\ntype = "R"\nparent = {parent}\nchild = {child}\n'
                   f'coordinates = ["q{name[1].lower()}"]\n' + ("loop = true\n" if loop else "")
                   + f"parent_frame = {sides[0]}\nchild_frame = {sides[1]}\n")
    out.append('[coordinates]\nindependent = ["qa"]\n')
    out.append(f'[trajectory]\nt_start = "0"\nt_end = "10"\nsamples = {samples}\n'
               f'q = {{ qa = "{_fourier(draw, Fraction(1, 2))}" }}\n')
    return "\n".join(out)


def coupled_loop(seed: int, samples: int = 100, parallelogram: bool = False, tree: bool = False) -> str:
    """A random four-bar (:func:`four_bar`) with one or two more bodies whose coordinates
    follow the loop's (``[[couplings]]``: a cable-driven counterweight, a belt, a gear):
    each hangs from ground or a loop body by an R or P joint with random frames, and
    follows a random tree coordinate of the loop (the crank, or a dependent one) with a
    random nonzero rational ratio and offset.

    ``tree`` (with ``parallelogram``): the same mechanism with the loop cut (its closing
    joint left out) and the parallelogram's dependent angles written as couplings of the
    crank (``qb = -qa``, ``qd = qa``), a follower of one of them rewritten as a follower
    of the crank: same bodies, same motion, no closed loop, an independent form to check
    the loop's against."""
    if tree and not parallelogram:
        raise ValueError("only a parallelogram has a tree form with couplings")
    text = four_bar(seed, samples=samples, parallelogram=parallelogram)
    draw = _Draw(f"coupled_loop:{seed}")
    extra = [4] if draw.rng.random() < 0.5 else [4, 5]
    leaders = ["qa", "qb", "qd"]
    bodies, joints, couplings = [], [], []
    for label in extra:
        bodies.append(_body_text(label, draw))
        jtype = draw.rng.choice("RRP")
        parent = draw.rng.randrange(4)
        frames = [_frame_text(_point(draw, 0.3), _default_frame(draw, _random_rotation(draw)), draw)
                  for _ in range(2)]
        joints.append(f'[[joints]]\nname = "JE{label}"\ntype = "{jtype}"\nparent = {parent}\nchild = {label}\n'
                      f'coordinates = ["qe{label}"]\nparent_frame = {frames[0]}\nchild_frame = {frames[1]}\n')
        leader = draw.rng.choice(leaders)
        ratio = draw.sign() * draw.decimal(0.3, 3, 1) if jtype == "R" else draw.sign() * draw.decimal(0.05, 0.4, 2)
        offset = draw.decimal(-0.2, 0.2, 2) if jtype == "R" else draw.decimal(-0.05, 0.05, 2)
        couplings.append((f"qe{label}", leader, ratio, offset))
    name = f"gen_coupled_{'parallelogram' if parallelogram else 'four_bar'}_{seed}" + ("_tree" if tree else "")
    text = text.replace(f"gen_four_bar_{seed}", name)
    head, tail = text.split("[coordinates]")
    if tree:
        head = re.sub(r'\[\[joints\]\]\nname = "JC"\n(?:(?!\n\n).)*\n', "", head, flags=re.S)
        resolved = {"qb": Fraction(-1), "qd": Fraction(1)}          # qb = -qa, qd = qa
        couplings = [(c, "qa", r * resolved[l], o) if l in resolved else (c, l, r, o) for c, l, r, o in couplings]
        couplings = [("qb", "qa", Fraction(-1), Fraction(0)), ("qd", "qa", Fraction(1), Fraction(0))] + couplings
    coupled = "".join(f'\n[[couplings]]\ncoordinate = "{c}"\nleader = "{l}"\nratio = "{exact_text(r)}"\n'
                      f'offset = "{exact_text(o)}"\n' for c, l, r, o in couplings)
    return head + "\n".join(bodies + joints) + "\n[coordinates]" + tail + coupled


def _found(match: re.Match[str] | None) -> re.Match[str]:
    """A match in text :func:`four_bar` wrote (always there)."""
    assert match is not None
    return match


def _random_turn_about_z(draw: _Draw) -> Rows:
    """A rotation about z by a rational-cosine angle (or none)."""
    if draw.rng.random() < 0.4:
        return ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    a, b, c = draw.rng.choice(_PYTHAGOREAN)
    co, si = Fraction(a, c) * draw.sign(), Fraction(b, c) * draw.sign()
    return ((co, -si, 0), (si, co, 0), (0, 0, 1))


def ladder(n: int, seed: int = 1, samples: int = 100) -> str:
    """n random four-bars in series (TOML text): four-bar k is :func:`four_bar` (seed
    ``seed + k``) with four-bar k-1's rocker as its ground, so every loop after the first
    stands on a moving body; each crank angle is independent."""
    bodies, joints, trajectory = [], [], []
    gravity = None
    for k in range(n):
        text = four_bar(seed + k, samples=samples)
        gravity = gravity or _found(re.search(r"^gravity = .*$", text, re.M)).group(0)
        base = 0 if k == 0 else 3 * k

        def label(b: int, k: int = k, base: int = base) -> int:
            return base if b == 0 else 3 * k + b

        for block in re.findall(r"\[\[bodies\]\]\n(?:(?!\n\n).)*", text, re.S):
            bodies.append(re.sub(r"label = (\d+)", lambda m: f"label = {label(int(m.group(1)))}", block))
        for block in re.findall(r"\[\[joints\]\]\n(?:(?!\n\n).)*", text, re.S):
            block = re.sub(r'name = "(\w+)"', lambda m: f'name = "{m.group(1)}{k}"', block)
            block = re.sub(r"(parent|child) = (\d+)", lambda m: f"{m.group(1)} = {label(int(m.group(2)))}", block)
            block = re.sub(r'coordinates = \["(\w+)"\]', lambda m: f'coordinates = ["{m.group(1)}{k}"]', block)
            joints.append(block)
        motion = _found(re.search(r'qa = "([^"]*)"', text)).group(1)
        trajectory.append(f'qa{k} = "{motion}"')
    independent = ", ".join(f'"qa{k}"' for k in range(n))
    return "\n\n".join([f'[mechanism]\nname = "ladder_{n}"\ntitle = "{n} four-bars in series"\n{gravity}']
                       + bodies + joints
                       + [f"[coordinates]\nindependent = [{independent}]",
                          f'[trajectory]\nt_start = "0"\nt_end = "10"\nsamples = {samples}\n'
                          f"q = {{ {', '.join(trajectory)} }}"]) + "\n"
