"""The ``baseparams`` command line (click).

One function per verb. Every verb that prints results takes ``--format text|json``; the
JSON keys are contracts (docs/cli.md). Errors a user can fix (a bad mechanism file, a
trajectory leaving the reachable range) are :class:`baseparams.errors.BaseparamsError`;
the :class:`Group` below turns them, once for every verb, into ``error: <message>`` on
stderr and exit code 2, with no traceback. Exit code 1 is reserved for a check that
failed (solvers disagree, a gap not closed); click's own usage errors exit 2.

To add a verb: write a function decorated with ``@main.command()`` (or ``@plot.command()``
for a figure), load mechanisms with :func:`load`, and print with :func:`emit`.
"""

import contextlib
import csv
import io
import signal
import textwrap
import threading
from collections.abc import Iterator

from typing import TYPE_CHECKING, Any, TypeVar

import click

from baseparams import __version__
from baseparams import registry
from baseparams.api.solving import get_solver, load as api_load, run_solver
from baseparams.cli.options import (emit, write_output, format_option, image_format_option, output_option,
                                    quiet_option, samples_option, seed_option, solver_option, solver_options_option,
                                    solvers_option, chosen_solvers)
from baseparams.errors import BaseparamsError
from baseparams.solvers.protocol import Capabilities, Solver, check_options, describe_solver, options_from_text
from baseparams.solvers.run import solver_options

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from baseparams.model.mechanism import Mechanism
    from baseparams.solvers.result import BaseParameterResult

F = TypeVar("F", bound="Callable[..., Any]")


class UserError(click.ClickException):
    """A message for the user, printed as ``error: ...`` on stderr; exit code 2."""
    exit_code = 2

    def show(self, file: Any = None) -> None:
        click.echo(f"error: {self.format_message()}", err=True, file=file)


class Group(click.Group):
    """A click group that reports baseparams' own errors as :class:`UserError` (exit 2) and
    anything else, a bug, as one line and exit code 3 (``--debug``: the traceback)."""
    group_class = type          # subgroups (``plot``) use this class too

    def invoke(self, ctx: click.Context) -> Any:
        if ctx.parent is not None:          # a subgroup (plot): the root handles everything
            return self._invoke(ctx)
        with interrupt_signals():
            try:
                return self._invoke(ctx)
            except KeyboardInterrupt:
                # Ctrl-C, SIGTERM or SIGHUP: the runners have stopped their workers (their
                # `finally`), an atomic write has removed its temporary file; one line, and
                # 128 + the signal's number, as a shell reports a process the signal ended
                click.echo("interrupted", err=True)
                ctx.exit(128 + (_received[-1] if _received else signal.SIGINT))

    def _invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except BaseparamsError as exc:
            raise UserError(getattr(exc, "message", str(exc))) from None
        except click.BadParameter as exc:
            raise UserError(bad_parameter(exc)) from None
        except click.BadOptionUsage as exc:       # an option without its value: "--format" at the end
            raise UserError(exc.format_message().rstrip(".")) from None
        except (click.ClickException, click.exceptions.Exit, click.Abort, KeyboardInterrupt):
            raise
        except MemoryError as exc:
            if ctx.find_root().params.get("debug"):
                raise
            raise UserError(out_of_memory(exc, ctx)) from None
        except Exception as exc:
            if ctx.find_root().params.get("debug"):
                raise
            click.echo(f"internal error: {type(exc).__name__}: {exc} (a bug in baseparams or a plugin; "
                       f"please report it; rerun with --debug for the traceback)", err=True)
            ctx.exit(INTERNAL_ERROR)


def bad_parameter(exc: click.BadParameter) -> str:
    """One line for an option's or argument's bad or missing value (``--format: 'xml' is not
    one of 'text', 'json'``), as every other bad input: click's three lines (usage, hint,
    error) were kept for usage errors proper, an unknown option or a missing argument
    (issue 46: a bad ``--format`` was the one option error not on one line)."""
    if isinstance(exc, click.MissingParameter):
        where = f" (see '{exc.ctx.command_path} --help')" if exc.ctx is not None else ""
        return exc.format_message().rstrip(".") + where
    hint = exc.param_hint if isinstance(exc.param_hint, str) else None
    if hint is None and exc.param is not None:
        hint = exc.param.get_error_hint(exc.ctx) if exc.ctx is not None else exc.param.name
    hint = (hint or "").replace("'", "")
    return f"{hint}: {exc.message}".rstrip(".") if hint else exc.message


