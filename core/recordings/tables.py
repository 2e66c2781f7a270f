"""A description's log files as tables of named columns, whatever their layout.

A ``[[runs]]`` file entry is a path (a log with a header row, an ``.npz``/``.mat`` file of
arrays, a ROS bag) or a table ``{ path = "...", names = [...], stacked = true }``:

- ``names``: a file without a header row (a UR's RTDE export of plain numbers), its
  columns named in order, as pandas' ``names=`` reads it;
- ``stacked = true``: one value a line, the values of one sample on ``len(names)``
  consecutive lines (the Panda's published log: its 7 joints on 7 lines, one file per
  quantity, the time in a file of its own, ``names = ["t"]``).

Every error names the log, its line and column and says what the description asked for;
none speaks of the project's own CSV layout (``t, q_c, tau_c``), which a description's log
need not follow. Why: a headerless log gave "time column '1' found in 0 files", and a
one-value-per-line log "not a comma-separated file with columns t, q_<coordinate>,
tau_<coordinate>" (issue 44).
"""

from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from baseparams.errors import InputError
from baseparams.io.schema import BOOLEAN, STRING, Array, Table
from baseparams.recordings.arrays import is_array_file, read_arrays
from baseparams.recordings.bags import STAMP, is_bag, read_bag
from baseparams.recordings.delimited import (DELIMITERS, MAX_MAGNITUDE, MISSING_CHARACTERS, NUMBER, _checked, _lines,
                                              _read_text, read_columns)

if TYPE_CHECKING:
    from baseparams.recordings.description import Description

LOG = Table({"path": (STRING, True),
             "names": (Array(STRING, min_length=1, what="a list of the columns' names, in order"), False),
             "stacked": (BOOLEAN, False)},
            what="a path, or a table { path = \"...\", names = [...], stacked = true }")
"""A file entry of ``[[runs]]`` (``file``, or a value of ``files``) once a plain path is
written as ``{ path = ... }``."""
WHAT = "a log with one sample a row"


@dataclass(frozen=True)
class LogFile:
    """One log a run reads: its ``path`` (relative to the description), the columns' names
    when the file has no header row, and whether it holds one value a line (``stacked``);
    ``key``: where the description names it (``runs[0].files.q``), for messages."""
    path: str
    names: tuple[str, ...] | None = None
    stacked: bool = False
    key: str = ""


def as_table(entry: object) -> object:
    """A file entry as a table: a plain path is ``{ path = ... }`` (other values are left for
    the schema to refuse)."""
    return {"path": entry} if isinstance(entry, str) else entry


def log_files(run: dict, description: str, key: str) -> dict[str | None, LogFile]:
    """The run's logs by alias (None: a run in one file), checked: ``stacked`` needs
    ``names``, names are distinct, an array file or a bag names its own columns."""
    if ("file" in run) == ("files" in run):
        raise InputError("give file (one log) or files (alias = log, read side by side)", file=description, key=key)
    entries = {None: (run["file"], f"{key}.file")} if "file" in run else \
        {alias: (entry, f"{key}.files.{alias}") for alias, entry in run["files"].items()}
    out: dict[str | None, LogFile] = {}
    for alias, (entry, where) in entries.items():
        spec = as_table(entry)
        assert isinstance(spec, dict)                  # the schema checked it
        names = tuple(spec["names"]) if "names" in spec else None
        stacked = bool(spec.get("stacked", False))
        if stacked and names is None:
            raise InputError("stacked = true (one value a line) needs names = [...]: the columns of one sample, "
                             "in the order of their lines", file=description, key=f"{where}.stacked")
        if names is not None:
            seen: set[str] = set()
            for k, name in enumerate(names):
                if not name.strip():
                    raise InputError("an empty name", file=description, key=f"{where}.names[{k}]")
                if name in seen:
                    raise InputError(f"{name!r} is named twice", file=description, key=f"{where}.names[{k}]")
                seen.add(name)
            if is_array_file(spec["path"]) or is_bag(spec["path"]):
                raise InputError("names and stacked are for text logs: an array file or a bag names its own "
                                 "columns", file=description, key=f"{where}.names")
        out[alias] = LogFile(spec["path"], names, stacked, where)
    return out


