"""Hook specifications: every extension point of baseparams.

Built-in joint types, solvers, mechanisms, mechanism readers and model effects register
through these same hooks, from modules named in the ``baseparams`` entry-point group
exactly as a third party's distribution would (see ``pyproject.toml``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:       # annotations only: the registry imports this module
    from baseparams.dynamics.effects import EffectKind
    from baseparams.formats import Reader, Writer
    from baseparams.model.joints import JointType
    from baseparams.model.multipoles import TransferRule
    from baseparams.registry import MechanismSource
    from baseparams.solvers.protocol import Solver

hookspec = pluggy.HookspecMarker("baseparams")
hookimpl = pluggy.HookimplMarker("baseparams")


@hookspec
def baseparams_joint_types() -> list[JointType]:
    """Return a list of :class:`baseparams.model.joints.JointType` this plugin provides.

    A joint type supplies its coordinates (count, names, kinds), its motion (from which the
    child-to-parent transform follows in any backend: ``JointType.transform(q, backend)``)
    and the equations it imposes when it closes a loop.
    """


@hookspec(firstresult=True)
def baseparams_transfer_rules(joint_type: str) -> list[TransferRule] | None:
    """Return the multipole-transfer rules of the joint type named ``joint_type``.

    ``joint_type``: the type's name (``"R"``). Return a list of
    :class:`baseparams.model.multipoles.TransferRule` (possibly empty: nothing may cross), or
    None when this plugin does not know that type. The first non-None answer wins. The
    symbolic solver calls this for every joint of a mechanism; a type with no rules makes
    its symbolic result an upper bound on the rank, which it says.
    """


@hookspec
def baseparams_readers() -> list[Reader]:
    """Return a list of mechanism readers, :class:`baseparams.formats.Reader`: ``name``
    (``"toml"``), ``suffixes`` (lower-case, with the dot: ``(".toml",)``), ``options``,
    ``read(path, **options)`` returning a :class:`baseparams.model.mechanism.Mechanism` and
    ``read_notes(path, **options)`` returning it with notes.

    A reader walks its format and builds the mechanism with
    :class:`baseparams.model.builder.MechanismBuilder`, passing each value's key path in
    its format so errors name it; it raises :class:`baseparams.errors.InputError` for a bad
    file. A mechanism file given by path is read by the reader of its suffix; two readers
    may not claim the same suffix. ``options`` names the keyword options ``read`` accepts,
    which ``baseparams convert`` offers as flags (``merge_fixed``, ``floating_base``);
    ``convert`` prints the notes of ``read_notes``. A reader with only ``name``, ``suffixes``
    and ``read(path)`` is accepted too: the registry completes it with no options and no
    notes (:func:`baseparams.formats.complete_reader`).
    """


@hookspec
def baseparams_writers() -> list[Writer]:
    """Return a list of mechanism writers, :class:`baseparams.formats.Writer`: ``name`` (``"urdf"``), ``suffixes``
    (lower-case, with the dot) and ``write(mechanism, path)``, which writes the mechanism
    in their format (``baseparams convert``) and returns a list of notes (what the format
    could not hold, what was approximated). A bad request is an
    :class:`baseparams.errors.InputError`; two writers may not claim the same suffix.
    """


@hookspec
def baseparams_mechanisms() -> list[MechanismSource]:
    """Return a list of :class:`baseparams.registry.MechanismSource` (name + TOML file)."""


@hookspec
def baseparams_solvers() -> list[Solver]:
    """Return a list of solvers, each satisfying :class:`baseparams.solvers.protocol.Solver`:
    ``name``, ``description``, ``capabilities`` (a ``Capabilities``), ``options`` (a tuple of
    ``SolverOption``: every keyword ``solve`` accepts), ``applicable(mechanism)`` (None, or
    the reason it cannot treat the mechanism) and
    ``solve(mechanism, *, progress=None, **options)`` returning a
    :class:`baseparams.solvers.result.BaseParameterResult`. See docs/solvers.md, "Writing a
    solver"."""


@hookspec
def baseparams_effects() -> list[EffectKind]:
    """Return a list of effect kinds (friction, spring, offset ...) satisfying
    :class:`baseparams.dynamics.effects.EffectKind`, usually
    :class:`baseparams.dynamics.effects.Effect` objects: ``name``, ``description``,
    ``coefficients`` and ``columns(q, qd, qdd, **options)``, the extra regressor columns
    (one per coefficient) of a force linear in its coefficients, evaluated on one joint
    coordinate's samples."""
