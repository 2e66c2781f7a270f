"""Running a solver: the one sequence every caller (CLI verbs, the Python API, the
orchestrator's jobs) goes through, so that a solver's ``solve`` does only its own work.

:func:`run_solver` = find the solver (by name, in the registry) -> check the options it
declares (values, ranges, the mechanism's bounds; defaults filled) -> refuse a mechanism
it does not take (:class:`~baseparams.solvers.protocol.NotApplicable`) -> ``solve``.
"""

from collections.abc import Mapping
from typing import Any

from baseparams.errors import InputError
from baseparams.model.mechanism import Mechanism
from baseparams.solvers.protocol import Progress, Solver, check_options, require_applicable
from baseparams.solvers.result import BaseParameterResult


def find_solver(name: str) -> Solver:
    """The registered solver ``name``. InputError (exit code 2 in the CLI) listing the
    registered ones when there is none, or naming the distribution and the members it lacks
    when the registered object does not implement :class:`Solver`."""
    from baseparams import registry
    solvers = registry.solvers()
    if name not in solvers:
        raise InputError(f"unknown solver {name!r}; registered solvers: {', '.join(solvers) or '(none)'} "
                         f"(see `baseparams plugins`)")
    reg = solvers[name]
    if not isinstance(reg.item, Solver):
        missing = [m for m in ("name", "description", "capabilities", "options", "applicable", "solve")
                   if not hasattr(reg.item, m)]
        raise InputError(f"solver {name!r} (distribution {reg.distribution}) does not implement the "
                         f"solver protocol (baseparams.solvers.protocol.Solver): missing {', '.join(missing)}")
    return reg.item


def solver_options(solver: Solver, options: Mapping[str, Any] | None = None, *,
                   common: Mapping[str, Any] | None = None,
                   mechanism: Mechanism | None = None) -> tuple[dict[str, Any], list[str]]:
    """(every declared option of ``solver``, checked, defaults filled; the names of
    ``common`` it ignored).

    ``options`` are meant for this solver: one it does not declare is an InputError.
    ``common`` are offered to every solver alike (a front door's ``--digits``, ``--samples``,
    ``--seed``): passed when the solver declares them, else dropped and named (None values
    are dropped silently: "not given"). Given twice (in both) is an InputError. Without
    ``mechanism`` only the ranges that do not depend on it are checked (call again with it,
    as :func:`run_solver` does, before solving): a front door can refuse a bad option
    before it reads a mechanism file.
    """
    given = dict(options or {})
    declared = {o.name for o in solver.options}
    ignored = []
    for name, value in (common or {}).items():
        if value is None:
            continue
        if name in given:
            raise InputError(f"option {name!r} both given, as a common option and as a solver option: give one")
        if name in declared:
            given[name] = value
        else:
            ignored.append(name)
    return check_options(solver, given, mechanism), ignored


def run_solver(solver: Solver | str, mechanism: Mechanism, options: Mapping[str, Any] | None = None, *,
               common: Mapping[str, Any] | None = None,
               progress: Progress | None = None) -> BaseParameterResult:
    """The base parameters of ``mechanism`` by ``solver`` (an object or a registered name).

    The sequence, once for every caller: :func:`find_solver` (for a name), the options
    checked as :func:`solver_options` says (``options``: this solver's own, an undeclared
    one is an InputError; ``common``: offered to every solver, passed only when declared,
    and each one ignored is said in the result's warnings), :func:`require_applicable`
    (NotApplicable, naming the mechanism's file and the reason), then ``solver.solve``
    with exactly the declared options. ``progress`` receives the solver's one-line messages.

        >>> from baseparams.solvers.run import run_solver
        >>> result = run_solver("vp", mechanism, {"recover": False})        # doctest: +SKIP
    """
    if isinstance(solver, str):
        solver = find_solver(solver)
    checked, ignored = solver_options(solver, options, common=common, mechanism=mechanism)
    require_applicable(solver, mechanism)
    result = solver.solve(mechanism, progress=progress, **checked)
    if ignored:
        accepted = ", ".join(o.name for o in solver.options) or "(none)"
        result.warnings[:0] = [f"{solver.name} ignores {name}: not one of its options ({accepted})"
                               for name in ignored]
    return result
