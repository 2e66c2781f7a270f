"""Built-in mechanism-file readers (TOML), registered like any third party's."""

from baseparams.hookspecs import hookimpl
from baseparams.io.toml_reader import TomlReader


@hookimpl
def baseparams_readers():
    return [TomlReader()]
