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
from collections.abc import Callable
from typing import Any

import numpy as np

from baseparams.dynamics import codegen
from baseparams.model.mechanism import Mechanism

GROUPS = ("q", "qd", "qdd")


@functools.lru_cache(maxsize=16)
def _compiled(mechanism: Mechanism, part: str = "regressor", kernel_name: str = "_tree_regressor",
              output: str = "K") -> tuple[Callable[..., None], np.ndarray, codegen.Layout, list[tuple[int, float]]]:
    """(function, constants, layout, fixed): the generated value-and-tangent code of one output
    of a traced kernel (K_tree; a closed loop's closure Jacobian or bias), the layout of its
    entries (the others are exact constants: ``fixed``). Directions: every input of every
    group the kernel reads, group after group."""
    graph, kernels = codegen._traced(mechanism, (part,))
    kernel = next(k for k in kernels if k.name == kernel_name)
    layout = codegen.layouts(kernel)[output]
    groups = kernel.inputs
    ops = graph.ops
    writes, live, last = codegen._liveness(graph, kernel)
    n = len(mechanism.coordinates)
    constants: list[float] = []
    index: dict[str, int] = {}

    def const(value: Any) -> str:
        key = codegen._float_literal(value)
        if key not in index:
            index[key] = len(constants)
            constants.append(float(key))
        return f"C[{index[key]}]"

    lines = [f"def _tangent({', '.join(groups)}, E, C, out_v, out_t):"]
    name = {}
    for i, (kind, a, b) in enumerate(ops):
        if not live[i]:
            continue
        v, t = f"v{i}", f"t{i}"
        name[i] = (v, t)
        if kind == "in":
            group, k = a[1]
            lines.append(f"    {v} = {group}[{k}]; {t} = E[{groups.index(group) * n + k}]")
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


def _run(mechanism: Mechanism, key: tuple[str, ...], inputs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(value (N, *shape), tangents (directions, N, *shape)) of the output ``key`` names at
    the samples ``inputs`` (one (N, n) array per input group)."""
    function, constants, layout, fixed = _compiled(mechanism, *key)
    inputs = [np.ascontiguousarray(np.asarray(x, dtype=float).T) for x in inputs]
    n, count = inputs[0].shape
    directions = len(inputs) * n
    seeds = np.zeros((directions, directions, count))
    for k in range(directions):
        seeds[k, k] = 1.0
    slots = len(layout.slots)
    out_v = np.empty((slots, count))
    out_t = np.empty((directions, slots, count))
    if slots:
        function(*inputs, seeds, constants, out_v, out_t)
    size = int(np.prod(layout.shape))
    value = np.zeros((count, size))
    tangent = np.zeros((directions, count, size))
    for flat, v in fixed:
        value[:, flat] = v
    index = np.array(layout.slots, dtype=np.intp)
    value[:, index] = out_v.T
    tangent[:, :, index] = out_t.transpose(0, 2, 1)
    return value.reshape((count,) + layout.shape), tangent.reshape((directions, count) + layout.shape)


def tree_regressor_with_tangents(mechanism: Mechanism, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """(K, dK) at samples of the tree coordinates (``q`` etc.: (N, n)): K (N, n, p) as
    :func:`codegen.tree_regressor` gives it, and dK (3 n, N, n, p), dK[g * n + i] the
    derivative of K with respect to input i of group g (q, qd, qdd)."""
    return _run(mechanism, ("regressor", "_tree_regressor", "K"), [q, qd, qdd])


def closure_jacobian_with_tangents(mechanism: Mechanism, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(J (N, m, n), dJ (n, N, m, n)): a closed loop's closure Jacobian and its derivatives
    with respect to each tree coordinate."""
    return _run(mechanism, ("closure", "_closure", "jac"), [q])


def closure_bias_with_tangents(mechanism: Mechanism, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(gamma (N, m), dgamma (2 n, N, m)): the closure bias (J qdd + gamma = 0 with J the
    Jacobian) and its derivatives with respect to q, then qd."""
    return _run(mechanism, ("closure", "_closure_bias", "gamma"), [q, qd])
