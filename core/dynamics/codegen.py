"""The float64 regressor (and loop-closure terms) as straight-line numpy code, generated once per mechanism.

Why: the generic kinematics (:mod:`baseparams.kinematics.tree`, :mod:`.regressor`) runs on
any number type, so over a batch of samples it makes thousands of small numpy calls on
Python lists, most of them multiplying by the exact zeros and ones of the joint frames.
Here the same generic code runs once on *tracing* numbers (:mod:`.tracing`) that record each
operation instead of computing it; zeros and ones fold away, repeated subexpressions are
shared (hash-consing, the common subexpression elimination sympy.cse would do, without
sympy's cost on large chains), dead terms are dropped, and what is left is written out as
one Python function of numpy arrays, each operation writing into a preallocated row
(:func:`_numpy_kernel` says why), evaluated over chunks of the batch.

Because the recorded operations are the generic code's own, in the same order, the
generated regressor equals the generic one to the last bit except where a folded ``x * 1``
or ``x + 0`` skipped a rounding-free operation; tests/test_codegen.py checks it to 1e-12
relative on generated chains, trees and loops, and against Pinocchio.

The source is standalone (numpy only): ``baseparams export MECH --to python`` writes it
(with the base regressor) as a module users import; :func:`compiled` execs the same text.
"""

from __future__ import annotations

import functools
import marshal
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np
import sympy
from flint import arb

from baseparams.dynamics import codecache
from baseparams.dynamics.regressor import tree_regressor as tree_regressor_rows_generic
from baseparams.dynamics.tracing import PARTS, Graph, Kernel, Sym, trace
from baseparams.kinematics.tree import TreeKinematics
from baseparams.numeric.backends import Arb, Backend, Exact, Float64

if TYPE_CHECKING:
    from baseparams.dynamics.closure import ClosureStructure
    from baseparams.kinematics.tree import BodyState
    from baseparams.model.mechanism import Mechanism
    from baseparams.solvers.result import BaseParameterResult

CHUNK = 8192          # samples per pass of the numpy code at most, ...
BUDGET = 2 ** 26      # ... its buffers and temporaries within 64 MB (fewer samples per pass on a big mechanism)


# ----- writing the code -----------------------------------------------------------------------
_BINARY = {"add": ("+", "add"), "sub": ("-", "subtract"), "mul": ("*", "multiply"), "div": ("/", "divide")}
_UNARY = {"neg": "negative", "cos": "cos", "sin": "sin"}


@dataclass(frozen=True)
class Layout:
    """Where a kernel's output array gets its entries: ``slots[j]`` (a flat index into the
    array of trailing ``shape``) is row j of the buffer the kernel fills, computed by node
    ``nodes[j]``; ``constants`` are (flat index, exact value) pairs, the same for every
    sample; every other entry is exactly zero."""
    shape: tuple[int, ...]
    slots: tuple[int, ...]
    nodes: tuple[int, ...]
    constants: tuple[tuple[int, Any], ...]


def layouts(kernel: Kernel) -> dict[str, Layout]:
    out: dict[str, Layout] = {}
    for name, (shape, entries) in kernel.outputs.items():
        slots: list[int] = []
        nodes: list[int] = []
        constants: list[tuple[int, Any]] = []
        for index, v in entries:
            flat = int(np.ravel_multi_index(index, shape))
            if isinstance(v, Sym):
                slots.append(flat)
                nodes.append(v.index)
            elif v != 0:
                constants.append((flat, sympy.sympify(v)))
        out[name] = Layout(tuple(shape), tuple(slots), tuple(nodes), tuple(constants))
    return out


@dataclass
class Constants:
    """The exact constants the kernels of one module read, numbered in order of use."""
    values: list[Any] = field(default_factory=list)
    _index: dict[Any, int] = field(default_factory=dict)

    def ref(self, value: Any) -> str:
        k = self._index.get(value)
        if k is None:
            k = self._index[value] = len(self.values)
            self.values.append(value)
        return f"C[{k}]"


