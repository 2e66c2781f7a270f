"""The built-in solvers, one package each (``dp``, ``vp``, ``exact``, ``symbolic``).

Each package's ``__init__`` registers its solver through the ``baseparams_solvers`` hook and
is named in the ``baseparams`` entry-point group of ``pyproject.toml``: exactly what a
third party's distribution does. Read one package to write your own solver.
"""
