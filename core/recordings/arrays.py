"""Logs saved as arrays (NumPy ``.npz``, MATLAB ``.mat``) read as named columns, so a
recording description maps them as it maps a CSV log's columns.

A one-dimensional variable is a column under its name (``t``); a two-dimensional one is a
column per channel, ``NAME[i]`` counted from 0 (``q[0]`` .. ``q[6]``), whichever way round it
was saved (samples along its longer axis: a log has more samples than channels). A MATLAB
struct's fields are ``STRUCT.FIELD`` (``log.q[2]``). Text, cells and other variables are not
columns. MATLAB v7.3 files are HDF5, which ``scipy.io.loadmat`` does not read: saved with
``-v7`` they are. Why: a researcher's log is often a ``.mat`` or ``.npz`` file, which had to be
converted to CSV by hand.
"""

import os
import zipfile
from collections.abc import Collection, Iterator

import numpy as np

from baseparams.errors import InputError
from baseparams.recordings.budget import read_budget

SUFFIXES = (".npz", ".mat")


def is_array_file(path: str | os.PathLike) -> bool:
    """A log saved as arrays (by its suffix), read by :func:`read_arrays`."""
    return str(path).lower().endswith(SUFFIXES)


def read_arrays(path: str, wanted: Collection[str] | None = None, dates: Collection[str] = ()
                ) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """(names, the ``wanted`` columns by name as float64, each sample's row from 1) of an
    array file, as :func:`.data.read_columns` gives a CSV log's. The wanted columns must have
    one length; in them an infinite value or a non-number is an error naming its row and
    column (NaN is a missing value, left out later). ``dates``: datetime64 columns, read as
    nanoseconds since 1970 (the ``iso`` time unit's)."""
    try:
        size = os.path.getsize(path)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=path) from None
    if size > read_budget():
        raise InputError(f"{size / 1e6:.0f} MB: larger than the memory budget allows ({read_budget() / 1e6:.0f} MB)",
                         file=path)
    variables = dict(_variables(path))
    names = list(variables)
    chosen = names if wanted is None else [n for n in names if n in wanted]
    lengths = {n: len(variables[n]) for n in chosen}
    if len(set(lengths.values())) > 1:
        shown = ", ".join(f"{n}: {k}" for n, k in lengths.items())
        raise InputError(f"the columns used have different lengths ({shown})", file=path)
    values: dict[str, np.ndarray] = {}
    for name in chosen:
        column = variables[name]
        if name in dates:
            if not np.issubdtype(column.dtype, np.datetime64):
                raise InputError("not dates and times (datetime64): give the time in a unit instead",
                                 file=path, key=f"column {name}")
            values[name] = column.astype("datetime64[ns]").astype(np.int64)
            continue
        if not (np.issubdtype(column.dtype, np.number) or column.dtype == bool):
            raise InputError(f"holds {column.dtype} values, not numbers", file=path, key=f"column {name}")
        out = np.asarray(column, dtype=float)
        bad = np.flatnonzero(np.isinf(out))
        if bad.size:
            raise InputError(f"{out[bad[0]]} is not a finite number", file=path,
                             key=f"row {int(bad[0]) + 1}, column {name}")
        values[name] = out
    count = next(iter(lengths.values()), 0)
    if wanted is not None and count == 0 and chosen:
        raise InputError("no samples", file=path)
    return names, values, list(range(1, count + 1))


def _variables(path: str) -> Iterator[tuple[str, np.ndarray]]:
    """Each column of the file: (name, its samples)."""
    try:
        if str(path).lower().endswith(".npz"):
            with np.load(path, allow_pickle=False) as archive:
                loaded = {name: archive[name] for name in archive.files}
        else:
            loaded = _matlab(path)
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except (OSError, ValueError, zipfile.BadZipFile, NotImplementedError) as exc:
        raise InputError(f"cannot read as {'a NumPy .npz' if path.lower().endswith('.npz') else 'a MATLAB .mat'} "
                         f"file: {exc}", file=path) from None
    for name, array in loaded.items():
        yield from _columns(name, array)


def _matlab(path: str) -> dict[str, np.ndarray]:
    import scipy.io
    with open(path, "rb") as fh:
        if b"HDF" in fh.read(512)[128:]:
            raise InputError("a MATLAB v7.3 (HDF5) file, which is not read: save it with -v7", file=path)
    data = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    out: dict[str, np.ndarray] = {}

    def add(name: str, value: object) -> None:
        if hasattr(value, "_fieldnames"):                      # a struct: its fields
            for field in value._fieldnames:
                add(f"{name}.{field}", getattr(value, field))
        elif isinstance(value, np.ndarray):
            out[name] = value
    for name, value in data.items():
        if not name.startswith("__"):
            add(name, value)
    return out


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
