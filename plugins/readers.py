"""Built-in mechanism-file reader and writer (TOML), registered like any third party's."""

from baseparams.formats import format_hooks
from baseparams.io.toml_reader import TomlReader
from baseparams.io.toml_writer import TomlWriter

baseparams_readers, baseparams_writers = format_hooks(TomlReader(), TomlWriter())
