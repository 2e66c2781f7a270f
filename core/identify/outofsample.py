"""Whether a named effect holds up out of sample: block cross-validation over the whole
recording, the stability of its coefficients from block to block, and its physical
plausibility. Diagnosis names only what passes all three (``docs/diagnosis.md``).

Why blocks: the residual of a filtered recording is correlated over many samples, so
random hold-out rows would leak the fit into the test. Contiguous blocks spread over the
whole recording (not only the last one) each see another part of the motion; ``MARGIN``
samples on each side of a held-out block are dropped from its training rows.

Why the stability test: an effect that stands in for one the catalogue lacks (viscous
friction imitating a torque delay, an offset imitating a smooth friction's shape) fits
each part of the motion with another coefficient, while a real effect has one value for
the whole recording. Each block's coefficient is estimated with the rest of the model held
at the whole-recording fit; their spread is tested (chi-square with HAC variances) and
must also be large (a third of the coefficient) to count, so that a real friction that
drifts a little with temperature is still named.
"""

from dataclasses import dataclass

import numpy as np
from scipy import stats

from baseparams.identify.longrun import hac_lags, long_run

FOLDS = 5
MARGIN = 10                 # samples dropped from the training rows beside a held-out block
UNSTABLE = 1.0 / 3.0        # a coefficient spread (RMS over blocks / |pooled|) counted as real
DELAY_LIMIT = 0.1           # s: a longer delay between positions and torques is not plausible


def blocks(n: int, folds: int = FOLDS) -> list[np.ndarray]:
    """``folds`` contiguous blocks of sample indices covering 0..n-1."""
    return [b for b in np.array_split(np.arange(n), folds) if len(b)]


@dataclass
class CrossValidation:
    """Held-out weighted residuals of each block (in sample order): ``residual`` (n, f),
    unweighted; ``sse`` the weighted sum of squares per block."""
    residual: np.ndarray
    sse: np.ndarray

    @property
    def total(self) -> float:
        return float(self.sse.sum())


def cross_validate(model: np.ndarray, y: np.ndarray, weights: np.ndarray, folds: int = FOLDS,
                   margin: int = MARGIN) -> CrossValidation:
    """Block cross-validation of the weighted least-squares fit of ``y`` (n, f) on ``model``
    (n, f, p) with fixed per-coordinate ``weights``: each block predicted from the others."""
    n, f, p = model.shape
    X = (model * weights[None, :, None])
    Y = y * weights[None, :]
    scale = np.linalg.norm(X.reshape(n * f, p), axis=0)
    scale[scale == 0] = 1.0
    X = X / scale
    residual = np.empty_like(y)
    sse = []
    for block in blocks(n, folds):
        lo, hi = max(block[0] - margin, 0), min(block[-1] + 1 + margin, n)
        train = np.r_[0:lo, hi:n]
        if p:
            A = X[train].reshape(-1, p)
            beta = np.linalg.lstsq(A, Y[train].reshape(-1), rcond=1e-10)[0]
            r = Y[block] - X[block] @ beta
        else:
            r = Y[block]
        residual[block] = r / weights[None, :]
        sse.append(float(np.sum(r ** 2)))
    return CrossValidation(residual, np.array(sse))


def block_coefficients(partial: np.ndarray, columns: np.ndarray, weights: np.ndarray, folds: int = FOLDS
                       ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each block's least-squares coefficients of ``columns`` (n, f, c) on the ``partial``
    residual (n, f) (the data minus the rest of the model), and their HAC covariances; blocks
    where the columns barely act are left out (rows of NaN)."""
    n, f, c = columns.shape
    estimates, covariances = [], []
    total = np.sum((columns * weights[None, :, None]) ** 2)
    for block in blocks(n, folds):
        Z = (columns[block] * weights[None, :, None]).reshape(-1, c)
        r = (partial[block] * weights[None, :]).reshape(-1)
        if np.sum(Z ** 2) < 1e-3 * total / folds or len(block) < 20:
            estimates.append(np.full(c, np.nan))
            covariances.append(np.full((c, c), np.nan))
            continue
        gamma, *_ = np.linalg.lstsq(Z, r, rcond=None)
        e = r - Z @ gamma
        scores = (Z * e[:, None]).reshape(len(block), f, c).sum(axis=1)
        S = long_run(scores, hac_lags(e.reshape(len(block), f)))
        H = np.linalg.pinv(Z.T @ Z)
        estimates.append(gamma)
        covariances.append(H @ S @ H * len(block))
    return np.array(estimates), covariances


@dataclass(frozen=True)
class Stability:
    pvalue: float
    spread: float               # RMS over blocks of |gamma_k - pooled| / |pooled|
    blocks: int
    values: list                # per block (None where the effect barely acts)

    def unstable(self, level: float) -> bool:
        return self.pvalue <= level and self.spread > UNSTABLE


def stability(partial: np.ndarray, columns: np.ndarray, weights: np.ndarray, folds: int = FOLDS
              ) -> Stability:
    """Homogeneity of an effect's coefficients over the blocks (see the module docstring)."""
    estimates, covariances = block_coefficients(partial, columns, weights, folds)
    ok = [k for k in range(len(estimates)) if np.all(np.isfinite(estimates[k]))]
    values = [estimates[k].tolist() if k in ok else None for k in range(len(estimates))]
    if len(ok) < 2:
        return Stability(1.0, 0.0, len(ok), values)
    precisions = [np.linalg.pinv(covariances[k]) for k in ok]
    P = sum(precisions)
    pooled = np.linalg.pinv(P) @ sum(Pk @ estimates[k] for Pk, k in zip(precisions, ok))
    q = float(sum((estimates[k] - pooled) @ Pk @ (estimates[k] - pooled) for Pk, k in zip(precisions, ok)))
    c = estimates.shape[1]
    pvalue = float(stats.chi2.sf(q, (len(ok) - 1) * c))
    norm = float(np.linalg.norm(pooled))
    spread = float(np.sqrt(np.mean([np.sum((estimates[k] - pooled) ** 2) for k in ok])) / norm) \
        if norm > 0 else np.inf
    return Stability(pvalue, spread, len(ok), values)


# ----- physical plausibility ---------------------------------------------------------------------
POSITIVE = {"viscous_friction": ("fv",), "coulomb_friction": ("fc",), "stribeck_friction": ("fs",),
            "rotor_inertia": ("Ia",), "spring": ("k",), "load_friction": ("mu",), "mass": ("m",),
            }


def implausible(kind: str, values: dict) -> str:
    """Why an effect's estimated coefficients are not physical ('' when they are): dissipative
    friction, stiffness, rotor inertia, load friction and masses are positive; a load
    friction coefficient is below 1 (it would dissipate more than the load); a delay is
    shorter than DELAY_LIMIT; a torque gain scale is above -1."""
    for name in POSITIVE.get(kind, ()):
        if name in values and values[name] <= 0:
            return f"{name} = {values[name]:.3g} <= 0 (must be positive)"
    if kind == "load_friction" and values.get("mu", 0) >= 1:
        return f"mu = {values['mu']:.3g} >= 1 (more than the load itself)"
    if kind == "delay" and abs(values.get("d", 0)) > DELAY_LIMIT:
        return f"|d| = {abs(values['d']):.3g} s > {DELAY_LIMIT} s"
    if kind == "gain" and values.get("g", 0) <= -1:
        return f"g = {values['g']:.3g} <= -1 (the torque would change sign)"
    return ""