def kernel_source(graph: Graph, kernel: Kernel, constants: Constants, scalar: bool = False) -> str:
    """``def name(<inputs>, C, <buffers>)``: straight-line code of the kernel.

    numpy flavour (:func:`_numpy_kernel`): inputs are (coordinates, chunk) arrays, row j of
    each buffer receives its layout's slot j, and one more argument ``W``, a (work rows,
    chunk) array, holds the temporaries. ``scalar`` flavour (ball or rational arithmetic,
    one state per call): inputs are sequences of numbers, buffers are lists, ``F`` is the
    backend's (cos, sin). ``C``: the constants' values in the arithmetic of the call.

    Only nodes an output needs are written; a register is reused once its value's last
    reader has run, so a long chain does not keep every temporary alive."""
    if not scalar:
        return _numpy_kernel(graph, kernel, constants)[0]
    lines = [f"def {kernel.name}({', '.join(kernel.inputs + ('C', 'F') + tuple(kernel.outputs))}):"]
    free: list[str] = []
    reg: dict[int, str] = {}
    count = 0
    for i, (kind, a, b), rows, ends, read_later in _schedule(graph, kernel, lambda name, row: f"{name}[{row}]"):
        if kind == "in":
            expr = f"{a[1][0]}[{a[1][1]}]"
        else:
            ra = reg[a] if isinstance(a, int) else constants.ref(a[1])
            rb = reg[b] if isinstance(b, int) else constants.ref(b[1]) if b is not None else None
            if kind in _BINARY:
                expr = f"{ra} {_BINARY[kind][0]} {rb}"
            elif kind == "neg":
                expr = f"-{ra}"
            else:
                expr = f"F[{('cos', 'sin').index(kind)}]({ra})"
            for x in ends:
                free.append(reg.pop(x))
        if free:
            target = free.pop()
        else:
            target, count = f"r{count}", count + 1
        reg[i] = target
        lines.append(f"    {target} = {expr}")
        lines.extend(f"    {row} = {target}" for row in rows)
        if not read_later:
            free.append(reg.pop(i))
    if len(lines) == 1:
        lines.append("    pass")
    return "\n".join(lines) + "\n"


def _liveness(graph: Graph, kernel: Kernel) -> tuple[dict[int, list[tuple[str, int]]], list[bool], dict[int, int]]:
    """Which buffer rows each node fills (``node -> [(buffer, row)]``), which nodes an
    output needs, and each needed node's last reader."""
    ops = graph.ops
    writes: dict[int, list[tuple[str, int]]] = {}
    for name, layout in layouts(kernel).items():
        for row, node in enumerate(layout.nodes):
            writes.setdefault(node, []).append((name, row))
    live = [False] * len(ops)
    stack = list(writes)
    while stack:
        i = stack.pop()
        if live[i]:
            continue
        live[i] = True
        stack.extend(x for x in _operands(ops[i]) if not live[x])
    last: dict[int, int] = {}
    for i, op in enumerate(ops):
        if live[i]:
            for x in _operands(op):
                last[x] = i
    return writes, live, last


def _numpy_kernel(graph: Graph, kernel: Kernel, constants: Constants) -> tuple[str, int]:
    """The numpy flavour's source and its number of work rows.

    Why this form: at a thousand samples a numpy operation's dispatch costs about as much
    as its arithmetic (docs/performance.md), so the call itself matters. Every operation writes into a
    preallocated row (``_multiply(a, b, w3)``: a ufunc with a positional ``out``) instead of
    allocating its result; every value an output needs is computed straight into its row
    of the output buffer; constants are 0-d arrays (numpy's slower path for a Python
    float scalar is skipped). Rows of ``W`` (temporaries), of the buffers and the inputs
    are bound to local names once per call. A work row is reused once its value's last
    reader has run; an input or output row never is. The values are bit for bit those of
    the allocating form (the same operations on the same operands).

    Measured and not kept (``benchmarks/bench_regressor.py --levels``): grouping independent
    operations of one kind into one call on stacked rows (level scheduling: 78 calls and
    118 gathers instead of 1 800 calls for the PUMA 560) was 1.6-3.4x slower than this form,
    since most operands must be gathered (a copy per row, as dear as the call it saves);
    writing the outputs straight into the samples-first result
    (strided rows) gained 1-13% up to 1 000 samples and lost 1.3-1.6x beyond."""
    body: list[str] = []
    free: list[str] = []
    loc: dict[int, str] = {}
    work = 0
    for i, (kind, a, b), rows, ends, read_later in _schedule(graph, kernel, lambda name, row: f"{name}_{row}"):
        if kind == "in":
            loc[i] = f"i{i}"
            body.append(f"    i{i} = {a[1][0]}[{a[1][1]}]")
            target = loc[i]
        else:
            args = [loc[x] if isinstance(x, int) else constants.ref(x[1]) for x in (a, b) if x is not None]
            for x in ends:
                if loc[x].startswith("w"):
                    free.append(loc[x])
            if rows:
                target, rows = rows[0], rows[1:]
            elif free:
                target = free.pop()
            else:
                target, work = f"w{work}", work + 1
            loc[i] = target
            name = _BINARY[kind][1] if kind in _BINARY else _UNARY[kind]
            body.append(f"    _{name}({', '.join(args)}, {target})")
        body.extend(f"    {row}[...] = {target}" for row in rows)
        if not read_later and target.startswith("w"):
            free.append(target)
    head = [f"def {kernel.name}({', '.join(kernel.inputs + ('C',) + tuple(kernel.outputs) + ('W',))}):"]
    for name, layout in layouts(kernel).items():
        if layout.slots:
            names = [f"{name}_{row}" for row in range(len(layout.slots))]
            head.append(f"    {', '.join(names)}, = {name}")
    if work:
        head.append(f"    {', '.join(f'w{k}' for k in range(work))}, = W")
    lines = head + body
    if len(lines) == 1:
        lines.append("    pass")
    return "\n".join(lines) + "\n", work


