"""Built-in mechanism-file readers and writers (TOML), registered like any third party's."""

from baseparams.hookspecs import hookimpl
from baseparams.io.formats import Reader, Writer
from baseparams.io.toml_reader import TomlReader
from baseparams.io.toml_writer import TomlWriter


@hookimpl
def baseparams_readers() -> list[Reader]:
    return [TomlReader()]


@hookimpl
def baseparams_writers() -> list[Writer]:
    return [TomlWriter()]
