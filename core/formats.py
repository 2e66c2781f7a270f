"""What a mechanism-file format plugin provides: the :class:`Reader` and :class:`Writer`
protocols (hooks ``baseparams_readers`` and ``baseparams_writers``).

The registry hands every consumer (the loader, ``baseparams convert``) objects that satisfy
these protocols in full: a reader registered without ``options`` or ``read_notes`` is
completed by :func:`complete_reader`, so callers never probe for optional attributes.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from baseparams.hookspecs import hookimpl

if TYPE_CHECKING:
    from baseparams.model.mechanism import Mechanism


@runtime_checkable
class Reader(Protocol):
    """Reads one mechanism-file format.

    ``name``: the format (``"toml"``); ``suffixes``: the file suffixes it reads, lower-case
    with the dot (``(".toml",)``); ``options``: the names of the keyword options ``read``
    and ``read_notes`` accept (``baseparams convert`` offers them as flags), possibly empty.
    A bad file is an :class:`baseparams.errors.InputError` naming the file, key and reason.
    """

    name: str
    suffixes: tuple[str, ...]
    options: tuple[str, ...]

    def read(self, path: str | Path, **options: Any) -> Mechanism:
        """The mechanism in the file at ``path`` (the loader checks its mobility)."""
        ...

    def read_notes(self, path: str | Path, **options: Any) -> tuple[Mechanism, list[str]]:
        """The mechanism and notes on what was approximated or dropped (``convert`` prints them)."""
        ...


@runtime_checkable
class Writer(Protocol):
    """Writes one mechanism-file format: ``name``, ``suffixes`` (as a :class:`Reader`'s) and
    ``write(mechanism, path)``, returning notes on what the format could not hold."""

    name: str
    suffixes: tuple[str, ...]

    def write(self, mechanism: Mechanism, path: str | Path) -> list[str]:
        """Write ``mechanism`` to ``path``; the notes (possibly none) for the user."""
        ...


class _CompletedReader:
    """A registered reader that declares only ``name``, ``suffixes`` and ``read``, with the
    rest of :class:`Reader` filled in: no options, no notes."""

    options: tuple[str, ...] = ()

    def __init__(self, reader: Any) -> None:
        self.reader = reader
        self.name: str = reader.name
        self.suffixes: tuple[str, ...] = tuple(reader.suffixes)
        self.description: str = getattr(reader, "description", "")

    def read(self, path: str | Path, **options: Any) -> Mechanism:
        mechanism: Mechanism = self.reader.read(path, **options)
        return mechanism

    def read_notes(self, path: str | Path, **options: Any) -> tuple[Mechanism, list[str]]:
        return self.read(path, **options), []


def complete_reader(reader: Any) -> Reader:
    """``reader`` itself when it has every member of :class:`Reader`, else an adapter that
    adds ``options = ()`` and ``read_notes`` (returning no notes). The hook's documented
    minimum for a third party is ``name``, ``suffixes`` and ``read(path)``."""
    if isinstance(reader, Reader):
        return reader
    return _CompletedReader(reader)


def format_hooks(reader: Reader, writer: Writer) -> tuple[Callable[[], list[Reader]], Callable[[], list[Writer]]]:
    """The two hook implementations of a plugin module that provides one file format (a
    reader and a writer): ``baseparams_readers, baseparams_writers = format_hooks(r, w)``
    at the top of the module its entry point names. Writing the two ``@hookimpl``
    functions by hand registers the same way."""

    @hookimpl
    def baseparams_readers() -> list[Reader]:
        return [reader]

    @hookimpl
    def baseparams_writers() -> list[Writer]:
        return [writer]

    return baseparams_readers, baseparams_writers
