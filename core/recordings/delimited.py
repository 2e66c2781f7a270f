"""Delimited text logs as named columns of numbers, read within the memory budget.

One reader for the project's CSV layout (:mod:`.data`) and for the text logs a recording
description names (:mod:`.tables`): the file's text read in chunks up to the read budget
(a device or an endless pipe refused, never read whole), then the columns wanted parsed a
batch of rows at a time, every field used checked to be a finite number (or a missing one,
or an ISO 8601 date), the first bad field named by its row and column.
"""

import csv
import math
import os
import re
import warnings
from collections.abc import Callable, Collection, Iterator, Sequence
from operator import itemgetter
from typing import Any

import numpy as np

from baseparams.errors import InputError
from baseparams.recordings.budget import PARSE_BYTES_PER_BYTE, read_budget

# Bytes read from a file at once (its size is checked against the budget as it grows).
READ_CHUNK = 1 << 20
# |value| above this is refused as out of range: the fit squares and sums the columns, and
# 1e150 squared is still finite where 1e300 is not.
MAX_MAGNITUDE = 1e150
# A number as the project's CSV takes it: ASCII digits, one optional sign, point and exponent
# (Python's float() also reads 1_0 as 10 and other scripts' digits).
NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
# The characters of NUMBERs, spaces (and NaN's, where values may be missing): a batch of fields
# made of these alone that float() takes is a batch of NUMBERs between spaces (float takes no
# other string of them), checked at once; rows are parsed per batch (bounded memory for the fields' strings).
NUMBER_CHARACTERS = b"0123456789+-.eE \t"
MISSING_CHARACTERS = NUMBER_CHARACTERS + b"nNaA"
PARSE_BATCH_ROWS = 1 << 13