def _schedule(graph: Graph, kernel: Kernel, row_name: Callable[[str, int], str],
              ) -> Iterator[tuple[int, tuple[Any, ...], list[str], list[int], bool]]:
    """The nodes an output of ``kernel`` needs, in order, for both code flavours: (node,
    its op, the output rows it fills as ``row_name`` writes them, the operands it is the
    last reader of, whether a later node reads it)."""
    writes, live, last = _liveness(graph, kernel)
    for i, op in enumerate(graph.ops):
        if live[i]:
            ends = [x for x in set(_operands(op)) if last[x] == i]
            yield i, op, [row_name(name, row) for name, row in writes.get(i, [])], ends, i in last


def _operands(op: tuple[Any, ...]) -> list[int]:
    return [x for x in op[1:] if isinstance(x, int)] if op[0] != "in" else []


def _float_literal(value: Any) -> str:
    v = float(sympy.N(value, 30))
    if not math.isfinite(v):
        raise ValueError(f"non-finite constant {value} in the traced code")
    return repr(v)


# ----- the module -----------------------------------------------------------------------------
_RUNTIME = '''
_add, _subtract, _multiply, _divide = _np.add, _np.subtract, _np.multiply, _np.divide
_negative, _cos, _sin = _np.negative, _np.cos, _np.sin


def _columns(x, n):
    """(..., n) -> ((n, samples) contiguous, leading shape)."""
    x = _np.asarray(x, dtype=float)
    if x.shape[-1:] != (n,):
        raise ValueError(f"expected an array with last axis of length {n}, got shape {x.shape}")
    lead = x.shape[:-1]
    return _np.ascontiguousarray(x.reshape(-1, n).T), lead


def _evaluate(kernel, inputs):
    """Run ``kernel`` (a name in _LAYOUTS) over (coordinates, samples) ``inputs`` chunk by
    chunk; one array (samples, *shape) per output, filled from the kernel's buffers (rows of
    one array with the temporaries).

    A chunk is as many samples as fit the buffers and temporaries in _BUDGET bytes, at most
    _CHUNK: each numpy call costs about 1 us whatever its length, so longer rows pay even
    past the caches (measured: docs/performance.md)."""
    layouts, work = _LAYOUTS[kernel], _WORK[kernel]
    function = globals()[kernel]
    count = inputs[0].shape[1]
    rows = sum(len(slots) for _, slots, _ in layouts) + work
    chunk = max(256, min(_CHUNK, _BUDGET // (8 * max(rows, 1))))
    width = min(count, chunk)
    space = _np.empty((rows, width))
    outs, buffers, columns, at = [], [], [], 0
    for shape, slots, constants in layouts:
        size = 1
        for s in shape:
            size *= s
        out = _np.zeros((count, size))
        for index, value in constants:
            out[:, index] = value
        outs.append(out)
        buffers.append(space[at:at + len(slots)])
        columns.append(_np.array(slots, dtype=_np.intp))
        at += len(slots)
    scratch = space[at:]
    for start in range(0, count, chunk):
        stop = min(start + chunk, count)
        views = [b[:, :stop - start] for b in buffers]
        function(*[x[:, start:stop] for x in inputs], _C, *views, scratch[:, :stop - start])
        for out, view, index in zip(outs, views, columns):
            # samples-last buffer to samples-first array, in blocks that stay in cache
            for block in range(0, stop - start, 256):
                end = min(block + 256, stop - start)
                if len(index):
                    out[start + block:start + end, index] = view[:, block:end].T
    return [out.reshape((count,) + shape) for out, (shape, _, _) in zip(outs, layouts)]
'''

