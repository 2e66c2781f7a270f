"""URDF in and out (docs/urdf.md): the reader and the writer, registered like any third party's."""

from baseparams.formats import format_hooks

from .reader import UrdfReader
from .writer import UrdfWriter

baseparams_readers, baseparams_writers = format_hooks(UrdfReader(), UrdfWriter())
