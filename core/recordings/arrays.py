"""Logs saved as arrays (NumPy ``.npz``, MATLAB ``.mat``) read as named columns, so a
recording description maps them as it maps a CSV log's columns.

A one-dimensional variable is a column under its name (``t``); a two-dimensional one is a
column per channel, ``NAME[i]`` counted from 0 (``q[0]`` .. ``q[6]``), whichever way round it
was saved (samples along its longer axis: a log has more samples than channels). A MATLAB
struct's fields are ``STRUCT.FIELD`` (``log.q[2]``). Text, cells and other variables are not
columns. MATLAB v7.3 files are HDF5, which ``scipy.io.loadmat`` does not read: saved with
``-v7`` they are. Why: a researcher's log is often a ``.mat`` or ``.npz`` file, which had to be
converted to CSV by hand.

Memory is known before it is spent (issue 46): only the variables the description uses are
read, and each one's declared size (a ``.npy`` member's header: shape and dtype; a MATLAB
element's tag and dimensions) is checked against the read budget (:mod:`.budget`) before a
byte of its data is read. A compressed file is small on disk and large in memory (a 2.4 MB
``.npz`` of zeros holds 2.4 GB), and a header may declare any shape (10^12 samples): both are
refused with the estimate, never allocated.
"""

import os
import re
import struct
import zipfile
import zlib
from collections import Counter
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass, replace
from math import prod
from typing import IO, TypeVar

import numpy as np

from baseparams.errors import InputError
from baseparams.recordings.budget import read_budget

SUFFIXES = (".npz", ".mat")


def is_array_file(path: str | os.PathLike) -> bool:
    """A log saved as arrays (by its suffix), read by :func:`read_arrays`."""
    return str(path).lower().endswith(SUFFIXES)


@dataclass(frozen=True)
class Variable:
    """One variable of an array file as its header declares it, before its data is read:
    ``columns`` the column names it gives (None: only known once read, a MATLAB struct's),
    ``declared`` the bytes reading it takes (its data, and a float64 copy where the values are
    converted)."""
    name: str
    columns: tuple[str, ...] | None
    declared: int
    what: str                       # its shape and type as declared, for messages
    placeholder: str = ""           # its columns in the list of names while not read (columns None)
    offset: int = -1                # a MATLAB v5 element's position in the file


def read_arrays(path: str, wanted: Collection[str] | None = None, dates: Collection[str] = ()
                ) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """(names, the ``wanted`` columns by name as float64, each sample's row from 1) of an
    array file, as :func:`.data.read_columns` gives a CSV log's. Only the variables holding a
    wanted column are read (all when ``wanted`` is None), after their declared size is checked
    against the read budget. The wanted columns must have one length; in them an infinite
    value, a non-number or a complex value (with an imaginary part other than 0) is an error
    naming its row and column (NaN is a missing value, left out later). ``dates``: datetime64
    columns, read as nanoseconds since 1970 (the ``iso`` time unit's)."""
    path = str(path)
    kind = "a NumPy .npz" if path.lower().endswith(".npz") else "a MATLAB .mat"
    try:
        size = os.path.getsize(path)
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=path) from None
    if size == 0:
        raise InputError(f"empty file (0 bytes): not {kind} file", file=path)
    try:
        if kind == "a NumPy .npz":
            variables, names, loaded = _npz(path, wanted)
        else:
            variables, names, loaded = _mat(path, wanted)
    except InputError:
        raise
    except MemoryError:
        raise InputError(_too_large_message(path, None, "reading its variables ran out of memory"),
                         file=path) from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, struct.error, NotImplementedError,
            RuntimeError, TypeError, KeyError, IndexError, OverflowError, AttributeError, UnicodeDecodeError,
            RecursionError) as exc:
        raise InputError(f"cannot read as {kind} file: {exc or type(exc).__name__}", file=path) from None
    except Exception as exc:            # scipy's MatReadError and its kin: a file that is not a .mat
        if type(exc).__module__.startswith("scipy."):
            raise InputError(f"cannot read as {kind} file: {exc or type(exc).__name__}", file=path) from None
        raise
    del variables
    twice = sorted(n for n, k in Counter(names).items() if k > 1 and (wanted is None or n in wanted))
    if twice:                       # a variable named "q[0]" beside a 2-D q: which one is meant?
        raise InputError(f"column {twice[0]!r} appears twice (a variable of that name, and a channel of "
                         f"{_variable_of(twice[0])!r}): rename one", file=path)
    chosen = [n for n in names if n in loaded and (wanted is None or n in wanted)]
    lengths = {n: len(loaded[n]) for n in chosen}
    if len(set(lengths.values())) > 1:
        shown = ", ".join(f"{n}: {k}" for n, k in lengths.items())
        raise InputError(f"the columns used have different lengths ({shown})", file=path)
    values: dict[str, np.ndarray] = {}
    for name in chosen:
        values[name] = _column(path, name, loaded[name], name in dates)
    count = next(iter(lengths.values()), 0)
    if wanted is not None and count == 0 and chosen:
        raise InputError("no samples", file=path)
    return names, values, list(range(1, count + 1))


