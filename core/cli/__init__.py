"""The ``baseparams`` command line: verbs (:mod:`.commands`; ``validate`` in :mod:`.validate`), figures (:mod:`.plots`) and
the symbolic derivation report (:mod:`.report`)."""

from . import validate as _validate  # noqa: F401  (registers the verb)
from . import convert as _convert  # noqa: F401  (registers the verb)
from . import identify as _identify  # noqa: F401  (registers simulate and identify)
from . import export as _export  # noqa: F401  (registers the verb)
from . import diagnose as _diagnose  # noqa: F401  (registers the verb)
from . import excite as _excite  # noqa: F401  (registers the verb)
from .commands import main

__all__ = ["main"]
