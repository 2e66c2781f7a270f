"""A recording's columns moved in time, for the delays of :mod:`.change` (the shared model's and
a change's lag): cubic interpolation through the four rows around each instant, run by run, and
the time derivative run by run."""

import numpy as np

from baseparams.recordings.data import MeasuredData


def time_derivative(x: np.ndarray, data: MeasuredData) -> np.ndarray:
    """d/dt of ``x`` (n, ...) at the fit's rows, run by run (segment by segment: no
    derivative across a clock reset or two logs joined)."""
    t = data.t
    out = np.zeros_like(x)
    edges = np.cumsum([0] + [len(s.kept()) for s in data.segments])
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a >= 2:
            out[a:b] = np.gradient(x[a:b], t[a:b], axis=0)
    return out


def shifted(x: np.ndarray, data: MeasuredData, delay: float) -> np.ndarray:
    """``x`` (n, ...) at the fit's rows as it was ``delay`` seconds earlier, run by run: cubic
    interpolation through the four rows around each instant (held at a segment's first row
    before it). Local, so its cost is four gathers: a spline through every column cost a third
    of a diagnosis between recordings, for the same order of accuracy (h^4)."""
    if delay == 0.0:
        return x
    t = data.t
    edges = np.cumsum([0] + [len(s.kept()) for s in data.segments])
    if len(edges) == 2 and edges[1] == len(x) == len(t) and len(x) >= 4:    # one run: no copy to write into
        moved = local_cubic(t, x, np.clip(t - delay, t[0], t[-1]))
        if x.flags.c_contiguous:
            return moved
        out = np.empty_like(x, dtype=float)     # x's memory layout: the products downstream round alike
        out[...] = moved
        return out
    out = np.array(x, dtype=float, copy=True)
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a >= 4:
            out[a:b] = local_cubic(t[a:b], x[a:b], np.clip(t[a:b] - delay, t[a], t[b - 1]))
    return out


# local_cubic's products are summed over blocks of about this many entries (fits a core's cache).
CUBIC_BLOCK = 1 << 15


def local_cubic(t: np.ndarray, x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``x`` (n >= 4, ...) sampled at increasing ``t``, at the instants ``at`` (within t's span):
    the Lagrange cubic through the nearest four samples (exact on cubics; any spacing)."""
    first = np.clip(np.searchsorted(t, at, side="right") - 2, 0, len(t) - 4)
    nodes = t[first[:, None] + np.arange(4)]                      # (m, 4)
    out = np.zeros((len(at),) + x.shape[1:])
    flat = x.reshape(len(x), -1)
    live = np.flatnonzero(np.any(flat != 0, axis=0))    # zero columns stay zero: most candidates' are
    if len(live) == 0:
        return out
    whole = len(live) == flat.shape[1]
    flat = flat if whole else flat[:, live]
    weights = np.ones((4, len(at)))
    for k in range(4):
        for j in range(4):
            if j != k:
                weights[k] *= (at - nodes[:, j]) / (nodes[:, k] - nodes[:, j])
    rows = np.zeros((len(at), flat.shape[1]))
    # where the four rows of instant i are i + c .. i + c + 3 for one c (uniform sampling: a few
    # runs of constant c) they are read as slices, a block of rows at a time (the four products
    # and their sum in cache): the same operations on the same numbers as gathers, a third of the time
    offset = first - np.arange(len(at))
    edges = np.concatenate([[0], np.flatnonzero(np.diff(offset)) + 1, [len(at)]])
    if len(edges) > 2 + len(at) // 16:                  # irregular sampling: one run per row or so
        for k in range(4):
            rows += np.take(flat, first + k, axis=0) * weights[k, :, None]
        edges = edges[:0]
    block = max(1, CUBIC_BLOCK // max(flat.shape[1], 1))
    part = np.empty((block, flat.shape[1]))
    for lo, hi in zip(edges[:-1], edges[1:]):
        c = int(offset[lo])
        for a in range(lo, hi, block):
            b = min(a + block, hi)
            for k in range(4):                          # rows = 0 + p_0 + p_1 + p_2 + p_3
                np.multiply(flat[a + c + k:b + c + k], weights[k, a:b, None], out=part[:b - a])
                rows[a:b] += part[:b - a]
    if whole:
        return rows.reshape(out.shape)
    out.reshape(len(at), -1)[:, live] = rows
    return out