def _column(path: str, name: str, column: np.ndarray, date: bool) -> np.ndarray:
    """A used column as float64 (dates: int64 nanoseconds), or the InputError naming it."""
    if date:
        if not np.issubdtype(column.dtype, np.datetime64):
            raise InputError("not dates and times (datetime64): give the time in a unit instead",
                             file=path, key=f"column {name}")
        return column.astype("datetime64[ns]").astype(np.int64)
    if np.issubdtype(column.dtype, np.complexfloating):
        imaginary = np.flatnonzero(column.imag != 0)
        if imaginary.size:
            k = int(imaginary[0])
            raise InputError(f"complex values (variable {_variable_of(name)!r}): {column[k]} has an imaginary part; "
                             "a column of real numbers is needed (save the real part, or the magnitude, "
                             "as the quantity logged)", file=path, key=f"row {k + 1}, column {name}")
        column = column.real
    if not (np.issubdtype(column.dtype, np.number) or column.dtype == bool):
        raise InputError(f"holds {column.dtype} values, not numbers", file=path, key=f"column {name}")
    out = np.asarray(column, dtype=float)
    bad = np.flatnonzero(np.isinf(out))
    if bad.size:
        raise InputError(f"{out[bad[0]]} is not a finite number", file=path,
                         key=f"row {int(bad[0]) + 1}, column {name}")
    return out


def _variable_of(column: str) -> str:
    """The top-level variable a column comes from: ``log`` of ``log.q[2]``, ``q`` of ``q[0]``."""
    match = re.match(r"[^.\[]+", column)
    return match[0] if match else column


def _used(variables: list[Variable], wanted: Collection[str] | None) -> list[Variable]:
    """The variables holding a wanted column (every one when ``wanted`` is None)."""
    if wanted is None:
        return list(variables)
    tops = {_variable_of(w) for w in wanted}
    return [v for v in variables if (v.columns is None and v.name in tops)
            or (v.columns is not None and any(c in wanted for c in v.columns))]


def _check_budget(path: str, used: list[Variable]) -> None:
    """Refuse (InputError, with the estimate) variables whose declared size exceeds the read
    budget, before any of their data is read."""
    need = sum(v.declared for v in used)
    if need > read_budget():
        largest = max(used, key=lambda v: v.declared)
        raise InputError(_too_large_message(path, need, f"variable {largest.name!r} declares {largest.what}"),
                         file=path)


def _too_large_message(path: str, need: int | None, what: str) -> str:
    from baseparams.dynamics.trajectory import MEMORY_VARIABLE, memory_limit
    budget = read_budget()
    estimate = f"reading the variables used would take about {_size(need)}, " if need is not None else ""
    return (f"{what}: {estimate}above the limit for a data file of {_size(budget)} (a sixth of "
            f"{MEMORY_VARIABLE}, {_size(memory_limit())}); save fewer samples or channels, split the log into "
            f"runs, or raise the limit with the environment variable {MEMORY_VARIABLE} (e.g. {MEMORY_VARIABLE}=16G)")