def read_run_tables(description: "Description", logs: dict[str | None, LogFile], folder: Path
                 ) -> tuple[dict, dict, dict]:
    """(tables, files, groups) of one run's logs: each table (header, the used columns by name,
    each sample's row) by alias; ``files``: each alias's name in messages; ``groups``: the
    alias a channel names it by (a bag is one table per topic, each on its own clock, all
    under the bag's alias). Only the columns the description uses are read."""
    head = description.data.get("recording", {})
    delimiter = log_format(description)
    wanted = {c.column for chans in description.channels.values() for c in chans if not c.absent}
    clock = str(head.get("time", "")).rpartition(":")[2]
    if clock:
        wanted.add(clock)
    dates = {clock} if head.get("time_unit") == "iso" else set()
    tables: dict = {}
    files: dict = {}
    groups: dict = {}
    only_bags = all(is_bag(folder / log.path) for log in logs.values())
    for alias, log in logs.items():
        where = str(folder / log.path)
        if is_bag(where):
            topics = read_bag(where, wanted, clock or STAMP, strict=only_bags)
            for topic, table in topics.items():
                tables[(alias, topic)] = table
                files[(alias, topic)] = f"{log.path} (topic {topic})"
                groups[(alias, topic)] = alias
            continue
        tables[alias] = read_arrays(where, wanted, dates) if is_array_file(where) else \
            read_log(where, log, description.path, *delimiter, wanted=wanted, dates=dates)
        files[alias] = log.path
        groups[alias] = alias
    if not tables:
        raise InputError("no topic of its bag(s) holds a column the description uses", file=description.path,
                         key="runs")
    if dates:                     # nanoseconds since 1970, as seconds since the run's first stamp
        (stamp,) = dates
        origin = min(int(table[stamp][0]) for _, table, _ in tables.values() if stamp in table)
        for _, table, _ in tables.values():
            if stamp in table:
                table[stamp] = (table[stamp] - origin) * 1e-9
    return tables, files, groups


def log_format(description: "Description") -> tuple[str, str | None]:
    """(delimiter, comment prefix) of the logs: ``[recording] delimiter`` (",", ";", "tab",
    "space" or "auto", the default) and ``comment`` (a prefix of lines to skip, none by default)."""
    head = description.data.get("recording", {})
    delimiter = head.get("delimiter", "auto")
    if delimiter != "auto" and delimiter not in DELIMITERS:
        raise InputError(f"unknown delimiter {delimiter!r}: one of auto, ',', ';', tab, space",
                         file=description.path, key="recording.delimiter")
    comment = head.get("comment") or None
    return DELIMITERS.get(delimiter, delimiter), comment


def read_log(path: str, log: LogFile, description: str, delimiter: str = "auto", comment: str | None = None,
             wanted: Collection[str] | None = None, dates: Collection[str] = ()
             ) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """(header, the ``wanted`` columns by name, each sample's line) of a text log at ``path``
    as ``log`` describes it (a header row, ``names``, or ``stacked``)."""
    where = f"{log.key} of {Path(description).name}" if log.key else Path(description).name
    text = _read_text(path, WHAT)
    if log.stacked:
        assert log.names is not None
        if set(dates) & set(log.names):
            raise InputError("dates and times (time_unit = \"iso\") are read from a log with one sample a row, not "
                             "from a stacked one", file=description, key=f"{log.key}.stacked")
        return _stacked(path, text, log.names, comment, wanted, where)
    first = next((line for line in _lines(text) if line.strip()
                  and not (comment and line.lstrip().startswith(comment))), "")
    fields = [f.strip() for f in _split(first, delimiter)]
    numbers = [f for f in fields if NUMBER.fullmatch(f)]
    if log.names is None and fields and len(numbers) == len(fields):
        shown = ", ".join(fields[:4]) + (", ..." if len(fields) > 4 else "")
        raise InputError(f"its first line ({shown}) holds numbers, not the columns' names: a log without a header "
                         f"row needs them in the description: {log.key or 'file'} = {{ path = \"{log.path}\", names = "
                         f"[...] }} ({len(fields)} names, in order)"
                         + ("; one value a line: add stacked = true" if len(fields) == 1 else ""),
                         file=path, key="row 1")
    if log.names is not None and fields and not numbers and len(fields) > 1:
        shown = ", ".join(fields[:4]) + (", ..." if len(fields) > 4 else "")
        raise InputError(f"its first line ({shown}) is a header row, and the description names the columns "
                         f"({where}: names): leave names out to read the header's", file=path, key="row 1")
    return read_columns(path, text, delimiter, comment, wanted, missing=True, dates=dates, names=log.names,
                        log=where)


