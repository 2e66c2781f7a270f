"""One atomic writer for every file a verb writes (report, export, convert, plot, ...).

A file is written to a temporary file in its own folder, flushed, fsynced and renamed over
the target (``os.replace``), so a full disk, a file-size limit (``ulimit -f``), Ctrl-C or
SIGKILL mid-write leaves either the old file or the new one, never a partial file. The
rename happens in one folder, hence on one filesystem, where POSIX makes it atomic.

Devices and pipes (``/dev/stdout``, ``/dev/full``, a FIFO) are written directly and never
replaced: a rename over ``/dev/full`` as root would turn the device into a regular file.

Every failure is a :class:`~baseparams.errors.InputError` ``<file>: cannot write: <reason>``
(exit 2 in the CLI); the temporary file is removed whatever happens.
"""

import contextlib
import errno
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path

from baseparams.errors import InputError

_SPECIAL_ROOTS = ("/dev/", "/proc/")      # /dev/stdout -> /proc/self/fd/1 may resolve to a plain file
_TEMP_ATTEMPTS = 100


def is_device(path: str | os.PathLike) -> bool:
    """True for a path to write in place: an existing non-regular file (device, FIFO,
    socket), or anything under /dev or /proc (their links lead to other processes' files)."""
    text = os.path.abspath(os.fspath(path))
    if text.startswith(_SPECIAL_ROOTS):
        return True
    try:
        mode = os.stat(text).st_mode
    except OSError:
        return False
    return not stat.S_ISREG(mode) and not stat.S_ISDIR(mode)


def atomic_write(path: str | os.PathLike, data: str | bytes, what: str = "") -> None:
    """Write ``data`` (text as UTF-8, newlines untouched, or bytes) to ``path`` atomically.

    ``what`` names the content in the error ("the report": ``cannot write the report: ...``).
    """
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    if os.fspath(path) and "\0" not in os.fspath(path) and is_device(path):
        _write_in_place(path, payload, what)
        return
    with atomic_path(path, what) as temporary:
        try:
            fd = os.open(temporary, os.O_WRONLY | os.O_TRUNC | getattr(os, "O_BINARY", 0))
        except OSError as exc:
            raise _error(path, what, exc) from None
        try:
            _write_all(fd, payload)
        except OSError as exc:
            raise _error(path, what, exc) from None
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, what: str = "") -> Iterator[Path]:
    """A temporary path (same folder, same suffix) to write ``path``'s new content to, e.g.
    by a writer plugin that takes a path; on a clean exit the file is fsynced and renamed
    over ``path``, on any exception (KeyboardInterrupt too) it is removed and ``path`` is
    untouched. For a device the path itself is given (written in place).

    An OSError inside the block becomes ``InputError("cannot write: ...")``.
    """
    if not os.fspath(path) or "\0" in os.fspath(path):
        raise InputError(f"cannot write{_what(what)}: not a file name", file=repr(os.fspath(path)))
    target = Path(path)
    if is_device(target):
        try:
            yield target
        except OSError as exc:
            raise _error(target, what, exc) from None
        return
    try:
        folder = stat.S_ISDIR(os.stat(target).st_mode)
    except OSError as exc:
        if exc.errno not in (errno.ENOENT,):        # a name too long, a file used as a folder ...
            raise _error(target, what, exc) from None
        folder = False
    if folder:
        raise InputError(f"cannot write{_what(what)}: it is a folder", file=target)
    temporary = _create_temporary(target, what)
    try:
        try:
            yield temporary
            _fsync_file(temporary)
            os.replace(temporary, target)
        except OSError as exc:
            raise _error(target, what, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise
    _fsync_folder(temporary.parent)


# ----- helpers -------------------------------------------------------------------------------
def _what(what: str) -> str:
    return f" {what}" if what else ""


def _error(path: str | os.PathLike[str], what: str, exc: OSError) -> InputError:
    return InputError(f"cannot write{_what(what)}: {exc.strerror or exc}", file=str(path))


def _create_temporary(target: Path, what: str) -> Path:
    """An empty file ``.<name>.<random>.tmp<suffix>`` next to ``target``, created exclusively
    with the mode a new file gets (0666 less the umask) or the target's own mode."""
    folder = target.parent
    try:
        mode = stat.S_IMODE(os.stat(target).st_mode)
    except OSError:
        mode = 0o666
    for _ in range(_TEMP_ATTEMPTS):
        # the stem shortened so that the temporary name is no longer than the target's
        candidate = folder / f".{target.stem[:max(1, len(target.stem) - 20)]}.{secrets.token_hex(4)}.tmp{target.suffix}"
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
        except FileExistsError:
            continue
        except OSError as exc:
            raise _error(target, what, exc) from None
        try:
            if mode != 0o666:
                os.fchmod(fd, mode)
        except (OSError, AttributeError):
            pass
        finally:
            os.close(fd)
        return candidate
    raise InputError(f"cannot write{_what(what)}: no free temporary name in {folder}", file=target)


def _write_all(fd: int, payload: bytes) -> None:
    view = memoryview(payload)
    while view:
        written = os.write(fd, view[:1 << 20])
        view = view[written:]
    os.fsync(fd)


def _write_in_place(path: str | os.PathLike[str], payload: bytes, what: str) -> None:
    try:
        fd = os.open(path, os.O_WRONLY | os.O_TRUNC | getattr(os, "O_BINARY", 0))
    except OSError as exc:
        raise _error(path, what, exc) from None
    try:
        view = memoryview(payload)
        while view:
            view = view[os.write(fd, view[:1 << 20]):]
    except OSError as exc:
        raise _error(path, what, exc) from None
    finally:
        os.close(fd)


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable where the platform allows (best effort)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
