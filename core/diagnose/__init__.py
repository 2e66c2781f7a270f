"""Diagnosing: candidates, selection, gates, verdict and report of what a model lacks.

- :mod:`.workflow`: diagnosis against a model (one set of runs), with :mod:`.problem`,
  :mod:`.gates`, :mod:`.verdict`, :mod:`.entries`, :mod:`.estimates` and :mod:`.fixed`;
- :mod:`.change`, :mod:`.changesearch`: what changed between two sets of runs;
- :mod:`.candidates`, :mod:`.derived`, :mod:`.given`, :mod:`.identifiable`: what may be named;
- :mod:`.wald`, :mod:`.selection`, :mod:`.final`, :mod:`.whiteness`, :mod:`.outofsample`: tests,
  the forward and backward steps, tests against the final model, colour, cross-validation.

The top room of the numerical core: imports identify, recordings and the layers below.
"""
from baseparams.lazy import public_names

# public name -> its module, imported on first use
_PUBLIC = {
    "diagnose_data": "workflow",
    "Diagnosis": "workflow",
    "Problem": "workflow",
    "prepare": "workflow",
    "diagnose_change": "change",
    "ChangeDiagnosis": "change",
}
__all__ = sorted(_PUBLIC)

__getattr__ = public_names(__name__, _PUBLIC)
