"""``python -m baseparams.cli``: the same as the ``baseparams`` command."""

from .commands import main

main()
