"""The ``baseparams`` command line: verbs (:mod:`.commands`), figures (:mod:`.plots`) and
the symbolic derivation report (:mod:`.report`)."""

from .commands import main

__all__ = ["main"]
