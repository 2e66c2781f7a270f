"""Fitting: the linear model of the torques, its weighting and covariance, the physical fit.

- :mod:`.fit`: ``identify``, ``predict``: estimates, covariance, validation;
- :mod:`.linear`, :mod:`.weighting`, :mod:`.longrun`: least squares, per-coordinate weights,
  long-run (HAC) covariance;
- :mod:`.base`: base parameters as a linear map; :mod:`.physical`: the physically consistent fit;
- :mod:`.impossible`: estimates no robot has (and the physical rule diagnosis shares).

Imports recordings and the layers below, never diagnose.
"""
from baseparams.lazy import public_names

# public name -> its module, imported on first use
_PUBLIC = {
    "identify": "fit",
    "predict": "fit",
    "fitted": "fit",
    "Identification": "fit",
    "Prediction": "fit",
}
__all__ = sorted(_PUBLIC)

__getattr__ = public_names(__name__, _PUBLIC)