def _size(count: int | None) -> str:
    value = float(count or 0)
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB"):
        if value < 1000 or unit == "PB":
            return f"{value:.0f} {unit}" if unit == "bytes" else f"{value:.3g} {unit}"
        value /= 1000
    return f"{value:.3g} PB"


# A variable with more channels than this has more than MAX_FILE_BYTES values, which no budget
# reads: its names are not spelled out (a header may declare 10^9 x 10^9), it is used when its
# name is, and refused then.
MAX_CHANNELS = 50_000


def _columns_of(name: str, shape: tuple[int, ...]) -> tuple[str, ...] | None:
    """The column names a numeric variable of ``shape`` gives (as :func:`_columns`); None for
    one wider than MAX_CHANNELS."""
    if len(shape) == 1:
        return (name,)
    if len(shape) != 2:
        return ()
    channels = min(shape)
    if channels == 1:
        return (name,)
    if channels > MAX_CHANNELS:
        return None
    return tuple(f"{name}[{k}]" for k in range(channels))


T = TypeVar("T")


def _foreign(call: Callable[[], T]) -> T:
    """``call()``, a parser of numpy's or scipy's reading the file's bytes: whatever it raises
    on bytes it does not expect (a TokenError from numpy's header parser, scipy's
    UnboundLocalError on a damaged .mat, both found by flipping bytes) is a file that cannot be
    read (ValueError here, an InputError above), not a bug of ours; running out of memory stays
    a MemoryError."""
    try:
        return call()
    except MemoryError:
        raise
    except Exception as exc:
        raise ValueError(f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__) from None


# ----- NumPy .npz -------------------------------------------------------------------------
def _npz(path: str, wanted: Collection[str] | None
         ) -> tuple[list[Variable], list[str], dict[str, np.ndarray]]:
    """The variables (from their headers), every column's name, and the used columns read."""
    with zipfile.ZipFile(path) as archive:
        variables: list[Variable] = []
        members: dict[str, str] = {}
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                continue
            name = info.filename[:-4]
            with archive.open(info) as fp:
                shape, dtype = _foreign(lambda: _npy_header(fp))
            members[name] = info.filename
            if dtype.hasobject or dtype.fields is not None or len(shape) not in (1, 2):
                continue                                         # not columns: never read
            count = prod(shape)
            converted = count * 8 if dtype != np.float64 else 0  # the float64 copy of the values
            variables.append(Variable(name, _columns_of(name, shape), count * dtype.itemsize + converted,
                                      f"shape {shape} of {dtype} ({_size(count * dtype.itemsize)})",
                                      f"{name}[...]"))
        used = _used(variables, wanted)
        _check_budget(path, used)
        loaded: dict[str, np.ndarray] = {}
        for variable in used:
            with archive.open(members[variable.name]) as fp:
                array = _foreign(lambda: np.lib.format.read_array(fp, allow_pickle=False))
            loaded.update(_columns(variable.name, array))
    return variables, _names(variables, loaded), loaded


def _names(variables: list[Variable], loaded: dict[str, np.ndarray]) -> list[str]:
    """Every column's name: as declared, or as read (a struct's fields), or a placeholder."""
    names: list[str] = []
    for v in variables:
        if v.columns is not None:
            names += v.columns
        else:
            names += [c for c in loaded if _variable_of(c) == v.name] or [v.placeholder]
    return names


