"""Two shortcuts of the expression machinery must not change a single result (issue 47):

- the parser makes ``sin``/``cos`` of a plain angle (rationals and t, no minus sign to move
  out) without sympy's evaluation: the expression must equal the one sympy's evaluation gives;
- :func:`baseparams.numeric.backends.evaluate` runs a program built once per expression: the
  same backend calls, in the same order, as walking the sympy tree each time (the walk is kept
  here as the reference), so every backend's numbers are the same to the last bit.
"""

import random
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy

from baseparams.io.loader import load_mechanism
from baseparams.model import expressions
from baseparams.model.expressions import parse_expression
from baseparams.numeric import backends
from baseparams.plugins.urdf.reader import default_trajectory

DATA = Path(__file__).parent / "data" / "urdf"
T = sympy.Symbol("t")


def _evaluated(text, monkeypatch, names=()):
    """``text`` parsed with sympy's own evaluation of every sin and cos (the shortcut off)."""
    with monkeypatch.context() as m:
        m.setattr(expressions, "_plain_angle", lambda arg: False)
        return parse_expression(text, names, time=True)


ANGLES = ["t", "3*t/2", "3*t/2 + 13/10", "27/10*t + 17/10", "t*t + 1", "2*(t + 1/3)", "t - 1", "1 - t",
          "-t", "-3*t/2 + 1/5", "-(t + 1)", "t - t", "0*t + 1/2", "1/2", "0", "pi*t", "2*pi + t", "t + pi/2",
          "sqrt(2)*t", "t**2 - 3*t", "-t**2 + 3*t", "(t - 1)*(t + 1)", "t/3 - 7/3", "7/3 - t/3", "L*t", "-L*t"]


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("function", ["sin", "cos"])
def test_a_plain_angle_gives_the_expression_sympy_evaluates(angle, function, monkeypatch):
    text = f"1/4*{function}({angle}) + {function}(2*({angle}))"
    fast = parse_expression(text, ("L",), time=True)
    assert fast == _evaluated(text, monkeypatch, ("L",))
    assert sympy.srepr(fast) == sympy.srepr(_evaluated(text, monkeypatch, ("L",)))


def test_random_fourier_series_parse_as_sympy_evaluates_them(monkeypatch):
    rng = random.Random(47)
    for _ in range(200):
        terms = []
        for _ in range(rng.randint(1, 4)):
            a, f, p = (Fraction(rng.randint(-300, 300), rng.choice([1, 10, 100, 1000])) for _ in range(3))
            terms.append(f"{a}*{rng.choice(['sin', 'cos'])}({f}*t + {p})")
        text = " + ".join(terms)
        fast = parse_expression(text, time=True)
        assert sympy.srepr(fast) == sympy.srepr(_evaluated(text, monkeypatch)), text


@pytest.mark.parametrize("urdf", sorted(DATA.glob("*.urdf")), ids=lambda p: p.stem)
def test_the_urdf_default_trajectories_are_the_expressions_sympy_evaluates(urdf, monkeypatch):
    texts = {}

    def keep(*args):
        texts.update(default_trajectory(*args))
        return texts

    with monkeypatch.context() as m:
        m.setattr("baseparams.plugins.urdf.reader.default_trajectory", keep)
        mech = load_mechanism(str(urdf))
    assert texts and mech.trajectory is not None
    for name, text in texts.items():
        assert sympy.srepr(mech.trajectory.expressions[name]) == sympy.srepr(_evaluated(text, monkeypatch))


# ----- evaluate: one program per expression, the same calls ------------------------------------
def _walk(backend, expr, env):
    """The tree walk that the programs replace (baseparams before issue 47), as the reference."""
    if expr.is_Rational:
        return backend.rational(Fraction(int(expr.p), int(expr.q)))
    if expr.is_Symbol:
        return env[expr.name]
    if expr is sympy.pi:
        return backend.pi()
    args = [] if expr.is_Pow else [_walk(backend, a, env) for a in expr.args]
    if expr.is_Add or expr.is_Mul:
        total = args[0]
        for a in args[1:]:
            total = total + a if expr.is_Add else total * a
        return total
    if expr.is_Pow:
        base, exponent = expr.args
        b = _walk(backend, base, env)
        if not (exponent.is_Integer or (exponent.is_Rational and exponent.q == 2)):
            raise ValueError(f"power {exponent} is not supported in backend evaluation")
        doubled = int(exponent * 2)
        n = doubled // 2 if doubled % 2 == 0 else (doubled - 1) // 2
        result = backend.rational(Fraction(1))
        for _ in range(abs(n)):
            result = result * b
        if n < 0:
            result = backend.rational(Fraction(1)) / result
        return result * backend.sqrt(b) if doubled % 2 else result
    if isinstance(expr, (sympy.sin, sympy.cos)):
        return backend.cos_sin(args[0])[1 if isinstance(expr, sympy.sin) else 0]
    if isinstance(expr, sympy.exp):
        return backend.exp(args[0])
    raise ValueError(f"cannot evaluate {expr} in backend {backend.name}")


class Recorder:
    """A backend of symbolic "numbers" that logs every call and operation in order: two
    evaluations that make the same log did the same arithmetic in the same order."""

    name = "recorder"

    def __init__(self):
        self.log = []

    def _made(self, what):
        self.log.append(what)
        return Logged(self, what)

    def rational(self, value):
        return self._made(f"q{value}")

    def pi(self):
        return self._made("pi")

    def cos_sin(self, x):
        return self._made(f"cos({x.what})"), self._made(f"sin({x.what})")

    def sqrt(self, x):
        return self._made(f"sqrt({x.what})")

    def exp(self, x):
        return self._made(f"exp({x.what})")


