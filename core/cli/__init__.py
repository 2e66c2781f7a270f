"""The ``baseparams`` command line: verbs (:mod:`.commands`; ``validate`` in :mod:`.validate`), figures (:mod:`.plots`) and
the symbolic derivation report (:mod:`.report`)."""

from . import validate as _validate  # noqa: F401  (registers the verb)
from .commands import main

__all__ = ["main"]
