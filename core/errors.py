"""Errors that carry what a user needs to fix their input: file, key path, reason."""

import os


class BaseparamsError(Exception):
    """Base class of all errors baseparams raises on purpose."""


class InputError(BaseparamsError):
    """Bad user input (a mechanism file, an option, a data file): exit code 2 in the CLI."""

    def __init__(self, reason: str, file: str | os.PathLike[str] | None = None, key: str | None = None) -> None:
        self.reason = reason
        self.file = None if file is None else str(file)
        self.key = key
        super().__init__(self.message)

    @property
    def message(self) -> str:
        where = []
        if self.file:
            where.append(self.file)
        if self.key:
            where.append(self.key)
        return (": ".join(where) + ": " if where else "") + self.reason


class KinematicsError(BaseparamsError):
    """A configuration that cannot be evaluated: loop does not close, singular, out of range."""