def out_of_memory(exc: MemoryError, ctx: click.Context) -> str:
    """One line for a MemoryError, wherever it was raised: what was being allocated (numpy
    says: "Unable to allocate 7.28 TiB for an array with shape ..."), and the budget that
    refuses such work before it starts. Bad input (data or options too large for this
    machine), not a bug: exit 2 (issue 46: exit 3 at 3.6 GB under a 4 GB address-space cap
    with BASEPARAMS_MAX_MEMORY set far above it)."""
    from baseparams.dynamics.trajectory import MEMORY_VARIABLE, memory_limit
    try:
        budget = f"{memory_limit() / 2 ** 30:.3g} GiB"
    except BaseparamsError:
        budget = "not a size"
    what = str(exc).strip() or "an allocation failed"
    verb = ctx.invoked_subcommand or ctx.info_name or "the command"
    return (f"out of memory in '{verb}': {what}. The work needs more memory than this machine gives: use "
            f"fewer samples or smaller data, or set {MEMORY_VARIABLE} (now {budget}) to the memory the "
            f"machine has, so that such work is refused with an estimate before it starts")


INTERNAL_ERROR = 3
INTERRUPT_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
_received: list[int] = []


@contextlib.contextmanager
def interrupt_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP raise KeyboardInterrupt, as SIGINT does, while a verb runs, so
    that every cleanup (``finally``: workers killed, temporary files removed) runs for
    them too; the previous handlers come back afterwards. Only in the main thread (where
    Python delivers signals); elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        _received.append(signum)
        raise KeyboardInterrupt

    previous = {}
    for name in INTERRUPT_SIGNALS:
        number = getattr(signal, name, None)
        if number is None:
            continue
        try:
            if signal.getsignal(number) is signal.SIG_IGN:
                continue                    # nohup, or started in the background: keep ignoring
            previous[number] = signal.signal(number, interrupt)
        except (OSError, ValueError):
            pass
    _received.clear()
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def load(mech: str, warn: bool = True) -> "Mechanism":
    """A registered mechanism name or a path to a mechanism file -> Mechanism; its
    warnings (``Mechanism.warnings``) go to stderr unless ``warn`` is false."""
    return api_load(mech, warn=_warn if warn else None)


def _warn(message: str) -> None:
    click.echo(f"warning: {message}", err=True)


def _wrap(words: "Iterable[str]", indent: str = "  ") -> str:
    return textwrap.fill(" ".join(words), width=88, initial_indent=indent, subsequent_indent=indent)


def _version() -> str:
    installed = registry.installed_version()
    return __version__ if installed == "not installed" else installed


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=_version(), prog_name="baseparams")
@click.option("--debug", is_flag=True, help="Show the traceback of an internal error (exit code 3).")
def main(debug: bool) -> None:
    """Base inertial parameters of mechanisms.

    MECH is a registered mechanism name (see `baseparams list`) or a path to a
    mechanism file (TOML, its format: `python -m pydoc baseparams.io.toml_reader`;
    URDF). Exit codes: 0 success,
    1 a check failed, 2 bad input or usage (the message names the file, the key
    and the reason), 3 an internal error (a bug: rerun with --debug for the traceback).
    """


# ----- list ---------------------------------------------------------------------
@main.command("list")
@format_option()
@output_option()
def list_mechanisms(fmt: str, output: str | None) -> None:
    """List the registered mechanisms.

    One line per mechanism: its name (usable as MECH), the distribution that provides
    it and its title. JSON: {"mechanisms": [{"name", "title", "source", "path"}]}, where
    "source" is the providing distribution.
    """
    rows = []
    for name, reg in registry.mechanisms().items():
        row = {"name": name, "title": "", "source": reg.distribution, "path": str(reg.item.path)}
        try:
            row["title"] = load(name, warn=False).title
        except BaseparamsError as exc:      # one broken file must not hide the others
            row["error"] = getattr(exc, "message", str(exc))
        rows.append(row)

    def text() -> str:
        if not rows:
            return "no mechanisms registered"
        width = max(len(r["name"]) for r in rows)
        dist = max(len(r["source"]) for r in rows)
        return "\n".join(f"{r['name']:<{width}}  {r['source']:<{dist}}  "
                         + (f"error: {r['error']}" if "error" in r else r["title"]) for r in rows)

    emit(fmt, {"mechanisms": rows}, text, output)