class Logged:
    def __init__(self, backend, what):
        self.backend, self.what = backend, what

    def _op(self, symbol, other):
        return self.backend._made(f"({self.what}{symbol}{other.what})")

    def __add__(self, other):
        return self._op("+", other)

    def __mul__(self, other):
        return self._op("*", other)

    def __truediv__(self, other):
        return self._op("/", other)


def _random_expression(rng, depth=0):
    x, y = sympy.Symbol("x"), sympy.Symbol("y")
    leaves = [T, x, y, sympy.pi, sympy.Rational(rng.randint(-9, 9), rng.randint(1, 9)), sympy.Integer(rng.randint(2, 5))]
    if depth > 3 or rng.random() < 0.3:
        return rng.choice(leaves)
    kind = rng.choice(["add", "mul", "pow", "sin", "cos", "exp", "sqrt"])
    a, b = _random_expression(rng, depth + 1), _random_expression(rng, depth + 1)
    return {"add": lambda: a + b, "mul": lambda: a * b, "pow": lambda: a ** rng.choice([2, 3, -1, -2, sympy.Rational(1, 2),
                                                                                        sympy.Rational(-3, 2)]),
            "sin": lambda: sympy.sin(a), "cos": lambda: sympy.cos(a), "exp": lambda: sympy.exp(a),
            "sqrt": lambda: sympy.sqrt(a)}[kind]()


def test_programs_make_the_calls_of_the_tree_walk_in_its_order():
    rng = random.Random(7)
    checked = 0
    for _ in range(400):
        expr = _random_expression(rng)
        walked, built = Recorder(), Recorder()
        env_w = {n: Logged(walked, n) for n in ("t", "x", "y")}
        env_b = {n: Logged(built, n) for n in ("t", "x", "y")}
        try:
            expected = _walk(walked, expr, env_w).what
        except ValueError as exc:
            with pytest.raises(ValueError) as info:
                backends.evaluate(built, expr, env_b)
            assert str(info.value) == str(exc)
        else:
            assert backends.evaluate(built, expr, env_b).what == expected
            checked += 1
        assert built.log == walked.log, expr
    assert checked > 200


def test_programs_give_the_same_arb_and_float_bits_as_the_walk():
    rng = random.Random(11)
    ball = backends.Arb(40)
    for _ in range(100):
        expr = _random_expression(rng) + T
        env64 = {"t": 0.731, "x": 1.25, "y": 2.5}
        with ball.activate():
            env = {"t": ball.rational(Fraction(731, 1000)), "x": ball.rational(Fraction(5, 4)),
                   "y": ball.rational(Fraction(5, 2))}
            try:
                expected = _walk(ball, expr, env)
            except (ValueError, ZeroDivisionError):
                continue
            got = backends.evaluate(ball, expr, env)
        assert got.mid().str(60, radius=False) == expected.mid().str(60, radius=False)
        assert got.rad() == expected.rad()
        with np.errstate(all="ignore"):
            try:
                expected64 = _walk(backends.Float64(), expr, env64)
            except (ValueError, ZeroDivisionError):
                continue
            got64 = backends.evaluate(backends.Float64(), expr, env64)
        assert repr(float(got64)) == repr(float(expected64)) or (got64 != got64 and expected64 != expected64)


def test_a_missing_symbol_and_an_unknown_function_are_named():
    with pytest.raises(KeyError, match="no value for symbol x"):
        backends.evaluate(backends.Float64(), T + sympy.Symbol("x"), {"t": 1.0})
    with pytest.raises(ValueError, match="cannot evaluate E in backend float64"):
        backends.evaluate(backends.Float64(), sympy.E * T, {"t": 1.0})
    with pytest.raises(ValueError, match="power 1/3 is not supported"):
        backends.evaluate(backends.Float64(), T ** sympy.Rational(1, 3), {"t": 1.0})


# ----- names: sympy's parser only where its namespace could read a name otherwise ------------
def test_every_name_sympy_reads_as_something_else_is_still_refused():
    import builtins
    import keyword
    import string

    from baseparams.model import builder
    rng = random.Random(3)
    names = set(dir(sympy)) | set(dir(builtins)) | {"x", "L", "q1", "E", "I", "N", "S", "Q", "O", "beta", "oo", "nan"}
    names |= {rng.choice(string.ascii_letters + "_") + "".join(rng.choice(string.ascii_letters + string.digits + "_")
                                                               for _ in range(rng.randint(0, 4))) for _ in range(3000)}
    checked = 0
    for name in sorted(names):
        if not builder.IDENT_RE.match(name) or keyword.iskeyword(name):
            continue
        try:
            read_otherwise = sympy.parse_expr(name) != sympy.Symbol(name)
        except Exception:                   # noqa: BLE001 - a parser failure is "otherwise" too
            read_otherwise = True
        if read_otherwise:
            assert builder._sympy_may_read(name), name
            checked += 1
    assert checked > 500
    assert builder.name_problem("q_torso") is None and not builder._sympy_may_read("q_torso")
    assert "means something else to sympy" in builder.name_problem("E")
