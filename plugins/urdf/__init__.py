"""URDF in and out (docs/urdf.md): the reader and the writer, registered like any third party's."""

from baseparams.hookspecs import hookimpl
from baseparams.io.formats import Reader, Writer

from .reader import UrdfReader
from .writer import UrdfWriter


@hookimpl
def baseparams_readers() -> list[Reader]:
    return [UrdfReader()]


@hookimpl
def baseparams_writers() -> list[Writer]:
    return [UrdfWriter()]