# ----- show ---------------------------------------------------------------------
def describe(mech: "Mechanism") -> dict[str, Any]:
    """The structure of a mechanism as the ``show`` JSON object."""
    from baseparams.dynamics.evaluator import closure_structure
    structure = closure_structure(mech)
    tree = {edge.joint.name for edge in mech.tree}
    return {
        "name": mech.name,
        "title": mech.title,
        "citation": mech.source,
        "path": mech.path,
        "bodies": mech.body_labels,
        "body_names": [b.name for b in mech.bodies],
        "joints": [{"name": j.name, "type": j.type.name, "parent": j.parent, "child": j.child,
                    "role": "tree" if j.name in tree else "loop",
                    "coordinates": list(j.coordinates) if j.name in tree else []}
                   for j in mech.joints],
        "coordinates": list(mech.coordinates),
        "independent": [mech.coordinates[i] for i in structure.independent],
        "loops": len(mech.loops),
        "dof": structure.dof,
        "gruebler": mech.gruebler,
        "closure_equations": mech.closure_equation_count,
        "redundant_closure_equations": structure.redundant,
        "parameter_count": len(mech.parameters),
        "parameters": list(mech.parameters),
        "geometry": mech.geometry_text,
        "warnings": list(mech.warnings),
    }


def describe_text(info: dict[str, Any]) -> str:
    lines = [f"{info['name']}: {info['title']}" if info["title"] else info["name"]]
    if info["path"]:
        lines.append(f"  file: {info['path']}")
    if info["citation"]:
        lines.extend(_wrap(f"source: {info['citation']}".split(), indent="  ").splitlines())
    lines.append(f"bodies ({len(info['bodies'])}, ground is 0):")
    lines += [f"  {label:>3}  {name}" for label, name in zip(info["bodies"], info["body_names"])]
    lines.append(f"joints ({len(info['joints'])}):")
    width = max(len(j["name"]) for j in info["joints"])
    tw = max(len(j["type"]) for j in info["joints"])
    for j in info["joints"]:
        coords = " ".join(j["coordinates"]) if j["role"] == "tree" else "(closes a loop)"
        lines.append(f"  {j['name']:<{width}}  {j['type']:<{tw}}  {j['parent']:>2} -> {j['child']:<2}  "
                     f"{j['role']:<4}  {coords}")
    lines.append(f"tree coordinates ({len(info['coordinates'])}):")
    lines.append(_wrap(info["coordinates"]))
    lines.append(f"independent coordinates ({len(info['independent'])}): {' '.join(info['independent'])}")
    lines.append(f"loops: {info['loops']} ({info['closure_equations']} closure equations, "
                 f"{info['redundant_closure_equations']} redundant)")
    lines.append(f"degrees of freedom: {info['dof']} (Gruebler count {info['gruebler']})")
    if info["geometry"]:
        lines.append(f"geometry ({len(info['geometry'])}, exact):")
        lines.append(_wrap(f"{k}={v}" for k, v in info["geometry"].items()))
    lines.append(f"inertial parameters ({info['parameter_count']}):")
    lines.append(_wrap(info["parameters"]))
    return "\n".join(lines)


@main.command()
@click.argument("mech", metavar="MECH")
@format_option()
@output_option()
def show(mech: str, fmt: str, output: str | None) -> None:
    """Show a mechanism's bodies, joints, coordinates and parameters.

    Joints are marked as spanning-tree joints (with their coordinates) or loop-closing
    joints. The degrees of freedom are the tree coordinates minus the rank of the
    loop-closure Jacobian; the Gruebler count and the number of redundant closure
    equations are printed beside them. MECH is a registered name or a path to a
    mechanism file.
    """
    from baseparams.io.loader import check_trajectory
    mechanism = load(mech)
    info = describe(mechanism)
    check_trajectory(mechanism)          # what solve checks before solving (issue 13)
    emit(fmt, info, lambda: describe_text(info), output)