def _split(line: str, delimiter: str) -> list[str]:
    if delimiter == "auto":
        delimiter = next((d for d in (",", ";", "\t") if d in line), " ")
    return line.split() if delimiter == " " else line.strip("\r\n").split(delimiter)


def _stacked(path: str, text: str, names: tuple[str, ...], comment: str | None, wanted: Collection[str] | None,
             where: str) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """A log of one value a line, the values of one sample on ``len(names)`` consecutive lines
    (comment lines skipped): every column by name, each sample's first line. A blank line
    between samples (after a whole number of them) separates them; one inside a sample is a
    missing value (NaN: the sample is left out later, with a note), never skipped, which would
    shift every later value into the next column."""
    width = len(names)
    body = text.rstrip()
    if (not comment or comment not in text) and not any(c in body for c in ", ;\t\r") and "\n\n" not in body \
            and body and body[0] != "\n":   # the common case at once: one number a line, nothing else, no blank line
        tokens = body.split("\n")
        return _stacked_values(path, tokens, list(range(1, len(tokens) + 1)), names, wanted, where)
    lines = text.splitlines()
    while lines and not lines[-1].strip():              # trailing blank lines
        lines.pop()
    fields: list[str] = []
    numbers: list[int] = []
    blanks: list[int] = []                              # values before each blank line
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            blanks.append(len(fields))
            fields.append("")
            numbers.append(number)
        elif not (comment and stripped.startswith(comment)):
            fields.append(stripped)
            numbers.append(number)
    if blanks:
        values_before = np.array(blanks) - np.arange(len(blanks))
        if np.all(values_before % width == 0):          # separators between samples
            keep = np.ones(len(fields), dtype=bool)
            keep[blanks] = False
            fields = [f for f, k in zip(fields, keep) if k]
            numbers = [n for n, k in zip(numbers, keep) if k]
    several = next((k for k, f in enumerate(fields) if " " in f or "\t" in f or "," in f.rstrip(",")
                    or ";" in f.rstrip(";")), None)
    if several is not None:
        raise InputError(f"{fields[several][:40]!r} holds several values: a stacked log ({where}: stacked = true) has "
                         "one value a line; leave stacked out for a log with one sample a row", file=path,
                         key=f"row {numbers[several]}")
    fields = [f.rstrip(",;") for f in fields]
    return _stacked_values(path, fields, numbers, names, wanted, where)


def _stacked_values(path: str, fields: list[str], numbers: list[int], names: tuple[str, ...],
                    wanted: Collection[str] | None, where: str) -> tuple[list[str], dict[str, np.ndarray], list[int]]:
    """A stacked log's fields (one a value, ``numbers`` their lines) as its columns."""
    width = len(names)
    if not fields:
        raise InputError(f"no values ({where})", file=path)
    if len(fields) % width:
        rest = len(fields) % width
        raise InputError(f"{len(fields)} values are not a whole number of samples of {width} ({where}: names = "
                         f"[{', '.join(names[:4])}{', ...' if width > 4 else ''}]): the last sample has "
                         f"{rest} value(s), from row {numbers[len(fields) - rest]}; is a value missing, or the names?",
                         file=path)
    values = None
    try:                                                 # at once when every field is a number
        if not "".join(fields).encode("ascii").translate(None, MISSING_CHARACTERS) and "" not in fields:
            values = np.array(fields, dtype=float)
    except (UnicodeEncodeError, ValueError):
        values = None
    if values is not None and not np.all(np.abs(values[~np.isnan(values)]) <= MAX_MAGNITUDE):
        values = None
    if values is None:
        checked = _checked(path, "?", fields, numbers, missing=True)
        if isinstance(checked, tuple):                   # name the column of the bad value
            k, error = checked
            raise InputError(error.reason, file=path, key=f"row {numbers[k]}, column {names[k % width]}")
        values = checked
    table = values.reshape(-1, width)
    used = [k for k, name in enumerate(names) if wanted is None or name in wanted]
    return list(names), {names[k]: np.ascontiguousarray(table[:, k]) for k in used}, numbers[::width]