def _npy_header(fp: IO[bytes]) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) a ``.npy`` member declares, from its header alone."""
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(fp)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(fp)
    else:
        reader = getattr(np.lib.format, "_read_array_header", None)
        if reader is None:
            raise ValueError(f"a .npy member of format version {version[0]}.{version[1]}, which is not read")
        shape, _, dtype = reader(fp, version)
    return tuple(int(s) for s in shape), np.dtype(dtype)


# ----- MATLAB .mat ------------------------------------------------------------------------
# MATLAB array classes (mxCLASS) and the bytes of one element
_MAT_ITEMSIZE = {4: 2, 6: 8, 7: 4, 8: 1, 9: 1, 10: 2, 11: 2, 12: 4, 13: 4, 14: 8, 15: 8}
_MAT_CELL, _MAT_STRUCT, _MAT_OBJECT, _MAT_SPARSE, _MAT_CHAR = 1, 2, 3, 5, 4
_MI_MATRIX, _MI_COMPRESSED = 14, 15
_HEAD_BYTES = 4096             # enough of an element for its flags, dimensions and name


def _mat(path: str, wanted: Collection[str] | None
         ) -> tuple[list[Variable], list[str], dict[str, np.ndarray]]:
    """The variables (from their headers), every column's name, and the used ones read."""
    import scipy.io
    with open(path, "rb") as fh:
        head = fh.read(512)
        if b"HDF" in head[128:]:
            raise InputError("a MATLAB v7.3 (HDF5) file, which is not read: save it with -v7", file=path)
        fh.seek(0)
        size = os.fstat(fh.fileno()).st_size
        version = scipy.io.matlab.matfile_version(fh)[0]
        if version == 0:
            variables = list(_mat4_variables(fh, size))
        elif version == 1:
            variables = list(_mat5_variables(fh, size))
        else:
            raise InputError("a MATLAB v7.3 (HDF5) file, which is not read: save it with -v7", file=path)
    used = _used(variables, wanted)
    _check_budget(path, used)
    if version == 1:
        with open(path, "rb") as fh:
            for variable in used:
                _check_mat5_element(fh, variable)
    loaded: dict[str, np.ndarray] = {}
    if used:
        data = _foreign(lambda: scipy.io.loadmat(path, variable_names=[v.name for v in used], squeeze_me=True,
                                                 struct_as_record=False))

        def add(name: str, value: object) -> None:
            if hasattr(value, "_fieldnames"):                      # a struct: its fields
                for field in value._fieldnames:
                    add(f"{name}.{field}", getattr(value, field))
            elif isinstance(value, np.ndarray):
                loaded.update(_columns(name, value))
        for name, value in data.items():
            if not name.startswith("__"):
                add(name, value)
    return variables, _names(variables, loaded), loaded


def _mat5_variables(fh: IO[bytes], size: int) -> Iterator[Variable]:
    """Each top-level variable of a MATLAB v5/v7 file, from its element's tag and header (a
    compressed element's first bytes inflated, never the rest)."""
    fh.seek(126)
    endian = {b"IM": "<", b"MI": ">"}.get(fh.read(2))
    if endian is None:
        raise ValueError("no MATLAB v5 endian indicator")
    position = 128
    while position + 8 <= size:
        fh.seek(position)
        mdtype, nbytes = struct.unpack(endian + "II", fh.read(8))
        if mdtype >> 16:                          # a small data element: no variable
            position += 8
            continue
        after = position + 8 + nbytes
        if mdtype == _MI_COMPRESSED:
            head = _inflated_head(fh, nbytes)
        elif mdtype == _MI_MATRIX:
            head = struct.pack(endian + "II", mdtype, nbytes) + fh.read(min(nbytes, _HEAD_BYTES))
        else:
            position = after
            continue
        variable = _mat5_header(head, endian)
        if variable is not None:
            yield replace(variable, offset=position)
        position = after


def _inflated_head(fh: IO[bytes], nbytes: int) -> bytes:
    """The first bytes of a compressed element, inflated (at most ``_HEAD_BYTES``)."""
    inflate = zlib.decompressobj()
    out, left = b"", nbytes
    while len(out) < _HEAD_BYTES and left > 0:
        chunk = fh.read(min(left, 65536))
        if not chunk:
            break
        left -= len(chunk)
        out += inflate.decompress(chunk, _HEAD_BYTES - len(out))
        if inflate.unconsumed_tail:
            break
    return out


