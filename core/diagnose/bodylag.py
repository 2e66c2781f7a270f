"""How late a payload's force is in a recording held against a given model (``--params``).

A recording's torques lag its positions (a current filter, a bus). The identification held
as given was fitted to a run with that lag and absorbed what it could of it; a payload added
since is new force, and it lags as every torque of the recording does. Its columns taken at
the positions' instants leave the lag's share of its force (omega d of it) in the residual,
which grows with the payload: on the PUMA with a 27 ms lag common to both runs, a 45 g load
on link6 was named as a payload with "structure remains" on q4 (7.5 times the noise level),
the verdict "partly explained". So the bodies' columns are taken as late as the data say: one
lag, estimated with every body's load columns together (Gauss-Newton, the given torque's
derivative a column beside them for what the held model lacks of the lag itself), used when
it stands clear of zero (:data:`CLEAR`). There it was 28.4 ms (z = 15), the body was named
and the verdict "explained". Where the lag does not stand clear (a small load, a quiet
recording), the columns stay as they were.
"""

import numpy as np

from baseparams.identify.linear import WeightedLinearModel

# The lag is used when it is this many (HAC) standard deviations from zero, at least half a
# sample step and within LONGEST seconds; otherwise the bodies' columns stay at the positions'
# instants. Why the half step: a 2 kHz UR5 recording without any lag, filtered and decimated
# to 17.5 Hz, gave 5.2 ms at z = 4.06 (a tenth of its 57 ms step: the filters' phase, not a
# lag), and a delay of -0.9 ms was named to undo it.
CLEAR = 4.0
LONGEST = 0.1
ITERATIONS = 6
TOLERANCE = 0.01              # of a sample step: the Gauss-Newton step at which it stops


def segments(t: np.ndarray) -> list[slice]:
    """The runs of a concatenated time axis: it restarts (or jumps ahead by more than ten
    steps) where a run ends."""
    if len(t) < 2:
        return [slice(0, len(t))]
    d = np.diff(t)
    step = float(np.median(d[d > 0])) if np.any(d > 0) else 1.0
    cuts = np.flatnonzero((d <= 0) | (d > 10 * step)) + 1
    edges = [0, *cuts.tolist(), len(t)]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]


def late(x: np.ndarray, t: np.ndarray, lag: float) -> np.ndarray:
    """``x`` (n, ...) as it was ``lag`` seconds earlier, run by run (linear interpolation;
    held at a run's first sample before it)."""
    if lag == 0.0:
        return x
    out = np.array(x, dtype=float, copy=True)
    for s in segments(t):
        ts = t[s]
        if len(ts) < 2:
            continue
        at = np.clip(ts - lag, ts[0], ts[-1])
        i = np.clip(np.searchsorted(ts, at, side="right") - 1, 0, len(ts) - 2)
        w = ((at - ts[i]) / (ts[i + 1] - ts[i])).reshape((-1,) + (1,) * (x.ndim - 1))
        out[s] = (1 - w) * x[s][i] + w * x[s][i + 1]
    return out


def rate(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """dx/dt (n, ...), run by run."""
    out = np.zeros_like(x, dtype=float)
    for s in segments(t):
        if s.stop - s.start >= 2:
            out[s] = np.gradient(x[s], t[s], axis=0)
    return out


def load_columns(bodies: np.ndarray) -> np.ndarray:
    """Every moving body's mass and first-moment columns (n, f, 4 per body) of the inertial
    regressor ``bodies`` (n, f, 10 per body): what a compact load on it adds."""
    blocks = [bodies[:, :, 10 * k: 10 * k + 4] for k in range(bodies.shape[-1] // 10)]
    blocks = [b for b in blocks if np.any(b)]
    return np.concatenate(blocks, axis=-1) if blocks else np.zeros(bodies.shape[:2] + (0,))


def body_lag(t: np.ndarray, y: np.ndarray, torque: np.ndarray, bodies: np.ndarray) -> tuple[float, float]:
    """(lag in s, its z) of the loads' force in ``y`` (n, f: measured less the given model's
    torque ``torque``), ``bodies`` the inertial regressor (n, f, 10 per body) at the
    positions' instants; (0, 0) when no body moves or the fit cannot tell."""
    X = load_columns(bodies)
    if X.shape[-1] == 0 or len(t) < 8:
        return 0.0, 0.0
    step = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    own = -rate(torque, t)[:, :, None]               # what the held model lacks of the lag
    lag, z, weights = 0.0, 0.0, None
    for _ in range(ITERATIONS):
        Xd = late(X, t, lag)
        fit = WeightedLinearModel(np.concatenate([own, Xd], axis=-1), y).fit(weights)
        weights = fit.weights
        force = Xd @ fit.coefficients[1:]
        column = -rate(force, t)[:, :, None]
        if not np.any(column):
            return 0.0, 0.0
        grown = WeightedLinearModel(np.concatenate([own, Xd, column], axis=-1), y).fit(weights, cov_type="hac")
        step_lag = float(grown.coefficients[-1])
        std = float(np.sqrt(max(grown.covariance[-1, -1], 0.0)))
        lag += step_lag
        z = lag / std if std > 0 else 0.0
        if not np.isfinite(lag) or abs(lag) > 2 * LONGEST:
            return 0.0, 0.0
        if abs(step_lag) <= TOLERANCE * step:
            break
    return lag, z


def usable(lag: float, z: float, t: np.ndarray) -> bool:
    """Whether a lag found by :func:`body_lag` is used (:data:`CLEAR`)."""
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return abs(z) >= CLEAR and max(0.5 * step, 0.0) <= lag <= LONGEST and lag > 0.0