_OPEN_API = '''

def tree_regressor(q, qd, qdd):
    """K of the tree coordinates, (..., n, p), for positions, velocities, accelerations
    q, qd, qdd of shape (..., n) (coordinate order: COORDINATES)."""
    (x, lead), (xd, _), (xdd, _) = (_columns(v, len(COORDINATES)) for v in _np.broadcast_arrays(q, qd, qdd))
    return _evaluate("_tree_regressor", [x, xd, xdd])[0].reshape(
        lead + (len(COORDINATES), len(PARAMETERS)))
'''

_CLOSED_API = '''

def closure(q):
    """The loop-closure equations at tree coordinates q (..., n): (phi (..., m), jacobian (..., m, n))."""
    x, lead = _columns(q, len(COORDINATES))
    phi, jac = _evaluate("_closure", [x])
    return phi.reshape(lead + phi.shape[1:]), jac.reshape(lead + jac.shape[1:])


def closure_bias(q, qd):
    """gamma (..., m): on the constraint manifold the accelerations satisfy J qdd + gamma = 0."""
    (x, lead), (xd, _) = (_columns(v, len(COORDINATES)) for v in _np.broadcast_arrays(q, qd))
    gamma, = _evaluate("_closure_bias", [x, xd])
    return gamma.reshape(lead + gamma.shape[1:])


def projection(q):
    """R (..., n, f) with qd = R zd at tree coordinates q on the constraint manifold
    (z: the INDEPENDENT coordinates): identity rows for z, -J_d^-1 J_z for the others."""
    _, jac = closure(q)
    jac = jac[..., list(EQUATIONS), :]
    jd, jz = jac[..., list(DEPENDENT)], jac[..., list(INDEPENDENT)]
    r = _np.zeros(jac.shape[:-2] + (len(COORDINATES), len(INDEPENDENT)))
    r[..., list(INDEPENDENT), range(len(INDEPENDENT))] = 1.0
    r[..., list(DEPENDENT), :] = -_np.linalg.solve(jd, jz)
    return r
'''


def module_source(mechanism: Mechanism, parts: Sequence[str] = PARTS, header: str = "", extra: str = "") -> str:
    """The standalone module (numpy only) of ``mechanism``'s float64 ``parts``: constants,
    the generated kernels, ``tree_regressor`` and, for a closed loop, ``closure``,
    ``closure_bias`` and ``projection``. ``header`` opens the module docstring; ``extra``
    (Python source) is appended (the export adds ``regressor`` and ``base_regressor``)."""
    graph, kernels = _traced(mechanism, tuple(parts))
    structure = _structure(mechanism)
    constants = Constants()
    text = [f'"""{header or "The float64 regressor of " + mechanism.name + ", generated by baseparams."}\n"""',
            "", "import numpy as _np", "",
            f"MECHANISM = {mechanism.name!r}",
            f"COORDINATES = {tuple(mechanism.coordinates)!r}   # tree coordinates: the last axis of q, qd, qdd",
            f"PARAMETERS = {tuple(mechanism.parameters)!r}",
            f"INDEPENDENT = {tuple(structure.independent)!r}   # indices into COORDINATES",
            f"DEPENDENT = {tuple(structure.dependent)!r}",
            f"EQUATIONS = {tuple(structure.rows)!r}   # the independent closure equations",
            f"_CHUNK, _BUDGET = {CHUNK}, {BUDGET}   # samples per pass at most; bytes of buffers and temporaries",
            ""]
    table, work = {}, {}
    for kernel in kernels:
        source, work[kernel.name] = _numpy_kernel(graph, kernel, constants)
        text.append(source)
        table[kernel.name] = [(lay.shape, lay.slots, tuple((i, float(sympy.N(v, 30))) for i, v in lay.constants))
                              for lay in layouts(kernel).values()]
    text.append(f"_LAYOUTS = {table!r}")
    text.append(f"_WORK = {work!r}   # rows of temporaries per kernel")
    text.append("_C = tuple(_np.array(v) for v in ("
                + "".join(f"{_float_literal(v)}, " for v in constants.values) + "))   # geometry constants, 0-d arrays")
    text.append(_RUNTIME)
    if "regressor" in parts:
        text.append(_OPEN_API)
    if "closure" in parts and mechanism.loops:
        text.append(_CLOSED_API)
    if extra:
        text.append(extra)
    return "\n".join(text) + "\n"