# ----- plugins ------------------------------------------------------------------
@main.command()
@format_option()
@output_option()
def plugins(fmt: str, output: str | None) -> None:
    """List the installed plugins and the distributions providing them.

    Joint types, solvers, mechanisms, model effects, mechanism-file readers and writers. Built-ins come from the
    `baseparams` distribution; a third party registers its own through the `baseparams`
    entry-point group (`python -m pydoc baseparams.hookspecs`). A joint type marked [no transfer rules]
    makes the symbolic solver's rank an upper bound.
    """
    def entry(name: str, reg: Any, **extra: Any) -> dict[str, Any]:
        out = {"name": name, "distribution": reg.distribution}
        if getattr(reg.item, "description", ""):
            out["description"] = reg.item.description
        return {**out, **extra}

    data = {
        "joints": [entry(n, r, dof=r.item.dof, suffixes=list(r.item.suffixes),
                         transfer_rules=registry.transfer_rules(n) is not None)
                   for n, r in registry.joint_types().items()],
        "solvers": [entry(n, r, **(describe_solver(r.item) if isinstance(r.item, Solver) else {}))
                    for n, r in registry.solvers().items()],
        "mechanisms": [entry(n, r, path=str(r.item.path)) for n, r in registry.mechanisms().items()],
        "effects": [entry(n, r) for n, r in registry.effects().items()],
        "readers": [entry(n, r, suffixes=list(r.item.suffixes)) for n, r in registry.readers().items()],
        "writers": [entry(n, r, suffixes=list(r.item.suffixes)) for n, r in registry.writers().items()],
    }

    def text() -> str:
        lines = []
        for kind, items in data.items():
            lines.append(f"{kind} ({len(items)}):")
            width = max([len(i["name"]) for i in items] + [1])
            dist = max([len(i["distribution"]) for i in items] + [1])
            for i in items:
                note = i.get("description") or i.get("path", "")
                if kind in ("readers", "writers"):
                    note = f"{' '.join(i['suffixes'])}  {note}"
                if kind == "joints" and not i["transfer_rules"]:
                    note += " [no transfer rules]"
                lines.append(f"  {i['name']:<{width}}  {i['distribution']:<{dist}}  {note}".rstrip())
            if not items:
                lines.append("  (none)")
        return "\n".join(lines)

    emit(fmt, data, text, output)


# ----- solve --------------------------------------------------------------------
def _progress(message: str) -> None:
    """A solver's own progress line, on stderr (``solve`` alone shows them)."""
    click.echo(message, err=True)


def capability_words(caps: Capabilities) -> list[str]:
    """A solver's capabilities in a few words (help texts)."""
    words = ["closed loops" if caps.closed_loops else "open chains only"]
    words += [w for flag, w in ((caps.needs_rational_geometry, "rational geometry only"),
                                (caps.certifies, "certifies the rank"),
                                (caps.exact_coefficients, "exact coefficients"),
                                (caps.symbolic_coefficients, "symbolic coefficients"),
                                (caps.derivation, "derivation (`report`)")) if flag]
    return words


class SolverListCommand(click.Command):
    """A command whose help ends with every registered solver, its capabilities and options
    (read from the registry when the help is shown, so plugins' solvers are listed too)."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        try:
            solvers = registry.solvers()
        except BaseparamsError as exc:
            formatter.write_paragraph()
            formatter.write_text(f"(registered solvers unavailable: {getattr(exc, 'message', exc)})")
            return
        with formatter.section("Registered solvers (--solver NAME; their options: -O NAME=VALUE)"):
            for name, reg in solvers.items():
                item = reg.item
                if not isinstance(item, Solver):
                    formatter.write_dl([(name, f"{getattr(item, 'description', '')} [not a Solver: "
                                               f"unusable]")])
                    continue
                formatter.write_dl([(name, f"{item.description} ({'; '.join(capability_words(item.capabilities))}; "
                                           f"from {reg.distribution})")])
                with formatter.indentation():
                    formatter.write_dl([(f"-O {o.name}", o.describe()) for o in item.options]
                                       or [("", "(no options)")])
        super().format_epilog(ctx, formatter)


def given_options(solver: Solver, extra: tuple[str, ...], **named: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the solver options of ``-O NAME=VALUE``, the named front-door options ``--digits``,
    ``--samples``, ``--seed`` given), checked against what the solver declares before any
    file is read. A named option the solver does not declare is dropped with a warning (dp
    has no digits); an undeclared ``-O`` option is an error."""
    given = options_from_text(solver, extra)
    common = {name: value for name, value in named.items() if value is not None}
    for name in common:
        if name in given:
            raise UserError(f"--{name} and -O {name}=... both given; give one")
    solver_options(solver, given, common=common)
    return given, common


