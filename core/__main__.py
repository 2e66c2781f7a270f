"""``python -m baseparams``: the same as the ``baseparams`` command."""

from baseparams.cli import main

main(prog_name="baseparams")
