"""The plugin manager: loads every ``baseparams`` entry point and answers registry questions.

Every hook is called through pluggy's hook callers (``pm.hook.<name>``), never by calling
an implementation's function: pluggy's argument checks and hook wrappers apply. List hooks
are called once per answering plugin (``pm.subset_hook_caller`` without the other
answering plugins; wrappers stay) so that each item keeps the distribution that provides
it, which ``baseparams plugins`` reports.
"""

from __future__ import annotations

import functools
import importlib.metadata
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

import pluggy

from baseparams import hookspecs
from baseparams.errors import InputError
from baseparams.formats import complete_reader

if TYPE_CHECKING:
    from baseparams.dynamics.effects import EffectKind
    from baseparams.formats import Reader, Writer
    from baseparams.model.joints import JointType
    from baseparams.model.multipoles import TransferRule
    from baseparams.solvers.protocol import Solver

T = TypeVar("T")
RUN_TIME = "(registered at run time)"


@dataclass(frozen=True)
class MechanismSource:
    name: str
    path: Path
    description: str = ""


@dataclass(frozen=True)
class Registered(Generic[T]):
    """A registered item with the distribution that provides it."""
    item: T
    distribution: str


@functools.lru_cache(maxsize=1)
def plugin_manager() -> pluggy.PluginManager:
    pm = pluggy.PluginManager("baseparams")
    pm.add_hookspecs(hookspecs)
    pm.load_setuptools_entrypoints("baseparams")
    return pm


def reset() -> None:
    """Forget cached answers and load the entry points of distributions installed since.

    Call it after registering a plugin at run time (``plugin_manager().register(obj)``) or
    unregistering one, or after installing a distribution in the running interpreter; plugins
    registered at run time stay registered.
    """
    _collect.cache_clear()
    plugin_manager().load_setuptools_entrypoints("baseparams")


def _distribution_of(pm: pluggy.PluginManager, plugin: object) -> str:
    for plug, dist in pm.list_plugin_distinfo():
        if plug is plugin:
            return str(dist.project_name if hasattr(dist, "project_name") else dist.metadata["name"])
    return RUN_TIME


@functools.lru_cache(maxsize=None)
def _collect(hook_name: str) -> tuple[Registered[Any], ...]:
    """Every item the plugins return from the list hook ``hook_name``, plugin by plugin in
    registration order, each with its distribution."""
    pm = plugin_manager()
    found: list[Registered[Any]] = []
    impls = getattr(pm.hook, hook_name).get_hookimpls()
    answering = [impl.plugin for impl in impls if not (impl.wrapper or impl.hookwrapper)]
    for plugin in answering:
        # the hook restricted to this plugin's answer (wrappers still wrap it)
        others = [p for p in answering if p is not plugin]
        dist = _distribution_of(pm, plugin)
        for answer in pm.subset_hook_caller(hook_name, remove_plugins=others)():
            found.extend(Registered(item, dist) for item in answer or [])
    return tuple(found)


class _Named(Protocol):
    @property
    def name(self) -> str: ...


N = TypeVar("N", bound=_Named)


class _ByName(Generic[N]):
    """A registry question: name -> Registered(item) of one list hook; a name registered
    twice is an InputError naming both distributions."""

    def __init__(self, hook_name: str, what: str, complete: Any = None) -> None:
        self.hook_name, self.what, self.complete = hook_name, what, complete
        self.__doc__ = f"name -> Registered({what}) of the ``{hook_name}`` hook, sorted by name."

    def __call__(self) -> dict[str, Registered[N]]:
        out: dict[str, Registered[N]] = {}
        for reg in _collect(self.hook_name):
            if self.complete is not None:
                reg = Registered(self.complete(reg.item), reg.distribution)
            name = reg.item.name
            if name in out:
                raise InputError(f"{self.what} {name!r} is registered twice "
                                 f"({out[name].distribution} and {reg.distribution})")
            out[name] = reg
        return dict(sorted(out.items()))


joint_types: _ByName[JointType] = _ByName("baseparams_joint_types", "joint type")
solvers: _ByName[Solver] = _ByName("baseparams_solvers", "solver")
effects: _ByName[EffectKind] = _ByName("baseparams_effects", "effect")
mechanisms: _ByName[MechanismSource] = _ByName("baseparams_mechanisms", "mechanism")
# readers are completed to the full Reader protocol (options, read_notes) where a plugin
# gives only name, suffixes and read
readers: _ByName[Reader] = _ByName("baseparams_readers", "reader", complete_reader)
writers: _ByName[Writer] = _ByName("baseparams_writers", "writer")


def transfer_rules(joint_type_name: str) -> list[TransferRule] | None:
    """The multipole-transfer rules of a joint type, or None if no plugin defines them."""
    rules: list[TransferRule] | None = plugin_manager().hook.baseparams_transfer_rules(
        joint_type=joint_type_name)
    return rules


def installed_version() -> str:
    try:
        return importlib.metadata.version("baseparams")
    except importlib.metadata.PackageNotFoundError:
        return "not installed"