@main.command(cls=SolverListCommand)
@click.argument("mech", metavar="MECH")
@solver_option(help="A registered solver (all are listed below).")
@click.option("--digits", type=click.IntRange(10, 20000), default=None,
              help="Fix the working precision of a variable-precision solver [default: automatic]; "
                   "dp and exact ignore it with a warning.")
@samples_option(help="Samples of the exciting trajectory (or random states, for exact) [default: the mechanism file's].")
@seed_option(help="Seed of the solver's random states (solvers that declare a seed option).", default=None)
@solver_options_option()
@format_option("text", "json", "csv",
               help="Output format: readable text, one JSON object, or CSV (name,expression: one row per "
                    "base parameter, coefficients as the text and JSON write them).")
@output_option()
@quiet_option()
def solve(mech: str, solver_name: str, digits: int | None, samples: int | None, seed: int | None,
          extra: tuple[str, ...], fmt: str, output: str | None, quiet: bool) -> None:
    """Base inertial parameters of MECH: rank, kept and grouped parameters, and the
    base parameter expressions phi_b = phi_1 + beta phi_2.

    Progress (the solver's own lines; --quiet: none) and warnings (e.g. no clear ridge in the
    singular values) go to stderr.
    A coefficient prints the same in text and CSV: an exact value as its exact string (1,
    0.20898125, 625/251), any other with exactly the digits the solver trusts; JSON writes the
    latter as a number with that decimal under "decimals". A solver that does not
    take MECH (exact on a closed loop) says why: `not applicable: <reason>`, exit code 2.
    """
    from baseparams.api import solve as api_solve
    given, common = given_options(get_solver(solver_name), extra, digits=digits, samples=samples, seed=seed)
    solution = api_solve(load(mech), solver_name, solver_options=given, common=common,
                         progress=None if quiet else _progress)
    for warning in solution.result.warnings:
        click.echo(f"warning: {warning}", err=True)
    if fmt == "csv":
        write_output(output, base_csv(solution.result).rstrip("\n"))
        return
    emit(fmt, solution.to_json(), solution.to_text, output)


def base_csv(result: "BaseParameterResult") -> str:
    """``name,expression`` rows, one per base parameter; the expression keeps every digit
    the solver wrote (``m2 + 0.5*mx3 - (L**2)*Izz1``)."""
    from baseparams.api.results import expression_text
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["name", "expression"])
    for b in result.base:
        writer.writerow([b["name"], expression_text(b["expression"])])
    return out.getvalue()


# ----- plot ---------------------------------------------------------------------
@main.group()
def plot() -> None:
    """Write figures (PNG, PDF or SVG)."""


def old_image_format() -> Any:
    """The ``--format png|pdf|svg`` of earlier releases on plot verbs (hidden, deprecated)."""
    return click.option("--format", "old_format", type=click.Choice(["png", "pdf", "svg"]), default=None, hidden=True,
                        help="Deprecated: --image-format.")


def chosen_image_format(new: str | None, old: str | None) -> str | None:
    """``--image-format``, or the deprecated ``--format`` with a note on stderr."""
    if old is not None:
        click.echo("note: --format on plot verbs is deprecated; use --image-format (or the file's suffix)", err=True)
    return new or old


@plot.command("mechanism")
@click.argument("mech", metavar="MECH")
@output_option(help="Image file to write (its suffix chooses the format).", required=True)
@click.option("--instants", type=click.IntRange(1, 12), default=4, show_default=True,
              help="Configurations of the default trajectory to draw (they span the range "
                   "of the first independent coordinate).")
@image_format_option()
@old_image_format()
def plot_mechanism(mech: str, output: str, instants: int, image_format: str | None, old_format: str | None) -> None:
    """Draw MECH in 3D at a few instants of its default trajectory.

    Bodies are segments between their joints (wheels are discs), ground joints black
    markers; the instants span the range of the first independent coordinate and the
    larger values are drawn darker. Without a default trajectory the reference
    configuration is drawn.
    """
    from baseparams.cli.plots import plot_mechanism as draw
    fmt = chosen_image_format(image_format, old_format)
    written = draw(load(mech), output, instants=instants, fmt=fmt)
    click.echo(f"wrote {written}")


