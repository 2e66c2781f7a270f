"""Forward-mode derivatives of the generated regressor code: K_tree and its tangents.

The float64 regressor is written once from a traced graph of the generic kinematics
(:mod:`baseparams.dynamics.codegen`). Here the same graph is written a second time with,
beside each value, its tangent: the derivatives of that value with respect to every tree
input (q_i, qd_i, qdd_i: 3 n directions, carried at once as a (3 n, samples) array), by the
rules of each operation (product, quotient, cos, sin). So dK/dq, dK/dqd and dK/dqdd are
exact to rounding, from the code that computes K, and never by finite differences: the
gradient of a trajectory criterion is then a chain rule through the trajectory's basis.
"""

from __future__ import annotations

import functools

import numpy as np

from baseparams.dynamics import codegen

GROUPS = ("q", "qd", "qdd")


@functools.lru_cache(maxsize=16)
def _compiled(mechanism):
    """(function, slots): the generated value-and-tangent code of K_tree and the flat indices
    of K's (n, p) entries it returns (every other entry is an exact constant: ``constants``)."""
    graph, kernels = codegen._traced(mechanism, ("regressor",))
    kernel = next(k for k in kernels if k.name == "_tree_regressor")
    layout = codegen.layouts(kernel)["K"]
    ops = graph.ops
    writes, live, last = codegen._liveness(graph, kernel)
    n = len(mechanism.coordinates)
    constants: list[float] = []
    index: dict = {}

    def const(value) -> str:
        key = codegen._float_literal(value)
        if key not in index:
            index[key] = len(constants)
            constants.append(float(key))
        return f"C[{index[key]}]"

    lines = ["def _tangent(q, qd, qdd, E, C, out_v, out_t):"]
    name = {}
    for i, (kind, a, b) in enumerate(ops):
        if not live[i]:
            continue
        v, t = f"v{i}", f"t{i}"
        name[i] = (v, t)
        if kind == "in":
            group, k = a[1]
            lines.append(f"    {v} = {group}[{k}]; {t} = E[{GROUPS.index(group) * n + k}]")
            continue
        va, ta = name[a] if isinstance(a, int) else (const(a[1]), None)
        vb, tb = (name[b] if isinstance(b, int) else (const(b[1]), None)) if b is not None else (None, None)
        if kind == "add":
            tan = f"{ta} + {tb}" if ta and tb else ta or tb
            lines.append(f"    {v} = {va} + {vb}; {t} = {tan}")
        elif kind == "sub":
            tan = f"{ta} - {tb}" if ta and tb else ta or f"-{tb}"
            lines.append(f"    {v} = {va} - {vb}; {t} = {tan}")
        elif kind == "mul":
            parts = [f"{ta} * {vb}" if ta else None, f"{va} * {tb}" if tb else None]
            lines.append(f"    {v} = {va} * {vb}; {t} = {' + '.join(p for p in parts if p)}")
        elif kind == "div":
            if tb is None:
                lines.append(f"    {v} = {va} / {vb}; {t} = {ta} / {vb}")
            else:
                num = f"{ta} - {v} * {tb}" if ta else f"-{v} * {tb}"
                lines.append(f"    {v} = {va} / {vb}; {t} = ({num}) / {vb}")
        elif kind == "neg":
            lines.append(f"    {v} = -{va}; {t} = -{ta}")
        elif kind == "cos":
            lines.append(f"    {v} = _cos({va}); {t} = -_sin({va}) * {ta}")
        elif kind == "sin":
            lines.append(f"    {v} = _sin({va}); {t} = _cos({va}) * {ta}")
        else:                                           # pragma: no cover - the graph's own ops
            raise ValueError(f"unknown traced operation {kind!r}")
        for x in set(codegen._operands((kind, a, b))):
            if last.get(x) == i and x not in writes:
                lines.append(f"    del v{x}, t{x}")
    for row, node in enumerate(layout.nodes):
        v, t = name[node]
        lines.append(f"    out_v[{row}] = {v}; out_t[:, {row}] = {t}")
    namespace = {"_cos": np.cos, "_sin": np.sin}
    exec(compile("\n".join(lines) + "\n", f"<baseparams tangent regressor: {mechanism.name}>", "exec"), namespace)
    fixed = [(flat, float(value)) for flat, value in layout.constants]
    return namespace["_tangent"], np.array(constants), layout, fixed


def tree_regressor_with_tangents(mechanism, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """(K, dK) at samples of the tree coordinates (``q`` etc.: (N, n)): K (N, n, p) as
    :func:`codegen.tree_regressor` gives it, and dK (3 n, N, n, p), dK[g * n + i] the
    derivative of K with respect to input i of group g (q, qd, qdd)."""
    function, constants, layout, fixed = _compiled(mechanism)
    q, qd, qdd = (np.ascontiguousarray(np.asarray(x, dtype=float).T) for x in (q, qd, qdd))
    n, count = q.shape
    directions = 3 * n
    seeds = np.zeros((directions, directions, count))
    for k in range(directions):
        seeds[k, k] = 1.0
    slots = len(layout.slots)
    out_v = np.empty((slots, count))
    out_t = np.empty((directions, slots, count))
    if slots:
        function(q, qd, qdd, seeds, constants, out_v, out_t)
    size = int(np.prod(layout.shape))
    K = np.zeros((count, size))
    dK = np.zeros((directions, count, size))
    for flat, value in fixed:
        K[:, flat] = value
    index = np.array(layout.slots, dtype=np.intp)
    K[:, index] = out_v.T
    dK[:, :, index] = out_t.transpose(0, 2, 1)
    return K.reshape((count,) + layout.shape), dK.reshape((directions, count) + layout.shape)
