"""Fitting: the linear model of the torques, its weighting and covariance, the physical fit.

- :mod:`.fit`: ``identify``, ``predict``: estimates, covariance, validation;
- :mod:`.linear`, :mod:`.weighting`, :mod:`.longrun`: least squares, per-coordinate weights,
  long-run (HAC) covariance;
- :mod:`.base`: base parameters as a linear map; :mod:`.physical`: the physically consistent fit;
- :mod:`.impossible`: estimates no robot has (and the physical rule diagnosis shares).

Imports recordings and the layers below, never diagnose.
"""
from importlib import import_module
from typing import Any

# public name -> its module; imported on first use so that reading a CSV does not load the
# whole room (PEP 562)
_PUBLIC = {
    "identify": "fit",
    "predict": "fit",
    "fitted": "fit",
    "Identification": "fit",
    "Prediction": "fit",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        return getattr(import_module(f"{__name__}.{_PUBLIC[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
