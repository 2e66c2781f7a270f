"""The plugin manager: loads every ``baseparams`` entry point and answers registry questions."""

import functools
import importlib.metadata
from dataclasses import dataclass
from pathlib import Path

import pluggy

from baseparams import hookspecs
from baseparams.errors import InputError


@dataclass(frozen=True)
class MechanismSource:
    name: str
    path: Path
    description: str = ""


@dataclass(frozen=True)
class Registered:
    """A registered item with the distribution that provides it."""
    item: object
    distribution: str


@functools.lru_cache(maxsize=1)
def plugin_manager():
    pm = pluggy.PluginManager("baseparams")
    pm.add_hookspecs(hookspecs)
    pm.load_setuptools_entrypoints("baseparams")
    return pm


def reset():
    """Forget cached answers and load the entry points of distributions installed since.

    Call it after registering a plugin at run time (``plugin_manager().register(obj)``) or
    unregistering one, or after installing a distribution in the running interpreter; plugins
    registered at run time stay registered.
    """
    _collect.cache_clear()
    plugin_manager().load_setuptools_entrypoints("baseparams")


def _distribution_of(pm, plugin):
    for plug, dist in pm.list_plugin_distinfo():
        if plug is plugin:
            return dist.project_name if hasattr(dist, "project_name") else dist.metadata["name"]
    return "(registered at run time)"


@functools.lru_cache(maxsize=None)
def _collect(hook_name):
    pm = plugin_manager()
    caller = getattr(pm.hook, hook_name)
    found = []
    for impl in caller.get_hookimpls():
        dist = _distribution_of(pm, impl.plugin)
        for item in impl.function() or []:
            found.append(Registered(item, dist))
    return tuple(found)


def joint_types():
    """name -> Registered(JointType). A later duplicate name is an error."""
    return _by_name("baseparams_joint_types", "joint type")


def solvers():
    return _by_name("baseparams_solvers", "solver")


def effects():
    return _by_name("baseparams_effects", "effect")


def mechanisms():
    return _by_name("baseparams_mechanisms", "mechanism")


def readers():
    """name -> Registered(reader): mechanism-file readers (``name``, ``suffixes``, ``read(path)``)."""
    return _by_name("baseparams_readers", "reader")


def writers():
    """name -> Registered(writer): mechanism-file writers (``name``, ``suffixes``, ``write(mechanism, path)``)."""
    return _by_name("baseparams_writers", "writer")


def _by_name(hook_name, what):
    out = {}
    for reg in _collect(hook_name):
        name = reg.item.name
        if name in out:
            raise InputError(f"{what} {name!r} is registered twice "
                             f"({out[name].distribution} and {reg.distribution})")
        out[name] = reg
    return dict(sorted(out.items()))


def transfer_rules(joint_type_name):
    """The multipole-transfer rules of a joint type, or None if no plugin defines them."""
    return plugin_manager().hook.baseparams_transfer_rules(joint_type=joint_type_name)


def installed_version():
    try:
        return importlib.metadata.version("baseparams")
    except importlib.metadata.PackageNotFoundError:
        return "not installed"
