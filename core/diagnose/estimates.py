"""The fitted model's figures a diagnosis reports and judges by: its prediction of every
sample from the training fit, the normalised RMS of a residual, the prediction floor on
held-out rows, and each effect's coefficients with HAC standard deviations.
"""

from dataclasses import dataclass

import numpy as np

from baseparams import registry
from baseparams.diagnose import derived
from baseparams.diagnose.selection import Candidate
from baseparams.identify.linear import LinearFit as Fit, WeightedLinearModel


@dataclass
class _Prediction:
    residual: np.ndarray          # (N, f), unweighted, every sample
    fit: Fit                      # the weighted fit on the training rows
    model: np.ndarray             # (N, f, p): the fitted model's columns, every sample


def _predict(inertial: np.ndarray, added: list[Candidate], y: np.ndarray, fit: Fit | None,
             train: int) -> _Prediction:
    """Predict every row from the weighted ``fit`` on the first ``train`` rows of the
    inertial model plus ``added`` (the selection's own; None: fit it here)."""
    model = np.concatenate([inertial] + [c.columns for c in added], axis=-1)
    if fit is None:
        fit = WeightedLinearModel(model[:train], y[:train]).fit()
    return _Prediction(y - model @ fit.coefficients, fit, model)


def holdout_floor(fit: Fit, rows: np.ndarray, tau: np.ndarray) -> tuple[float, float]:
    """(prediction floor, noise floor) on held-out model ``rows`` (m, f, p) with measured
    ``tau`` (m, f), in the normalisation of :func:`nrms`, from the training ``fit``'s own
    noise levels and coefficient covariance: the NRMS a correct model reaches there on
    average (squared: the mean of sigma_c^2 + x^T Cov x over the rows,
    :meth:`Fit.prediction_variance`), and the noise SD alone. The noise SD is the floor of a
    fitted residual, not of a prediction: where a held-out row lies far from the fitted ones
    (the SLA's arms next to their toggle, one sample holding half the inertial columns'
    energy) the coefficients' error is amplified."""
    sigma = np.broadcast_to(1.0 / fit.weights, tau.shape)
    return nrms(np.sqrt(fit.prediction_variance(rows)), tau), nrms(sigma, tau)


def nrms(residual: np.ndarray, tau: np.ndarray) -> float:
    """Normalized RMS: per coordinate RMS(residual) / RMS(tau), then the RMS over the
    coordinates (each coordinate counts equally, whatever its units)."""
    scale = np.sqrt(np.mean(tau ** 2, axis=0))
    scale[scale == 0] = 1.0
    per = np.sqrt(np.mean(residual ** 2, axis=0)) / scale
    return float(np.sqrt(np.mean(per ** 2)))


def coefficients(inertial: np.ndarray, candidates: list[Candidate], added: list[int], y: np.ndarray,
                 weights: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each added effect's coefficients and HAC standard deviations in the final model (the
    sandwich's effect block equals Frisch-Waugh-Lovell's on the effect columns with the
    inertial model projected out), with the final model's noise ``weights`` (None: estimated
    here)."""
    if not added:
        return []
    blocks = [candidates[i].columns for i in added]
    full = WeightedLinearModel(np.concatenate([inertial] + blocks, axis=-1), y).fit(weights, cov_type="hac")
    std = full.std
    out, start = [], inertial.shape[-1]
    for block in blocks:
        width = block.shape[-1]
        out.append((full.coefficients[start:start + width], std[start:start + width]))
        start += width
    return out


def coefficient_names(kind: str) -> tuple[str, ...]:
    """A candidate kind's coefficient names (a registered effect's, or a derived kind's)."""
    effects = registry.effects()
    return effects[kind].item.coefficients if kind in effects else derived.COEFFICIENTS[kind]