def _mat5_header(head: bytes, endian: str) -> Variable | None:
    """A matrix element's name, class, dimensions and declared bytes."""
    mdtype, nbytes = struct.unpack(endian + "II", head[:8])
    if mdtype != _MI_MATRIX:
        return None
    offset = 8

    def element() -> bytes:
        nonlocal offset
        kind, count = struct.unpack(endian + "II", head[offset:offset + 8])
        if kind >> 16:                                # small element: the data in the tag
            count = kind >> 16
            data = head[offset + 4:offset + 4 + count]
            offset += 8
            return data
        data = head[offset + 8:offset + 8 + count]
        offset += 8 + count + (-count) % 8
        return data

    kinds = []

    def typed(allowed: tuple[int, ...]) -> bytes:
        """The next subelement, of one of the ``allowed`` types (scipy's reader indexes a
        table by the type unchecked: a flipped byte there crashed the process)."""
        kind = struct.unpack(endian + "I", head[offset:offset + 4])[0]
        kind = kind & 0xFFFF if kind >> 16 else kind
        if kind not in allowed:
            raise ValueError(f"a MATLAB element of type {kind} where one of {allowed} belongs")
        kinds.append(kind)
        return element()

    flags = typed((6,))
    word = struct.unpack(endian + "I", flags[:4])[0]
    klass, complex_ = word & 0xFF, bool(word & 0x0800)
    raw_dims = typed((5,))
    dims = tuple(struct.unpack(endian + f"{len(raw_dims) // 4}i", raw_dims[:len(raw_dims) // 4 * 4]))
    name = typed((1, 2, 16)).decode("latin-1").rstrip("\x00")
    if any(d < 0 for d in dims):
        raise ValueError(f"variable {name!r} declares negative dimensions {dims}")
    count = prod(dims)
    element_bytes = nbytes + 8
    if klass in (_MAT_CELL, _MAT_STRUCT, _MAT_OBJECT):
        # an object array of ``count`` entries, and the fields' data inside the element
        return Variable(name, None, max(element_bytes, count * 8),
                        f"a {'x'.join(map(str, dims))} {'struct' if klass == _MAT_STRUCT else 'cell'} of "
                        f"{_size(element_bytes)}", f"{name}.*")
    if klass == _MAT_SPARSE:
        return Variable(name, (), element_bytes, f"a sparse matrix of {_size(element_bytes)}")
    itemsize = _MAT_ITEMSIZE.get(klass, 8) * (2 if complex_ else 1)
    columns = () if klass == _MAT_CHAR else _columns_of(name, tuple(d for d in dims if d != 1))
    converted = count * 8 if (klass != 6 or complex_) and columns != () else 0
    return Variable(name, columns, max(element_bytes, count * itemsize) + converted,
                    f"{'x'.join(map(str, dims))} values of {_size(count * itemsize)}", f"{name}[...]")


# the MATLAB data types (miINT8 .. miUTF32) scipy's reader has a dtype for
_MI_DATA = (1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 16, 17, 18)


def _check_mat5_element(fh: IO[bytes], variable: Variable) -> None:
    """Walk a used variable's whole element (inflated, within its declared size, which the
    budget allowed) and check every subelement's type and bounds before scipy reads it: its
    reader indexes a table by the type without a check, and a .mat with one byte flipped there
    ended the process with a segmentation fault."""
    fh.seek(126)
    endian = "<" if fh.read(2) == b"IM" else ">"
    fh.seek(variable.offset)
    mdtype, nbytes = struct.unpack(endian + "II", fh.read(8))
    if mdtype == _MI_COMPRESSED:
        inflate = zlib.decompressobj()
        data = inflate.decompress(fh.read(nbytes), variable.declared + 8)
    else:
        data = struct.pack(endian + "II", mdtype, nbytes) + fh.read(nbytes)
    _walk_matrix(data, 0, endian)


def _walk_matrix(data: bytes, at: int, endian: str) -> int:
    """Check the miMATRIX element at ``at`` (its subelements, its cells' and fields' matrices);
    the position after it."""

    def tag(at: int) -> tuple[int, int, int, int]:
        """(type, bytes, where the data starts, where the next element starts)"""
        if at + 8 > len(data):
            raise ValueError("a MATLAB element runs past its end")
        kind, count = struct.unpack_from(endian + "II", data, at)
        if kind >> 16:
            kind, count = kind & 0xFFFF, kind >> 16
            if count > 4:
                raise ValueError("a MATLAB small element of more than 4 bytes")
            return kind, count, at + 4, at + 8
        after = at + 8 + count + (-count) % 8
        if at + 8 + count > len(data):
            raise ValueError("a MATLAB element runs past its end")
        return kind, count, at + 8, after

    def data_element(at: int, allowed: tuple[int, ...] = _MI_DATA) -> tuple[int, int, int]:
        kind, count, start, after = tag(at)
        if kind not in allowed:
            raise ValueError(f"a MATLAB data element of type {kind}, which no reader knows")
        return count, start, after

    kind, count, start, after = tag(at)
    if kind != _MI_MATRIX:
        raise ValueError(f"a MATLAB element of type {kind} where an array belongs")
    if count == 0:
        return after
    _, flags, at = data_element(start, (6,))
    word = struct.unpack_from(endian + "I", data, flags)[0]
    klass, complex_ = word & 0xFF, bool(word & 0x0800)
    size, dims, at = data_element(at, (5,))
    shape = struct.unpack_from(endian + f"{size // 4}i", data, dims)
    if any(d < 0 for d in shape):
        raise ValueError("negative MATLAB dimensions")
    _, _, at = data_element(at, (1, 2, 16))                        # the name
    entries = prod(shape)
    if klass in _MAT_ITEMSIZE or klass == _MAT_CHAR:                # numeric, logical, char
        _, _, at = data_element(at)
        if complex_:
            _, _, at = data_element(at)
    elif klass == _MAT_SPARSE:
        for _ in range(4 if complex_ else 3):
            _, _, at = data_element(at)
    elif klass == _MAT_CELL:
        for _ in range(entries):
            at = _walk_matrix(data, at, endian)
    elif klass in (_MAT_STRUCT, _MAT_OBJECT):
        if klass == _MAT_OBJECT:
            _, _, at = data_element(at, (1, 2, 16))                # the class name
        width_bytes, width_at, at = data_element(at, (5,))
        width = struct.unpack_from(endian + "i", data, width_at)[0] if width_bytes >= 4 else 0
        names, _, at = data_element(at, (1, 2, 16))
        if width <= 0 and names:
            raise ValueError("MATLAB struct field names of no length")
        for _ in range(entries * (names // width if width > 0 else 0)):
            at = _walk_matrix(data, at, endian)
    else:                           # a function handle, an opaque object: scipy's own (not columns)
        return after
    if at > after:
        raise ValueError("a MATLAB array's parts run past its element")
    return after


def _mat4_variables(fh: IO[bytes], size: int) -> Iterator[Variable]:
    """Each variable of a MATLAB v4 file, from its 20-byte header (its data uncompressed)."""
    position = 0
    while position + 20 <= size:
        fh.seek(position)
        raw = fh.read(20)
        for endian in ("<", ">"):
            mopt, rows, cols, imaginary, namelength = struct.unpack(endian + "5i", raw)
            if 0 <= mopt < 5000 and rows >= 0 and cols >= 0 and 0 < namelength < 65536:
                break
        else:
            raise ValueError("not a MATLAB v4 variable header")
        precision, form = (mopt // 10) % 10, mopt % 10
        itemsize = {0: 8, 1: 4, 2: 4, 3: 2, 4: 2, 5: 1}.get(precision)
        if itemsize is None:
            raise ValueError(f"unknown MATLAB v4 precision {precision}")
        name = fh.read(namelength).decode("latin-1").rstrip("\x00")
        data = rows * cols * itemsize * (2 if imaginary else 1)
        columns = _columns_of(name, tuple(d for d in (rows, cols) if d != 1)) if form == 0 else ()
        yield Variable(name, columns, data + (rows * cols * 8 if columns != () else 0),
                       f"{rows}x{cols} values of {_size(data)}", f"{name}[...]")
        position += 20 + namelength + data


def _columns(name: str, array: np.ndarray) -> Iterator[tuple[str, np.ndarray]]:
    if array.dtype == object or array.ndim == 0 or array.ndim > 2:
        return
    if array.ndim == 1:
        yield name, array
        return
    samples = array if array.shape[0] >= array.shape[1] else array.T
    if samples.shape[1] == 1:
        yield name, samples[:, 0]
        return
    for k in range(samples.shape[1]):
        yield f"{name}[{k}]", samples[:, k]