def _read_text(path: str, what: str = "a CSV file") -> str:
    """The file's text, read in chunks up to :func:`read_budget` (a device such as /dev/zero
    or an endless pipe is refused once past it, never read whole). ``what`` the file should
    be, in messages: a log a description names is not the project's CSV layout."""
    budget = read_budget()
    try:
        size = os.path.getsize(path)
        if size > budget:
            raise InputError(_too_large(size, budget), file=path)
        chunks, total = [], 0
        with open(path, "rb") as fh:
            while True:
                chunk = fh.read(READ_CHUNK)
                if not chunk:
                    break
                if b"\x00" in chunk:
                    raise InputError(f"binary file (it contains NUL bytes): not {what}", file=path)
                total += len(chunk)
                if total > budget:
                    raise InputError(_too_large(total, budget, more=True), file=path)
                chunks.append(chunk)
        raw = b"".join(chunks)
    except IsADirectoryError:
        raise InputError(f"is a directory, not {what}", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", file=path) from None
    if not raw.strip():
        raise InputError("empty file: a CSV file with a header row and samples is needed" if what == "a CSV file"
                         else f"empty file: {what} with samples is needed", file=path)
    if b"\x00" in raw:
        raise InputError(f"binary file (it contains NUL bytes): not {what}", file=path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not a text file (byte {exc.start} is not UTF-8): not {what}", file=path) from None
    return text


def _too_large(size: int, budget: int, more: bool = False) -> str:
    from baseparams.dynamics.trajectory import MEMORY_VARIABLE
    return (f"{'more than ' if more else ''}{size:,} bytes: reading it would take about "
            f"{PARSE_BYTES_PER_BYTE} times that in memory, above the limit for a data file of {budget:,} "
            f"bytes; split it into runs or files, decimate it, or raise {MEMORY_VARIABLE}")


DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\t": "\t", "space": " ", " ": " "}


def read_columns(path: str, text: str, delimiter: str = ",", comment: str | None = None,
                 wanted: Collection[str] | None = None, missing: bool = False,
                 on_header: Callable[[list[str]], None] | None = None, dates: Collection[str] = (),
                 names: Sequence[str] | None = None, log: str | None = None
                 ) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """(header, values, lines) of a delimited text: the header's names, the columns in
    ``wanted`` (None: all) that the header has as float64 by name, and each data row's line.
    Blank lines (and lines starting with ``comment``) are skipped. ``delimiter``: ",", ";",
    "\t", " " (any run of spaces and tabs: loggers that align columns) or "auto" (the
    header's first of these). A field of a wanted column that is not a finite number names
    its row and column (``missing``: an empty or NaN field is NaN, for the caller to leave
    out); the other columns are not read; ``dates``: columns of ISO 8601 dates and times
    (``2024-05-01 12:00:00.123``), read as int64 nanoseconds since 1970 (UTC, or the logger's
    local time without an offset). ``on_header``: checks the header once the rows'
    structure is known (the errors come in the order: a row's field count, the header, the
    first bad number, whichever batch holds it). Why columns by name, row by row: a robot's
    log has many columns a description does not use (a UR's RTDE log 100 and more, some of
    them text), and its rows kept as strings took 30 times the file's size in memory.

    ``names``: a file without a header row (a controller's export), its columns named in
    order (pandas' ``names=``): every line is a sample. ``log``: where a recording
    description names this file (its messages then speak of the description, never of the
    project's CSV layout); a column it uses (``wanted``) that the header has twice is an error."""
    if delimiter == "auto":
        head = next((line for line in _lines(text)
                     if line.strip() and not (comment and line.lstrip().startswith(comment))), "")
        delimiter = next((d for d in (",", ";", "\t") if d in head), " " if " " in head.strip() else ",")
    if delimiter == " ":
        reader: Any = _Whitespace(text)
    else:                                  # line by line: a StringIO holds 4 bytes a character
        reader = csv.reader(_lines(text), strict=True, delimiter=delimiter)
    header: list[str] | None = None
    header_line, lines = 0, []
    used: list[int] = []
    pending: list[list[str]] = []              # the rows not yet converted, whole
    done: list[list[np.ndarray]] = []
    bad: list[InputError] = []                 # the first bad number, raised after the header's checks
    if names is not None:                      # no header row: the columns named by the description
        header = list(names)
        used = [k for k, name in enumerate(header) if wanted is None or name in wanted]
        done = [[] for _ in used]
    try:
        for fields in reader:
            if not fields or (not fields[0].strip() and not "".join(fields).strip()):
                continue                                          # a blank line
            if comment and fields[0].lstrip().startswith(comment):
                continue
            if header is None:
                header = [f.strip() for f in fields]
                header_line = reader.line_num
                used = [k for k, name in enumerate(header) if wanted is None or name in wanted]
                done = [[] for _ in used]
                continue
            if len(fields) != len(header):
                if names is not None:
                    raise InputError(f"{len(fields)} fields, the description names {len(header)} columns "
                                     f"({log}: names = [{', '.join(header[:4])}{', ...' if len(header) > 4 else ''}])",
                                     file=path, key=f"row {reader.line_num}")
                raise InputError(f"{len(fields)} fields, the header has {len(header)}: "
                                 + ("not a CSV file with this header" if log is None else
                                    f"not a table with this header ({log}; a file without a header row: give its "
                                    "columns' names in the description, names = [...])"),
                                 file=path, key=f"row {reader.line_num}")
            lines.append(reader.line_num)
            pending.append(fields)
            if len(pending) >= PARSE_BATCH_ROWS:
                _convert(path, header, used, pending, done, lines, missing, bad, dates)
    except csv.Error as exc:
        raise InputError(f"not a CSV file: {exc}" if log is None else f"not a delimited text log ({log}): {exc}",
                         file=path, key=f"row {reader.line_num}") from None
    if header is None:
        raise InputError("no header row" if log is None else f"no lines with values ({log})", file=path)
    if log is None and len(header) < 2:
        raise InputError(f"the header {','.join(header)!r} has one column: not a comma-separated "
                         "file with columns t, q_<coordinate>, tau_<coordinate>", file=path,
                         key=f"row {header_line}")
    if not lines:
        raise InputError("a header but no samples" if names is None else "no samples", file=path)
    if log is not None and wanted is not None:  # a column used twice: which one is meant?
        for name in sorted(set(wanted) & set(header)):
            where = [k + 1 for k, n in enumerate(header) if n == name]
            if len(where) > 1:
                raise InputError(f"column {name!r} appears twice (columns {where[0]} and {where[1]}), and the "
                                 f"description uses it ({log}): rename one in the file's header, or name the "
                                 "columns in the description (names = [...])", file=path,
                                 key="header" if names is None else None)
    if on_header is not None:
        on_header(header)
    _convert(path, header, used, pending, done, lines, missing, bad, dates)
    if bad:
        raise bad[0]
    values: dict[str, np.ndarray] = {}
    for k, parts in zip(used, done):
        values.setdefault(header[k], np.concatenate(parts) if parts else np.zeros(0))
    return header, values, lines


def _convert(path: str, header: list[str], used: list[int], pending: list[list[str]],
             done: list[list[np.ndarray]], lines: list[int], missing: bool, bad: list[InputError],
             dates: Collection[str] = ()) -> None:
    """The used fields of the pending rows as numbers (appended to ``done``; ``pending``
    emptied): a column's batch is checked against NUMBER at once and converted by ``float``; a
    batch that fails is gone through field by field to name the first bad field's row and column."""
    if not pending or not used or bad:         # after a bad number only the rows' structure is read
        pending.clear()
        return
    first = len(lines) - len(pending)
    rows = map(itemgetter(*used), pending) if len(used) > 1 else ((row[used[0]],) for row in pending)
    allowed = MISSING_CHARACTERS if missing else NUMBER_CHARACTERS
    errors: list[tuple[int, InputError]] = []
    for k, fields, parts in zip(used, zip(*rows), done):
        values = None
        if header[k] in dates:
            checked = _datetimes(path, header[k], fields, lines[first:])
            if isinstance(checked, tuple):
                errors.append(checked)
            else:
                parts.append(checked)
            continue
        try:                                       # float() takes the spaces around a field
            if not "".join(fields).encode("ascii").translate(None, allowed):
                values = np.array(list(map(float, fields)) if not (missing and "" in fields) else
                                  [float(f) if f else math.nan for f in fields])
        except (UnicodeEncodeError, ValueError):   # not ASCII, or a field float() does not take
            values = None
        if values is not None and not np.all(np.abs(values[~np.isnan(values)]) <= MAX_MAGNITUDE):
            values = None
        if values is None:
            checked = _checked(path, header[k], [f.strip() for f in fields], lines[first:], missing)
            if isinstance(checked, tuple):      # the batch's first bad field by row, then column
                errors.append(checked)
                continue
            values = checked
        parts.append(values)
    if errors:
        bad.append(min(errors, key=lambda e: e[0])[1])
    pending.clear()


def _datetimes(path: str, name: str, fields: Sequence[str], lines: list[int]
               ) -> np.ndarray | tuple[int, InputError]:
    """ISO 8601 dates and times as nanoseconds since 1970 (int64: exact; seconds since 1970 in
    a float are rounded to 0.24 us), a trailing Z (UTC) allowed; or the first field that is not one: its index and the
    InputError naming its row and column."""
    stamps = [f.strip().removesuffix("Z") for f in fields]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")          # numpy warns on a time zone offset
            ns = np.array(stamps, dtype="datetime64[ns]")
        if not np.isnat(ns).any():
            return ns.astype(np.int64)
    except (ValueError, UserWarning, DeprecationWarning):
        pass
    for i, stamp in enumerate(stamps):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                bad = np.isnat(np.datetime64(stamp, "ns"))
        except (ValueError, UserWarning, DeprecationWarning):
            bad = True
        if bad:
            shown = stamp if len(stamp) <= 40 else stamp[:37] + "..."
            return i, InputError(f"{shown!r} is not a date and time (ISO 8601, e.g. 2024-05-01 12:00:00.123, "
                                 "UTC with Z or local without an offset)", file=path, key=f"row {lines[i]}, column {name}")
    raise AssertionError("a batch numpy refused has a field it refuses")      # pragma: no cover


def _checked(path: str, name: str, fields: list[str], lines: list[int], missing: bool
             ) -> np.ndarray | tuple[int, InputError]:
    """Stripped fields as float64, field by field; or the first that is not a finite number
    in range: its index and the InputError naming its row and column."""
    out = np.empty(len(fields))
    match = NUMBER.fullmatch
    for i, (line, stripped) in enumerate(zip(lines, fields)):
        if missing and (not stripped or stripped.lower().lstrip("+-") == "nan"):
            out[i] = np.nan
            continue
        value = float(stripped) if match(stripped) else None
        if value is None or not abs(value) <= MAX_MAGNITUDE:
            shown = stripped if len(stripped) <= 40 else stripped[:37] + "..."
            if value is not None:
                reason = "is not finite" if not math.isfinite(value) else \
                    f"is out of range (|value| > {MAX_MAGNITUDE:g})"
            elif stripped.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                reason = "is not finite"
            else:
                reason = "is not a number (ASCII digits, sign, point and exponent only)"
                if re.match(r"\d{4}-\d\d-\d\d", stripped):
                    reason += "; a date and time: a recording reads them with time_unit = \"iso\""
            return i, InputError(f"{shown!r} {reason}", file=path, key=f"row {line}, column {name}")
        out[i] = value
    return out


def _lines(text: str) -> Iterator[str]:
    """The text's lines with their ends, one at a time (no list of them all); lines end at
    "\n" ("\r\n" included), or at "\r" in a text that has no "\n"."""
    start, end_of_line = 0, "\n" if "\n" in text or "\r" not in text else "\r"
    while start < len(text):
        end = text.find(end_of_line, start)
        end = len(text) if end < 0 else end + 1
        yield text[start:end]
        start = end


class _Whitespace:
    """Rows split at runs of spaces and tabs, with csv.reader's ``line_num``."""

    def __init__(self, text: str):
        self.text = text
        self.line_num = 0

    def __iter__(self) -> Iterator[list[str]]:
        for self.line_num, line in enumerate(_lines(self.text), start=1):
            yield line.split()
