"""URDF in and out (docs/urdf.md): the reader and the writer, registered like any third party's."""

from baseparams.hookspecs import hookimpl

from .reader import UrdfReader
from .writer import UrdfWriter


@hookimpl
def baseparams_readers():
    return [UrdfReader()]


@hookimpl
def baseparams_writers():
    return [UrdfWriter()]