def _structure(mechanism: Mechanism) -> ClosureStructure:
    # the evaluator's choice of independent coordinates and closure equations; imported
    # here, not at the top, because the evaluator imports this module
    from baseparams.dynamics.closure import closure_structure
    return closure_structure(mechanism)


# ----- in this process ------------------------------------------------------------------------
# Generating and compiling costs about as much as evaluating the generic numpy code on a few
# thousand samples (docs/generated_numpy.md), so the float64 paths use
# the generated code once it is compiled or when the batch is large enough to pay for it.
GENERATE_AT = {"regressor": 2000, "closure": 50}   # samples
_CACHE: dict[tuple[Mechanism, str], dict[str, Any]] = {}
_CACHE_SIZE = 32


@functools.lru_cache(maxsize=_CACHE_SIZE)
def _traced(mechanism: Mechanism, parts: tuple[str, ...]) -> tuple[Graph, list[Kernel]]:
    """:func:`trace`, once per mechanism and parts: the numpy and the scalar (arb, one
    float64 state) code of a closed loop are written from the same graph, traced once."""
    return trace(mechanism, parts)


def compiled(mechanism: Mechanism, part: str) -> dict[str, Any]:
    """The generated module of one of ``mechanism``'s ``PARTS``, executed once and cached."""
    key = (mechanism, part)
    namespace = _CACHE.get(key)
    if namespace is None:
        source = module_source(mechanism, (part,))
        namespace = {"__name__": f"baseparams_generated_{part}"}
        exec(compile(source, f"<baseparams generated {part}: {mechanism.name}>", "exec"), namespace)
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = namespace
    return namespace


def worthwhile(mechanism: Mechanism, part: str, values: Sequence[Any]) -> bool:
    """Should a float64 batch (``values``: per-coordinate scalars or arrays) run the
    generated code? Yes once it is compiled, or for at least ``GENERATE_AT[part]`` samples."""
    if (mechanism, part) in _CACHE:
        return True
    shape = np.broadcast_shapes(*(np.shape(v) for v in values)) if len(values) else ()
    return int(np.prod(shape, dtype=int)) >= GENERATE_AT[part]


def tree_regressor(mechanism: Mechanism, q: Sequence[Any], qd: Sequence[Any], qdd: Sequence[Any]) -> np.ndarray:
    """K of the tree coordinates (..., n, p) from lists (one entry per coordinate) of
    float64 scalars or arrays of samples, as :class:`~baseparams.dynamics.evaluator.Sample`
    holds them: the generated equivalent of :func:`~.regressor.tree_regressor_array`."""
    return _run(mechanism, "regressor", "_tree_regressor", (q, qd, qdd))[0]


def closure(mechanism: Mechanism, q: Sequence[Any]) -> tuple[list[Any], list[list[Any]]]:
    """Closure values and Jacobian rows as :meth:`TreeKinematics.closure` gives them (lists
    of per-sample arrays), from per-coordinate values ``q``."""
    phi, jac = _run(mechanism, "closure", "_closure", (q,))
    m, n = jac.shape[-2:]
    return [phi[..., i] for i in range(m)], [[jac[..., i, j] for j in range(n)] for i in range(m)]