@plot.command("singular-values")
@click.argument("mech", metavar="MECH")
@output_option(help="Image file to write (its suffix chooses the format).", required=True)
@solvers_option(help="A solver whose singular values to draw.", default=("dp", "vp"))
@click.option("--digits", type=click.IntRange(10, 20000), default=30, show_default=True,
              help="Precision of variable-precision solvers (the seed paper's figure uses 30).")
@samples_option()
@image_format_option()
@old_image_format()
@quiet_option()
def plot_singular_values(mech: str, output: str, solver_names: tuple[str, ...], old_solvers: str | None,
                         digits: int, samples: int | None, image_format: str | None, old_format: str | None,
                         quiet: bool) -> None:
    """Singular values of the (column-scaled) observation matrix of MECH, one series per
    solver on one log scale, with each solver's rank marked: the seed paper's figure of
    DP (*) against VP (+)."""
    from baseparams.cli.plots import plot_singular_values as draw
    fmt = chosen_image_format(image_format, old_format)
    mechanism = load(mech)
    results = []
    for name in chosen_solvers(solver_names, old_solvers):
        solver = get_solver(name)
        wanted = {"digits": digits, "recover": False, "samples": samples}
        declared = {o.name for o in solver.options}
        options = check_options(solver, {k: v for k, v in wanted.items() if k in declared and v is not None})
        result = run_solver(solver, mechanism, options, progress=None if quiet else _progress)
        if not result.singular_values:
            raise UserError(f"solver {name!r} gives no singular values to plot")
        results.append(result)
    written = draw(results, output, fmt=fmt)
    click.echo(f"wrote {written}")


# ----- report (symbolic derivation) -------------------------------------------------
@main.command()
@click.argument("mech", metavar="MECH")
@solver_option(help="A registered solver that gives a derivation (its capabilities say so).", default="symbolic")
@solver_options_option()
@format_option("text", "markdown", "latex", help="Rendering of the derivation.")
@click.option("--keep", default="", help="Parameters never to eliminate (comma separated).")
@click.option("--eliminate-first", "first", default="",
              help="Parameters to eliminate whenever a transfer allows it (comma separated).")
@click.option("--no-certify", is_flag=True, help="Skip the ball-arithmetic rank check (faster).")
@output_option()
def report(mech: str, solver_name: str, extra: tuple[str, ...], fmt: str, keep: str, first: str, no_certify: bool,
           output: str | None) -> None:
    """Derive MECH's base parameters by multipole transfers and print the derivation.

    Like the seed paper's Tabs. 4-5 and appendix: parameters without effect (per body and
    condition), the transfer at each joint and the parameter it eliminates, every step's
    values, the base parameters and how the rank was checked (`python -m pydoc
    baseparams.plugins.solvers.symbolic`). Any
    solver whose capabilities include a derivation may be chosen (built in: symbolic);
    --keep, --eliminate-first and --no-certify are passed as its options of those names
    (keep, eliminate_first, certify), -O NAME=VALUE any option it declares.
    """
    from baseparams.cli.report import render
    solver = get_solver(solver_name)
    if not solver.capabilities.derivation:
        able = [n for n, r in registry.solvers().items()
                if isinstance(r.item, Solver) and r.item.capabilities.derivation]
        raise UserError(f"solver {solver_name!r} gives no derivation; solvers that do: "
                        f"{', '.join(able) or '(none)'}")
    given = options_from_text(solver, extra)
    for flag, name, value in (("--keep", "keep", keep or None), ("--eliminate-first", "eliminate_first", first or None),
                              ("--no-certify", "certify", False if no_certify else None)):
        if value is not None:
            if name in given:
                raise UserError(f"{flag} and -O {name}=... both given; give one")
            given[name] = value
    check_options(solver, given)
    result = run_solver(solver, load(mech), given)
    if result.diagnostics.derivation is None:
        raise UserError(f"solver {solver_name!r} declares a derivation but its result has none")
    text = render(result, fmt)
    if output is not None:                  # -o "" is a bad file name, not standard output
        from baseparams.io.atomic import atomic_write
        atomic_write(output, text, what="the report")     # a full disk keeps the old file whole
        click.echo(f"wrote {output}", err=True)        # as every -o FILE: stdout stays empty
    else:
        click.echo(text, nl=False)


