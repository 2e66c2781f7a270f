"""Loading a mechanism and running a solver on it: the one home of the get-solver /
check-options / load / require-applicable / solve sequence that every verb, the
orchestrator and the Python functions use."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from os import PathLike
from typing import TYPE_CHECKING, Any, Union

from baseparams import registry
from baseparams.errors import InputError

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism
    from baseparams.solvers.protocol import Solver
    from baseparams.solvers.result import BaseParameterResult

    from .results import Solution

DEFAULT_SOLVER = "vp"
"""The solver every verb and function uses unless told otherwise: certified ranks, and
coefficients with only the digits it trusts (docs/solvers.md)."""

Progress = Callable[[str], None]
MechanismLike = Union[str, "PathLike[str]", "Mechanism"]
Warn = Callable[[str], None]


def load(mech: MechanismLike, *, warn: Warn | None = None) -> "Mechanism":
    """A registered mechanism name (``"puma560"``), a path to a mechanism file in any
    registered format (TOML, URDF), or the TOML text of one (a string over several lines, as
    :mod:`baseparams.model.generate` writes) -> :class:`~baseparams.model.mechanism.Mechanism`;
    a Mechanism is returned as it is. ``warn`` receives each of the file's warnings
    (doubtful but accepted input); by default they are kept in ``mechanism.warnings`` only."""
    from baseparams.model.mechanism import Mechanism
    if isinstance(mech, Mechanism):
        return mech
    from baseparams.io.loader import parse_mechanism, resolve      # sympy and flint load here
    mechanism = parse_mechanism(mech) if isinstance(mech, str) and "\n" in mech else resolve(mech)
    if warn is not None:
        for warning in mechanism.warnings:
            warn(warning)
    return mechanism


def get_solver(name: str) -> "Solver":
    """A registered solver by name; an InputError listing the registered ones otherwise, or
    naming the distribution whose solver does not implement the Solver protocol."""
    from baseparams.solvers.run import find_solver
    return find_solver(name)


def check_solver_options(solver: "Solver", options: Mapping[str, Any],
                         common: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``options`` checked against what ``solver`` declares (names, types, ranges), before
    any file is read; InputError naming the option otherwise. ``common``: front-door options
    (``--digits``, ``--samples``, ``--seed``) given to the solvers that declare them."""
    from baseparams.solvers.run import solver_options
    return solver_options(solver, options, common=common)[0]


def run_solver(solver: "Solver", mechanism: "Mechanism", options: Mapping[str, Any] | None = None, *,
               common: Mapping[str, Any] | None = None,
               progress: Progress | None = None) -> "BaseParameterResult":
    """:func:`baseparams.solvers.run.run_solver`: the one solver sequence (options checked
    against the mechanism, the solver required to take it, then solve)."""
    from baseparams.solvers.run import run_solver as run
    return run(solver, mechanism, options, common=common, progress=progress)


def chosen_options(solver_options: Mapping[str, Any] | None, old: Mapping[str, Any], function: str) -> dict[str, Any]:
    """The solver options of a front-door function: ``solver_options={...}``, the one way every
    function takes them (``identify``, ``excite`` and ``export`` alike), and the keyword
    arguments ``solve``/``export`` took before it (``bp.solve(m, "vp", digits=40)``), still
    read with a DeprecationWarning. Why one way: the keywords of a function such as
    ``identify`` (``samples``? ``seed``?) would collide with a solver's option names."""
    options = dict(solver_options or {})
    if old:
        import warnings
        warnings.warn(f"{function}(..., {', '.join(f'{k}=...' for k in old)}): solver options as keyword "
                      f"arguments are deprecated; pass solver_options={{...}}", DeprecationWarning, stacklevel=3)
        both = sorted(set(old) & set(options))
        if both:
            raise InputError(f"{', '.join(both)} given both in solver_options and as a keyword argument; give one")
        options.update(old)
    return options


def solve(mech: MechanismLike, solver: str = DEFAULT_SOLVER, *, solver_options: Mapping[str, Any] | None = None,
          progress: Progress | None = None, common: Mapping[str, Any] | None = None, **options: Any) -> "Solution":
    """The base inertial parameters of ``mech`` (a registered name, a file or a Mechanism)
    by the registered ``solver``; ``solver_options`` are the solver's declared options
    (``{"digits": 30, "samples": 200, "seed": 3}`` ...; ``baseparams plugins`` lists them;
    given as keyword arguments they are deprecated). ``common``: ``digits``/``samples``/``seed``
    offered to any solver, passed to those that declare them (the command line's ``--digits``).

    >>> import baseparams as bp
    >>> bp.solve("pendulum", "dp").rank
    3
    """
    from .results import Solution
    options = chosen_options(solver_options, options, "solve")
    chosen = get_solver(solver)
    check_solver_options(chosen, options, common)  # the option's own range, before reading the file
    mechanism = load(mech)
    return Solution(run_solver(chosen, mechanism, options, common=common, progress=progress), mechanism)