def closure_arrays(mechanism: Mechanism, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closure values (samples, m) and Jacobian (samples, m, n) at tree coordinates ``q``
    given as one (n, samples) array: the batched Newton's form, without per-coordinate lists."""
    module = compiled(mechanism, "closure")
    phi, jac = module["_evaluate"]("_closure", [np.ascontiguousarray(q, dtype=float)])
    return phi, jac


def closure_bias(mechanism: Mechanism, q: Sequence[Any], qd: Sequence[Any]) -> list[np.ndarray]:
    """The closure bias terms (list of per-sample arrays) at positions and velocities q, qd."""
    gamma = _run(mechanism, "closure", "_closure_bias", (q, qd))[0]
    return [gamma[..., i] for i in range(gamma.shape[-1])]


def _run(mechanism: Mechanism, part: str, kernel: str, groups: Sequence[Sequence[Any]]) -> list[np.ndarray]:
    module = compiled(mechanism, part)
    n = len(mechanism.coordinates)
    values = [np.asarray(v, dtype=float) for group in groups for v in group]
    shape = np.broadcast_shapes(*(v.shape for v in values)) if values else ()
    count = int(np.prod(shape, dtype=int))
    inputs = []
    for g in range(len(groups)):
        block = np.empty((n, count))
        for i in range(n):
            block[i] = np.broadcast_to(values[g * n + i], shape).reshape(-1)
        inputs.append(block)
    outs = module["_evaluate"](kernel, inputs)
    return [out.reshape(shape + out.shape[1:]) for out in outs]


# ----- ball and rational arithmetic -------------------------------------------------------------
# One state per call, in the backend's own numbers: every operation is the backend's (a ball
# operation in arb, so each entry's ball still contains its exact value), minus the work on
# exact zeros and ones and the repeated subexpressions of the generic code.
ScalarModule = tuple[dict[str, Any], dict[str, dict[str, Layout]], tuple[Any, ...]]
_SCALAR: dict[tuple[Mechanism, str], ScalarModule] = {}
_SCALAR_CONSTANTS: dict[tuple[Any, ...], Any] = {}


def _scalar_module(mechanism: Mechanism, part: str) -> ScalarModule:
    key = (mechanism, part)
    found = _SCALAR.get(key)
    if found is None:
        stored = codecache.key(mechanism, f"{part}, scalar")
        kept = codecache.load(stored)
        if kept is None:
            graph, kernels = _traced(mechanism, (part,))
            constants = Constants()
            source = "\n".join(kernel_source(graph, k, constants, scalar=True) for k in kernels)
            code = compile(source, f"<baseparams generated {part}, scalar: {mechanism.name}>", "exec")
            kept = (marshal.dumps(code), {k.name: layouts(k) for k in kernels}, tuple(constants.values))
            codecache.store(stored, kept)
        namespace: dict[str, Any] = {}
        exec(marshal.loads(kept[0]), namespace)
        found = (namespace, kept[1], kept[2])
        if len(_SCALAR) >= _CACHE_SIZE:
            _SCALAR.pop(next(iter(_SCALAR)))
        _SCALAR[key] = found
    return found


def _backend_constants(mechanism: Mechanism, part: str, backend: Backend, values: Sequence[Any]) -> tuple[Any, ...]:
    """The constants in ``backend`` (at its digits), computed once per precision."""
    key = (mechanism, part, backend.name, getattr(backend, "digits", None))
    found = _SCALAR_CONSTANTS.get(key)
    if found is None:
        with backend.activate():
            found = tuple(backend.evaluate(v) for v in values)
        if isinstance(backend, Float64):
            found = tuple(float(v) for v in found)       # Python floats: faster than numpy scalars
        if len(_SCALAR_CONSTANTS) >= 4 * _CACHE_SIZE:
            _SCALAR_CONSTANTS.pop(next(iter(_SCALAR_CONSTANTS)))
        _SCALAR_CONSTANTS[key] = found
    return found


def _trig(backend: Backend) -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    if isinstance(backend, Arb):
        return (arb.cos, arb.sin)
    if isinstance(backend, Float64):
        return (math.cos, math.sin)
    return (lambda x: backend.cos_sin(x)[0], lambda x: backend.cos_sin(x)[1])


def _scalar_run(mechanism: Mechanism, part: str, kernel: str, backend: Backend,
                inputs: Sequence[Sequence[Any]]) -> list[list[Any]]:
    """The outputs of one scalar kernel at one state, each a flat list in ``backend``'s numbers."""
    namespace, lays, values = _scalar_module(mechanism, part)
    constants = _backend_constants(mechanism, part, backend, values)
    outputs = lays[kernel]
    buffers: list[list[Any]] = [[None] * len(layout.slots) for layout in outputs.values()]
    namespace[kernel](*inputs, constants, _trig(backend), *buffers)
    flats = []
    for template, layout, buffer in zip(_fixed_entries(mechanism, part, kernel, backend), outputs.values(), buffers):
        flat = list(template)
        for slot, v in zip(layout.slots, buffer):
            flat[slot] = v
        flats.append(flat)
    return flats


def _fixed_entries(mechanism: Mechanism, part: str, kernel: str, backend: Backend) -> list[list[Any]]:
    """Per output of ``kernel``: its flat entries with the state-independent ones (exact
    zeros, constants of the geometry) in ``backend``'s numbers, computed once per precision."""
    key = (mechanism, part, kernel, backend.name, getattr(backend, "digits", None))
    found = _SCALAR_CONSTANTS.get(key)
    if found is None:
        _, lays, _ = _scalar_module(mechanism, part)
        found = []
        with backend.activate():
            zero = backend.rational(Fraction(0))
            for layout in lays[kernel].values():
                flat = [zero] * math.prod(layout.shape)
                for slot, v in layout.constants:
                    flat[slot] = backend.evaluate(v)
                found.append(flat)
        if len(_SCALAR_CONSTANTS) >= 4 * _CACHE_SIZE:
            _SCALAR_CONSTANTS.pop(next(iter(_SCALAR_CONSTANTS)))
        _SCALAR_CONSTANTS[key] = found
    return found


def scalar_tree_regressor(mechanism: Mechanism, backend: Backend, q: Sequence[Any], qd: Sequence[Any],
                          qdd: Sequence[Any]) -> list[list[Any]]:
    """K_tree at one state in ``backend``'s arithmetic (arb, rationals): n rows of 10 *
    bodies entries, as :func:`~.regressor.generic_tree_regressor` gives them. Call within
    the backend's precision."""
    flat, = _scalar_run(mechanism, "regressor", "_tree_regressor", backend, (q, qd, qdd))
    p = 10 * len(mechanism.body_labels)
    return [flat[k * p:(k + 1) * p] for k in range(len(mechanism.coordinates))]


def scalar_closure(mechanism: Mechanism, backend: Backend, q: Sequence[Any]) -> tuple[list[Any], list[list[Any]]]:
    """Closure values and Jacobian rows at one state in ``backend``'s numbers (arb balls,
    Python floats), as :meth:`TreeKinematics.closure` gives them (about 10x faster on the
    SLA: no body states, no work on the frames' exact zeros and ones, no numpy call on one
    element). In arb every operation is a ball operation, so the enclosures stay rigorous
    (Krawczyk's test runs on them). Call within the backend's precision."""
    phi, jac = _scalar_run(mechanism, "closure", "_closure", backend, (q,))
    n = len(mechanism.coordinates)
    return phi, [jac[i * n:(i + 1) * n] for i in range(len(phi))]


def scalar_closure_bias(mechanism: Mechanism, backend: Backend, q: Sequence[Any], qd: Sequence[Any]) -> list[Any]:
    """The closure bias terms gamma at one state (arb balls, Python floats), as
    ``TreeKinematics.closure(states, want_bias=True)`` gives them."""
    gamma, = _scalar_run(mechanism, "closure", "_closure_bias", backend, (q, qd))
    return gamma


def regressor_columns(kin: TreeKinematics) -> list[tuple[int, ...]] | None:
    """Per row of :func:`regressor_rows`: the columns that can be nonzero (the others are
    exact zeros in every state), when the generated code gives the rows; else None."""
    if not isinstance(kin.backend, (Arb, Exact)):
        return None
    return _nonzero_columns(kin.mechanism)


@functools.lru_cache(maxsize=_CACHE_SIZE)
def _nonzero_columns(mechanism: Mechanism) -> list[tuple[int, ...]]:
    _, lays, _ = _scalar_module(mechanism, "regressor")
    layout = lays["_tree_regressor"]["K"]
    n, p = layout.shape
    columns: list[set[int]] = [set() for _ in range(n)]
    for flat in list(layout.slots) + [slot for slot, _ in layout.constants]:
        columns[flat // p].add(flat % p)
    return [tuple(sorted(c)) for c in columns]


def regressor_rows(kin: TreeKinematics, q: Sequence[Any], qd: Sequence[Any], qdd: Sequence[Any],
                   states: Mapping[int, BodyState] | Callable[[], Mapping[int, BodyState]]) -> list[list[Any]]:
    """K_tree's rows at one state: generated code in arb and rationals, the generic
    recursion otherwise (float64 and sympy keep :func:`~.regressor.tree_regressor`).
    ``states``: the body states, or a callable giving them (read only by the generic path)."""
    if isinstance(kin.backend, (Arb, Exact)):
        return scalar_tree_regressor(kin.mechanism, kin.backend, q, qd, qdd)
    return tree_regressor_rows_generic(kin, states() if callable(states) else states, qdd)


# ----- the export -------------------------------------------------------------------------------
_EXPORT_OPEN = '''

def regressor(q, qd, qdd):
    """K (..., n, p): tau = K phi, for q, qd, qdd of shape (..., n) in COORDINATES order."""
    return tree_regressor(q, qd, qdd)
'''

_EXPORT_CLOSED = '''

def regressor(q, qd, qdd):
    """K (..., f, p) in the independent coordinates (tau_z = K phi; f = len(INDEPENDENT)).

    q, qd, qdd (..., n): ALL tree coordinates (COORDINATES order) on the constraint
    manifold: positions closing the loops (closure(q)[0] ~ 0), velocities qd = R zd and
    accelerations with J qdd + gamma = 0. This module does not solve the loop closure;
    K = R^T K_tree with R = projection(q)."""
    return _np.einsum("...kf,...kp->...fp", projection(q), tree_regressor(q, qd, qdd))
'''

_EXPORT_BASE = '''

def base_regressor(q, qd, qdd):
    """The base regressor (..., rows, len(BASE_PARAMETERS)): the columns BASE_COLUMNS of
    regressor(q, qd, qdd), since K phi = K_kept phi_b with phi_b = phi_kept + beta phi_eliminated."""
    return regressor(q, qd, qdd)[..., list(BASE_COLUMNS)]
'''


def export_source(mechanism: Mechanism, result: BaseParameterResult) -> str:
    """A standalone module (numpy only) with ``regressor(q, qd, qdd) -> K`` and
    ``base_regressor`` (the columns of ``result``'s base parameters), the base parameter
    expressions in its docstring and in ``BASE_PARAMETERS``."""
    params = list(mechanism.parameters)
    base = [(row["name"], dict(row["expression"])) for row in result.base]
    columns = [params.index(next(p for p, c in expr.items() if c == "1" and p not in result.eliminated))
               for _, expr in base]
    closed = bool(mechanism.loops)
    lines = [f"The regressor of {mechanism.name}, generated by baseparams ({result.solver} solver: rank {result.rank}"
             + (", certified" if result.certified else "") + ").",
             "",
             "Standalone: needs numpy only. Arrays of states may have any leading shape (a batch).",
             "",
             "- regressor(q, qd, qdd) -> K: tau = K phi, phi = PARAMETERS (10 per body: m mx my mz",
             "  Ixx Ixy Ixz Iyy Iyz Izz, first moments and inertia about the body origin).",
             "- base_regressor(q, qd, qdd) -> K_b = K[..., BASE_COLUMNS]: tau = K_b phi_b.",
             "- tree_regressor(q, qd, qdd): K of all tree coordinates."]
    if closed:
        lines += ["",
                  "CLOSED LOOPS: q, qd, qdd are ALL tree coordinates (COORDINATES), already on the",
                  "constraint manifold (the loops closed, qd and qdd consistent): this module does",
                  "not solve the loop closure. K is then in the independent coordinates",
                  "(INDEPENDENT): K = R^T K_tree, R = projection(q) from the closure Jacobian",
                  "(closure(q) gives the equations' values to check a state, closure_bias(q, qd)",
                  "the acceleration constraint J qdd + gamma = 0)."]
    lines += ["", "Base parameters (phi_b = phi_kept + beta phi_eliminated):"]
    lines += [f"  {name} = " + " + ".join(p if c == "1" else f"({c})*{p}" for p, c in expr.items())
              for name, expr in base]
    extra = (_EXPORT_CLOSED if closed else _EXPORT_OPEN) + _EXPORT_BASE + "\n" + "\n".join([
        f"BASE_SOLVER = {result.solver!r}",
        f"BASE_RANK = {result.rank!r}",
        f"BASE_PARAMETERS = {tuple(base)!r}",
        f"BASE_COLUMNS = {tuple(columns)!r}   # indices into PARAMETERS"])
    return module_source(mechanism, PARTS, header="\n".join(lines).replace('"""', "'''"), extra=extra)
