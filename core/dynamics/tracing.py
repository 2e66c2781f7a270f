"""Tracing numbers: the generic kinematics, run once on :class:`Sym` values, records its
operations into a :class:`Graph` instead of computing them.

Why a module of its own: recording (with its folding of exact zeros, ones and negations, and
its sharing of repeated subexpressions) is one job; :mod:`.codegen` writes and runs code from
what is recorded here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import sympy

from baseparams.dynamics.regressor import generic_tree_regressor
from baseparams.kinematics.tree import TreeKinematics
from baseparams.numeric.backends import Symbolic

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism

Operand = int | tuple[str, Any] | None     # a node id, ("c", exact constant) or ("i", input name)

# ----- tracing numbers ------------------------------------------------------------------------
class Graph:
    """Recorded operations: node i is ``ops[i] = (op, a, b)``; an operand is a node id (int)
    or ``("c", value)``, an exact constant (sympy number or int) of the geometry."""

    def __init__(self) -> None:
        self.ops: list[tuple[Any, ...]] = []
        self._memo: dict[tuple[Any, ...], Sym] = {}

    def node(self, op: str, a: Any = None, b: Any = None) -> Sym:
        x, y = _operand(a), _operand(b)
        if op in ("add", "mul") and (isinstance(x, tuple) or (isinstance(y, int) and isinstance(x, int) and y < x)):
            x, y = y, x                       # commutative: one node for a+b and b+a, node first
        key = (op, x, y)
        found = self._memo.get(key)
        if found is None:
            found = Sym(self, len(self.ops))
            self.ops.append(key)
            self._memo[key] = found
        return found

    def input(self, name: tuple[str, int]) -> Sym:
        return self.node("in", ("i", name))


def _operand(v: Any) -> Operand:
    if v is None or isinstance(v, tuple):
        return v
    return v.index if isinstance(v, Sym) else ("c", sympy.sympify(v))


def _const(v: Any) -> bool:
    return not isinstance(v, Sym)


def _negated(v: Any) -> Sym | None:
    """The x of ``v = -x`` (a traced negation), else None: negations fold into + and -."""
    if isinstance(v, Sym):
        op = v.graph.ops[v.index]
        if op[0] == "neg":
            return Sym(v.graph, op[1])
    return None


def _graph(a: Any, b: Any) -> Graph:
    return (a if isinstance(a, Sym) else b).graph


def _add(a: Any, b: Any) -> Any:
    if _const(a) and _const(b):
        return a + b
    if _const(a) and a == 0:
        return b
    if _const(b) and b == 0:
        return a
    if _negated(b) is not None:
        return _sub(a, _negated(b))
    if _negated(a) is not None:
        return _sub(b, _negated(a))
    return _graph(a, b).node("add", a, b)


def _sub(a: Any, b: Any) -> Any:
    if _const(a) and _const(b):
        return a - b
    if _const(b) and b == 0:
        return a
    if _const(a) and a == 0:
        return _neg(b)
    if _negated(b) is not None:
        return _add(a, _negated(b))
    return _graph(a, b).node("sub", a, b)


def _mul(a: Any, b: Any) -> Any:
    if _const(a) and _const(b):
        return a * b
    if _const(a):
        a, b = b, a
    if _const(b):
        if b == 0:
            return b * 0
        if b == 1:
            return a
        if b == -1:
            return _neg(a)
        if _negated(a) is not None:
            return _mul(_negated(a), -b)
        return a.graph.node("mul", a, b)
    if _negated(a) is not None and _negated(b) is not None:
        return _mul(_negated(a), _negated(b))
    return a.graph.node("mul", a, b)


def _div(a: Any, b: Any) -> Any:
    if _const(a) and _const(b):
        return a / b
    if _const(b) and b == 1:
        return a
    if _const(b):
        return _mul(a, 1 / sympy.sympify(b))
    return _graph(a, b).node("div", a, b)


def _neg(a: Any) -> Any:
    if _const(a):
        return -a
    if _negated(a) is not None:
        return _negated(a)
    return a.graph.node("neg", a)


def _reflected(op: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
    """``other op self`` as a method of ``self`` (Python's reflected operators)."""
    return lambda self, other: op(other, self)


class Sym:
    """A traced value: arithmetic records a node of its :class:`Graph`."""

    __slots__ = ("graph", "index")

    def __init__(self, graph: Graph, index: int) -> None:
        self.graph = graph
        self.index = index

    __add__, __radd__ = _add, _reflected(_add)
    __sub__, __rsub__ = _sub, _reflected(_sub)
    __mul__, __rmul__ = _mul, _reflected(_mul)
    __truediv__, __rtruediv__ = _div, _reflected(_div)
    __neg__ = _neg

    def __pos__(self) -> Sym:
        return self

    def cos(self) -> Any:
        inner = _negated(self)
        return self.graph.node("cos", self if inner is None else inner)

    def sin(self) -> Any:
        inner = _negated(self)
        return self.graph.node("sin", self) if inner is None else _neg(self.graph.node("sin", inner))


class _Tracing(Symbolic):
    """Exact sympy geometry (so a constant is exact in every arithmetic the code runs in);
    angles are traced."""

    def cos_sin(self, x: Any) -> tuple[Any, Any]:
        if isinstance(x, Sym):
            return x.cos(), x.sin()
        return super().cos_sin(x)


# ----- what is traced ---------------------------------------------------------------------
@dataclass(frozen=True)
class Kernel:
    """One generated function: its inputs (subsets of q, qd, qdd) and the arrays it fills,
    each ``name -> (trailing shape, [(index, traced value)])``."""
    name: str
    inputs: tuple[str, ...]
    outputs: dict[str, tuple[tuple[int, ...], list[tuple[tuple[int, ...], Any]]]]


PARTS = ("regressor", "closure")   # what can be generated: K_tree; the loop-closure terms


def trace(mechanism: Mechanism, parts: Sequence[str] = PARTS) -> tuple[Graph, list[Kernel]]:
    """Run the generic tree regressor (``"regressor"``) and, for a closed loop, the closure
    equations with their Jacobian and bias (``"closure"``, :meth:`TreeKinematics.closure`)
    of ``mechanism`` on tracing numbers: the graph and the kernels to write from it."""
    kin = TreeKinematics(mechanism, _Tracing())
    g = Graph()
    n = kin.n
    q, qd, qdd = ([g.input((name, i)) for i in range(n)] for name in ("q", "qd", "qdd"))
    states = kin.forward(q, qd)
    kernels: list[Kernel] = []
    if "regressor" in parts:
        rows = generic_tree_regressor(kin, states, qdd)
        p = 10 * len(mechanism.body_labels)
        kernels.append(Kernel("_tree_regressor", ("q", "qd", "qdd"), {
            "K": ((n, p), [((k, j), v) for k, row in enumerate(rows) for j, v in enumerate(row)])}))
    if "closure" in parts and mechanism.loops:
        values, jac, _ = kin.closure(kin.forward(q), q=q)
        m = len(values)
        kernels.append(Kernel("_closure", ("q",), {
            "phi": ((m,), [((i,), v) for i, v in enumerate(values)]),
            "jac": ((m, n), [((i, j), v) for i, row in enumerate(jac) for j, v in enumerate(row)])}))
        _, _, bias = kin.closure(states, want_bias=True, q=q)
        kernels.append(Kernel("_closure_bias", ("q", "qd"), {
            "gamma": ((m,), [((i,), v) for i, v in enumerate(bias)])}))
    return g, kernels
