"""Diagnosing: candidates, selection, gates, verdict and report of what a model lacks.

- :mod:`.workflow`: diagnosis against a model (one set of runs);
- :mod:`.change`, :mod:`.changesearch`: what changed between two sets of runs;
- :mod:`.candidates`, :mod:`.derived`, :mod:`.given`, :mod:`.identifiable`: what may be named;
- :mod:`.selection`, :mod:`.whiteness`, :mod:`.outofsample`: tests, colour, cross-validation.

The top room of the numerical core: imports identify, recordings and the layers below.
"""
from importlib import import_module
from typing import Any

# public name -> its module; imported on first use so that reading a CSV does not load the
# whole room (PEP 562)
_PUBLIC = {
    "diagnose_data": "workflow",
    "Diagnosis": "workflow",
    "Problem": "workflow",
    "prepare": "workflow",
    "diagnose_change": "change",
    "ChangeDiagnosis": "change",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        return getattr(import_module(f"{__name__}.{_PUBLIC[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
