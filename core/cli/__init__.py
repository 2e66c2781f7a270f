"""The ``baseparams`` command line: verbs (:mod:`.commands`; ``validate`` in :mod:`.validate`), figures (:mod:`.plots`) and
the symbolic derivation report (:mod:`.report`)."""

# BLAS threads: one per process unless the user says otherwise, set by `import baseparams`
# (core/__init__.py) before numpy loads, for the command line and the Python API alike.
from . import validate as _validate  # noqa: E402,F401  (registers the verb)
from . import convert as _convert  # noqa: E402,F401  (registers the verb)
from . import identify as _identify  # noqa: E402,F401  (registers simulate and identify)
from . import export as _export  # noqa: E402,F401  (registers the verb)
from . import diagnose as _diagnose  # noqa: E402,F401  (registers the verb)
from . import excite as _excite  # noqa: E402,F401  (registers the verb)
from .commands import main  # noqa: E402

__all__ = ["main"]
