"""Built-in mechanism-file readers and writers (TOML), registered like any third party's."""

from baseparams.hookspecs import hookimpl
from baseparams.io.toml_reader import TomlReader
from baseparams.io.toml_writer import TomlWriter


@hookimpl
def baseparams_readers():
    return [TomlReader()]


@hookimpl
def baseparams_writers():
    return [TomlWriter()]
